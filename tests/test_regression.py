"""Training pinned bit for bit: short seeded runs against the metrics recorded in
``tests/data/pinned_metrics.json``.

A change that moves any bit of a run's metrics fails here, loudly: the seed study's parts
(``experiments/studies/study.py``), recorded across sessions, are comparable only while training is
unchanged. A change meant to alter training re-records the pins and says so in its commit; the
study's parts recorded before it then belong to another protocol.

XLA compiles for the processor it runs on, and two kinds of CPU (one with AVX-512, one without;
two AMD EPYC generations with the same AVX-512 flags, as measured) round the same program
differently in the last bits. So the pins are kept per kind of
processor (:func:`processor`): where this one has pins, the runs must match them bit for bit;
a processor with none must match one recorded elsewhere bit for bit or, failing that, to
rounding (with a warning that asks for its pins: record them with
``python tests/test_regression.py --record`` at a commit whose training is the pinned one).
"""

import json
import platform
import sys
import warnings
from pathlib import Path

import jaxlib
import numpy as np
import pytest

from fppo_jax import sweep, train

PINNED = Path(__file__).resolve().parent / "data" / "pinned_metrics.json"
TINY = {"num_envs": 4, "num_steps": 32, "num_minibatches": 4, "num_epochs": 2}
# Where XLA's code differs between processors: the width of its vector instructions.
VECTOR_FEATURES = (
    "sse4_2",
    "avx",
    "avx2",
    "fma",
    "avx512f",
    "avx512bw",
    "avx512vl",
    "avx512dq",
    "avx512_bf16",
    "avx512_vnni",
    "avx512vbmi",
    "amx_tile",
)
# Two kinds of processor round a few updates' metrics apart by about 1e-4 (measured: 1e-4 at
# most, relative, on these runs); a change to the training arithmetic itself moves them further.
ROUNDING = {"rtol": 1e-3, "atol": 1e-5}

# name: a function giving {metric: values} of a short seeded run, at the `paper` preset's shape
# where it is cheap (the study's own), else tiny.
RUNS = {
    "gymnax cartpole, fppo-lp, paper preset": lambda: (
        train("cartpole", "fppo-lp", seed=3, total_steps=4096).metrics
    ),
    "native reacher, fppo-qp, paper preset": lambda: (
        train("reacher", "fppo-qp", seed=1, total_steps=4096, backend="native").metrics
    ),
    "a two-setting sweep on cartpole": lambda: {
        f"{name}[{run}]": values[run]
        for name, values in sweep(
            "cartpole", {"variant": ["ppo", "tr-ppo"]}, seeds=[0, 5], total_steps=512, **TINY
        ).metrics.items()
        for run in range(4)
    },
}


def processor() -> str:
    """This kind of processor, as far as XLA's rounding goes: jaxlib's version, the CPU's
    model, family and model number (two generations with the same vector instructions are
    told apart) and its vector instruction sets."""
    model, family, number, flags = platform.machine(), "", "", set()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                key, _, value = line.partition(":")
                key, value = key.strip(), value.strip()
                if key == "model name":
                    model = value
                elif key == "cpu family":
                    family = value
                elif key == "model":
                    number = value
                elif key == "flags":
                    flags = set(value.split())
    except OSError:
        pass
    generation = f" (family {family}, model {number})" if family and number else ""
    features = " ".join(f for f in VECTOR_FEATURES if f in flags) or "features unknown"
    return f"jaxlib {jaxlib.__version__}; {model}{generation}; {features}"


def fingerprint(metrics: dict[str, np.ndarray]) -> dict[str, dict[str, object]]:
    """Each metric's dtype, bytes (hex) and values (for a readable failure)."""
    return {
        name: {
            "dtype": str(np.asarray(v).dtype),
            "hex": np.ascontiguousarray(v).tobytes().hex(),
            "values": np.asarray(v, float).tolist(),
        }
        for name, v in sorted(metrics.items())
    }


def changed_bits(found: dict, pinned: dict) -> list[str]:
    return [m for m in pinned if found[m]["hex"] != pinned[m]["hex"]]


def beyond_rounding(found: dict, pinned: dict) -> list[str]:
    return [
        m
        for m in pinned
        if not np.allclose(found[m]["values"], pinned[m]["values"], equal_nan=True, **ROUNDING)
    ]


def describe(metrics: list[str], found: dict, pinned: dict) -> str:
    return "; ".join(
        f"{m}: pinned {pinned[m]['values'][:3]}, now {found[m]['values'][:3]}" for m in metrics[:3]
    )


def test_pins_are_recorded_per_processor_and_this_one_is_named():
    platforms = json.loads(PINNED.read_text())
    assert platforms and all(sorted(pins) == sorted(RUNS) for pins in platforms.values())
    assert processor().startswith(f"jaxlib {jaxlib.__version__}; ")


@pytest.mark.parametrize("name", list(RUNS))
def test_training_is_unchanged_bit_for_bit(name):
    platforms = {where: pins[name] for where, pins in json.loads(PINNED.read_text()).items()}
    found = fingerprint(RUNS[name]())
    for pinned in platforms.values():
        assert sorted(found) == sorted(pinned), "the metrics recorded per update changed"
    here = processor()
    if here in platforms:
        pinned = platforms[here]
        changed = changed_bits(found, pinned)
        assert not changed, (
            f"training changed on {here}: {len(changed)} metrics differ from the pins "
            f"({describe(changed, found, pinned)}). If this is meant, re-record the pins on "
            "every kind of processor and say so: the seed study's parts recorded before the "
            "change are then another protocol."
        )
    elif not any(not changed_bits(found, pinned) for pinned in platforms.values()):
        nearest = min(platforms.values(), key=lambda pinned: len(beyond_rounding(found, pinned)))
        apart = beyond_rounding(found, nearest)
        assert not apart, (
            f"training changed: {len(apart)} metrics differ from every processor's pins by more "
            f"than rounding ({describe(apart, found, nearest)})"
        )
        warnings.warn(
            f"no pins for this processor ({here}): its runs match the pins of another to "
            "rounding only; record its own with `python tests/test_regression.py --record` at a "
            "commit whose training is the pinned one",
            stacklevel=1,
        )


if __name__ == "__main__":
    if sys.argv[1:] != ["--record"]:
        sys.exit("usage: python tests/test_regression.py --record")
    platforms = json.loads(PINNED.read_text()) if PINNED.exists() else {}
    platforms[processor()] = {name: fingerprint(run()) for name, run in RUNS.items()}
    PINNED.parent.mkdir(exist_ok=True)
    PINNED.write_text(json.dumps(platforms, indent=1) + "\n")
    print(f"wrote the pins of {processor()} to {PINNED}")
