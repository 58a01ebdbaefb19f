"""A run and a sweep killed with SIGKILL at one moment after another, each time resumed by the
same call with ``resume=True``, end as an uninterrupted one does: every metric bit for bit, and
for a run the whole training state (the parameters among it); for a sweep its ``diverged`` too.

Each attempt is a child process, parked at the moment wanted (its callback, or orbax's rename of
a checkpoint written in full, prints a marker and sleeps) or caught compiling; the parent sees
the marker and the checkpoint directory in the state wanted, and kills it. Each resumed attempt
is checked to start where the checkpoints on disk say. The attempts of a test share a
persistent compilation cache, so that only the first one compiles: attempts killed one after
another in one directory, rather than each moment on its own, keep the module fast.
"""

import json
import os
import re
import signal
import subprocess
import sys
import textwrap
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from conftest import TINY

from fppo_jax.envs import native

ROOT = Path(__file__).resolve().parents[1]

# Every update is checkpointed and then seen by the callback (checkpoint_every=1); the sweep's
# two runs train one at a time (chunk=1), so that it has a group boundary. progress=True prints
# "compiling…" before compiling: the marker of that moment.
CALLS = {
    "train": {"env": "cartpole", "variant": "fppo-qp", "seed": 3, "total_steps": 128 * 4},
    "sweep": {
        "env": "cartpole",
        "grid": {"variant": ["ppo", "fppo-lp"]},
        "seeds": [0],
        "chunk": 1,
        "total_steps": 128 * 3,
    },
}
CALLS["native"] = {**CALLS["train"], "env": "swimmer", "backend": "native"}
OPTIONS = {**TINY, "checkpoint_every": 1, "progress": True}
UPDATES = {"train": 4, "sweep": 3, "native": 4}  # per run; a checkpoint's step is
# group · updates + update

# The attempts, in order, in one checkpoint directory: how each is stopped, and where it must
# start (the first run and update its callback sees; None: it trains nothing).
# "parked": killed in the callback after (run, update), once that update's checkpoint is on disk;
# "writing": killed while checkpoint `step` is in its temporary directory, not yet renamed.
CHAINS = {
    "train": [
        ("compiling", None, None),  # before any checkpoint exists
        ("writing", 1, (0, 1)),  # resumed with no checkpoint: afresh
        ("parked", (0, 2), (0, 1)),  # a write killed is no checkpoint: afresh again
        ("writing", 4, (0, 3)),  # the last checkpoint
        ("end", None, (0, 4)),
        ("end", None, None),  # finished: it trains nothing and gives the same results
    ],
    "sweep": [
        ("compiling", None, None),
        ("parked", (0, 2), (0, 1)),  # mid-group
        ("parked", (0, 3), (0, 3)),  # group 0's last checkpoint, before group 1's first
        ("compiling", None, None),  # a resumed attempt, with checkpoints on disk
        ("writing", 4, (1, 1)),  # group 1's first checkpoint: group 0 has nothing left
        ("parked", (1, 2), (1, 1)),  # mid-group, with a finished group in the checkpoint
        ("end", None, (1, 3)),
        ("end", None, None),
    ],
}

# The child: trains `spec["call"]` (train or sweep), prints the run and update of every chunk,
# parks where the spec says, and writes what the call returned to `spec["out"]`.
CHILD = textwrap.dedent("""
    import json, sys, time
    import jax, numpy as np
    import fppo_jax

    spec = json.loads(sys.argv[1])

    def park(where):
        print(f"parked {where}", flush=True)
        while True:  # until the test kills it
            time.sleep(1)

    def callback(snapshot):
        print(f"chunk {snapshot.runs.start} {snapshot.update}", flush=True)
        if [snapshot.runs.start, snapshot.update] == spec["parked"]:
            park("in the callback")

    if spec["writing"] is not None:  # orbax's last step of a save, on a local file system
        from orbax.checkpoint._src.path import atomicity

        rename = atomicity.AtomicRenameTemporaryPath.finalize

        async def finalize(self):  # a checkpoint written in full, before its rename
            if self.get_final().name == str(spec["writing"]):
                park(f"writing {self.get()}")
            await rename(self)

        atomicity.AtomicRenameTemporaryPath.finalize = finalize

    result = getattr(fppo_jax, spec["kind"])(**spec["call"], callback=callback)
    arrays = {f"metrics/{name}": v for name, v in result.metrics.items()}
    if spec["kind"] == "train":
        for path, leaf in jax.tree_util.tree_flatten_with_path(result.state)[0]:
            if jax.dtypes.issubdtype(leaf.dtype, jax.dtypes.prng_key):
                leaf = jax.random.key_data(leaf)
            arrays["state" + jax.tree_util.keystr(path)] = np.asarray(leaf)
        arrays["resumed_from"] = np.asarray(result.resumed_from)
    else:
        arrays["diverged"] = result.diverged
    np.savez(spec["out"], **arrays)
""")


def steps_on_disk(directory: Path) -> list[int]:
    """Complete checkpoints: orbax renames a step's directory to its number once written."""
    return sorted(int(p.name) for p in directory.iterdir() if p.name.isdigit())


def writes_in_progress(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.glob("*.orbax-checkpoint-tmp*"))


@contextmanager
def child(kind, directory, log, cache, *, resume, parked=None, writing=None):
    """A child process training `kind` with checkpoints in `directory`, its output in `log`;
    killed on leaving, if still running. `cache`: the compilation cache, or None for none."""
    call = {**CALLS[kind], **OPTIONS, "checkpoint_dir": str(directory), "resume": resume}
    function = "sweep" if kind == "sweep" else "train"
    spec = {"kind": function, "call": call, "out": str(log.with_suffix(".npz"))}
    spec.update(parked=parked, writing=writing)
    path = os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])
    env = {**os.environ, "PYTHONPATH": path}
    if cache is not None:
        env["JAX_COMPILATION_CACHE_DIR"] = str(cache)
        env["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] = "0"
    else:  # nor the session's, where another test may have put the same program
        env["FPPO_JAX_CACHE_DIR"] = "off"
    with open(log, "w") as stream:
        process = subprocess.Popen(
            [sys.executable, "-c", CHILD, json.dumps(spec)],
            stdout=stream,
            stderr=subprocess.STDOUT,
            env=env,
        )
    process.log = log
    try:
        yield process
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()


def output(process) -> str:
    return process.log.read_text(errors="replace")


def first_chunk(log: Path) -> tuple[int, int] | None:
    """The run and update of the first chunk a child trained, if any."""
    found = re.search(r"^chunk (\d+) (\d+)$", log.read_text(errors="replace"), re.MULTILINE)
    return (int(found[1]), int(found[2])) if found else None


def wait_until(process, marker: str, ready=lambda: True, what: str = "") -> None:
    """Poll until the child has printed `marker` and `ready()`; fail if it ends first."""
    what = what or repr(marker)
    while not (marker in output(process) and ready()):
        assert process.poll() is None, f"the child ended before {what}:\n{output(process)[-3000:]}"
        time.sleep(0.01)


def kill(process) -> None:
    os.kill(process.pid, signal.SIGKILL)
    assert process.wait() == -signal.SIGKILL


def results(process) -> dict[str, np.ndarray]:
    """What the child's call returned, once it has ended well."""
    assert process.wait() == 0, output(process)[-3000:]
    with np.load(process.log.with_suffix(".npz")) as arrays:
        return dict(arrays)


def assert_same_results(resumed: dict, whole: dict) -> None:
    """Every metric (and a run's state, a sweep's `diverged`) equal bit for bit."""
    names = set(whole) - {"resumed_from"}
    assert set(resumed) - {"resumed_from"} == names
    assert any(name.startswith("metrics/") for name in names)
    for name in sorted(names):
        a, b = resumed[name], whole[name]
        assert (a.dtype, a.shape) == (b.dtype, b.shape), name
        assert a.tobytes() == b.tobytes(), name


def attempt(kind, directory, log, cache, stop, where) -> dict | None:
    """One attempt at training `kind`, stopped as `stop` and `where` say (see CHAINS), and the
    checks of the directory it leaves; its results if it ended."""
    resume = directory.exists()  # the first attempt is the plain call
    if stop == "compiling":
        before = steps_on_disk(directory) if resume else []
        # Without the cache it compiles for seconds, so the kill surely lands in it.
        with child(kind, directory, log, None, resume=resume) as process:
            wait_until(process, "compiling")
            kill(process)
        assert steps_on_disk(directory) == before, log.stem
        return None
    parked = list(where) if stop == "parked" else None
    writing = where if stop == "writing" else None
    with child(kind, directory, log, cache, resume=resume, parked=parked, writing=writing) as p:
        if stop == "end":
            return results(p)
        if stop == "parked":
            step = where[0] * UPDATES[kind] + where[1]
            # Its checkpoint, begun before the callback, completes in the background.
            wait_until(p, "parked", lambda: step in steps_on_disk(directory), f"checkpoint {step}")
            kill(p)
            assert max(steps_on_disk(directory)) == step, log.stem
        else:
            # Parked with the checkpoint written in full under its temporary name.
            wait_until(p, "parked", lambda: writes_in_progress(directory), f"writing {where}")
            kill(p)
            left = [name.split(".")[0] for name in writes_in_progress(directory)]
            assert left == [str(where)], log.stem
            assert steps_on_disk(directory)[-1:] == ([where - 1] if where > 1 else []), log.stem
    return None


@pytest.mark.parametrize(
    "kind",
    # Each chain takes over a minute on a CPU: with -m slow. In the default run a run killed
    # mid-chunk resumes to the same bits (tests/test_checkpoint.py), and a sweep resumed after
    # its end (tests/test_driver.py).
    [pytest.param("train", marks=pytest.mark.slow), pytest.param("sweep", marks=pytest.mark.slow)],
)
def test_killed_at_every_moment_and_resumed_each_time_ends_as_if_never_stopped(kind, tmp_path):
    cache, directory = tmp_path / "jax-cache", tmp_path / "checkpoints"
    # Uninterrupted first, to fill the compilation cache: with the same options, so that it is
    # the same compiled program, and in a directory of its own.
    whole = attempt(kind, tmp_path / "uninterrupted", tmp_path / "whole.log", cache, "end", None)
    for number, (stop, where, starts) in enumerate(CHAINS[kind]):
        log = tmp_path / f"{number}-{stop}.log"
        resumed = attempt(kind, directory, log, cache, stop, where)
        assert first_chunk(log) == starts, log.stem
        if resumed is not None:
            assert_same_results(resumed, whole)
            if kind == "train":
                assert resumed["resumed_from"] == (starts[1] - 1 if starts else UPDATES[kind])
    assert writes_in_progress(directory) == []  # the ones left were written over


# About a minute on 2 cores, with -m slow; in the default run a resumed native run restarts its
# environments and keeps its learning (tests/test_native.py).
@pytest.mark.slow
def test_a_killed_native_run_resumes_in_fresh_environments_with_its_learning_intact(tmp_path):
    if not native.envpool_installed():
        pytest.skip("the native backend's envpool is Linux-only")
    directory = tmp_path / "checkpoints"
    whole = attempt("native", tmp_path / "uninterrupted", tmp_path / "whole.log", None, "end", None)
    assert attempt("native", directory, tmp_path / "killed.log", None, "parked", (0, 2)) is None
    log = tmp_path / "resumed.log"
    resumed = attempt("native", directory, log, None, "end", None)
    # Restored from the checkpoint of update 2, with environments started afresh (their state
    # lived in envpool, which no checkpoint holds), and said so.
    assert resumed["resumed_from"] == 2 and first_chunk(log) == (0, 3)
    assert "resuming at update 2 in fresh environments" in log.read_text()
    # The updates before the kill are the uninterrupted run's, bit for bit; the ones after go on
    # from what was learnt but from new episodes, so they are not.
    for name in ("policy_loss", "value_loss", "entropy"):
        a, b = resumed[f"metrics/{name}"], whole[f"metrics/{name}"]
        assert a.shape == b.shape == (UPDATES["native"],)
        assert a[:2].tobytes() == b[:2].tobytes(), name
        assert np.isfinite(a).all() and not np.array_equal(a[2:], b[2:]), name
    samples = TINY["num_envs"] * TINY["num_steps"]
    assert resumed["state.obs_stats.count"] == pytest.approx(UPDATES["native"] * samples, abs=1e-3)
