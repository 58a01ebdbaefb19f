"""Training pinned bit for bit: short seeded runs against the metrics recorded in
``tests/data/pinned_metrics.json``.

A change that moves any bit of a run's metrics fails here, loudly: the seed study's parts
(``experiments/study.py``), recorded across sessions, are comparable only while training is
unchanged. A change meant to alter training re-records them and says so in its commit, with
``python tests/test_regression.py --record``; the study's parts recorded before it then
belong to another protocol. The pins were recorded with jax 0.10.2 on an x86-64 CPU; XLA on
another version or processor may round differently.
"""

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from fppo_jax import sweep, train

PINNED = Path(__file__).resolve().parent / "data" / "pinned_metrics.json"
TINY = {"num_envs": 4, "num_steps": 32, "num_minibatches": 4, "num_epochs": 2}

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


@pytest.mark.parametrize("name", list(RUNS))
def test_training_is_unchanged_bit_for_bit(name):
    pinned = json.loads(PINNED.read_text())[name]
    found = fingerprint(RUNS[name]())
    assert sorted(found) == sorted(pinned), "the metrics recorded per update changed"
    changed = [m for m in pinned if found[m]["hex"] != pinned[m]["hex"]]
    detail = "; ".join(
        f"{m}: pinned {pinned[m]['values'][:3]}, now {found[m]['values'][:3]}" for m in changed[:3]
    )
    assert not changed, (
        f"training changed: {len(changed)} metrics differ from the pins ({detail}). If this is "
        "meant, re-record with `python tests/test_regression.py --record` and say so: the seed "
        "study's parts recorded before the change are then another protocol."
    )


if __name__ == "__main__":
    if sys.argv[1:] != ["--record"]:
        sys.exit("usage: python tests/test_regression.py --record")
    PINNED.parent.mkdir(exist_ok=True)
    record = {name: fingerprint(run()) for name, run in RUNS.items()}
    PINNED.write_text(json.dumps(record, indent=1) + "\n")
    print(f"wrote {PINNED}")
