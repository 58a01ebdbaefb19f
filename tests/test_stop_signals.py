"""A cluster's stop signals: a checkpointed run stops at the end of its chunk of updates,
checkpointed, and leaves the process's signal handlers as it found them; the command catches
them from its first moment, before it imports JAX; a tune and a study stop at their next safe
point and go on bit for bit; a stopped command's exit status is its own, whatever the
interpreter's teardown would do."""

import dataclasses
import os
import re
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from conftest import TINY
from helpers import TUNE_ARMS, TUNE_SMALL, rung_scores

import fppo_jax
import fppo_jax.run.training as training
from fppo_jax import train
from fppo_jax.analysis import population
from fppo_jax.analysis.studies import study
from fppo_jax.analysis.tuning import tune
from fppo_jax.cli import INTERRUPTED, main
from fppo_jax.run.stop_signals import STOP_SIGNALS, StoppedAtSafePoint
from fppo_jax.store.saved_policy import read_policy

ROOT = Path(__file__).resolve().parents[1]
FLAGS = ["train", "--env", "cartpole", "--variant", "ppo", "--steps", "512", "--num-envs", "4"]
FLAGS += ["--num-steps", "32", "--minibatches", "4", "--epochs", "2", "--checkpoint-every", "1"]


def signal_after_first_chunk(monkeypatch, number):
    """The process sends itself `number` while the first chunk of updates is being handled."""
    run_chunks = training.run_chunks

    def chunks_then_signal(*args):
        for index, chunk in enumerate(run_chunks(*args)):
            if index == 0:
                os.kill(os.getpid(), number)
            yield chunk

    monkeypatch.setattr(training, "run_chunks", chunks_then_signal)


@pytest.mark.parametrize("number, status", [(signal.SIGTERM, 143), (signal.SIGUSR1, 138)])
def test_a_stop_signal_checkpoints_the_chunk_and_exits_for_a_requeue(
    tmp_path, monkeypatch, capsys, number, status
):
    before = {n: signal.getsignal(n) for n in STOP_SIGNALS}
    signal_after_first_chunk(monkeypatch, number)
    flags = [*FLAGS, "--checkpoint-dir", str(tmp_path)]
    assert main(flags) == status
    assert {n: signal.getsignal(n) for n in STOP_SIGNALS} == before
    error = capsys.readouterr().err
    assert f"stopped by {signal.Signals(number).name} after update 1, checkpointed in" in error
    assert read_policy(tmp_path)[1]["update"] == 1

    monkeypatch.undo()
    assert main([*flags, "--resume"]) == 0
    assert "updates   4 × 128 samples" in capsys.readouterr().out


# The command in a process of its own, which sends itself the signal where it is told: as it
# starts (in what the command does first, before it imports the trainer) or while it compiles.
# Uncaught, the signal would end the process there.
SIGNALLED_WHILE = textwrap.dedent("""
    import importlib, os, sys
    from fppo_jax.cli import entry_point

    where, number, *flags = sys.argv[1:]
    module, name = {
        "starting": ("fppo_jax.run.compile_cache", "enable"),
        "compiling": ("fppo_jax.run.driver", "compile_program"),
    }[where]
    module = importlib.import_module(module)
    at = getattr(module, name)

    def signalled(*args, **kwargs):
        os.kill(os.getpid(), int(number))
        return at(*args, **kwargs)

    setattr(module, name, signalled)
    sys.argv[1:] = flags
    entry_point()
""")


@pytest.mark.parametrize(
    "where, number, status",
    [("starting", signal.SIGTERM, 143), ("compiling", signal.SIGUSR1, 138)],
)
def test_a_stop_signal_before_training_stops_the_command_once_compiled(
    tmp_path, capsys, where, number, status
):
    flags = [*FLAGS, "--checkpoint-dir", str(tmp_path), "--resume"]
    done = subprocess.run(
        [sys.executable, "-c", SIGNALLED_WHILE, where, str(int(number)), *flags],
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        capture_output=True,
        text=True,
    )
    assert done.returncode == status, done.stderr[-3000:]
    last = done.stderr.splitlines()[-1]
    assert last == (
        f"fppo-jax: stopped by {signal.Signals(number).name} before training (while starting "
        "or compiling), nothing new checkpointed; resume (--resume) to go on from the newest "
        f"checkpoint in {tmp_path}, or from the start if there is none"
    )
    assert "compiled in" not in done.stderr and not [
        p for p in tmp_path.iterdir() if p.name.isdigit()
    ]
    assert main(flags) == 0  # the same command again trains the run
    assert "updates   4 × 128 samples" in capsys.readouterr().out


def test_signals_are_caught_only_for_a_checkpointed_run(tmp_path, tiny):
    seen = []

    def handlers(snapshot):
        seen.append(signal.getsignal(signal.SIGTERM))

    before = signal.getsignal(signal.SIGTERM)
    train("cartpole", "ppo", total_steps=256, callback=handlers, **tiny)
    assert seen[-1] is before  # nothing to save: the signal's own action is kept
    train("cartpole", "ppo", total_steps=256, callback=handlers, checkpoint_dir=tmp_path, **tiny)
    assert seen[-1] is not before and signal.getsignal(signal.SIGTERM) is before


def test_a_signal_in_the_last_chunk_lets_the_run_finish(tmp_path, tiny):
    def signal_at_the_end(snapshot):
        if snapshot.update == 2:
            os.kill(os.getpid(), signal.SIGTERM)

    result = train(
        "cartpole",
        "ppo",
        total_steps=256,
        checkpoint_dir=tmp_path,
        callback=signal_at_the_end,
        checkpoint_every=1,
        **tiny,
    )
    assert result.metrics["env_steps"].shape == (2,)
    with pytest.raises(fppo_jax.StoppedBySignal, match="after update 1"):
        train(
            "cartpole",
            "ppo",
            total_steps=256,
            checkpoint_dir=tmp_path / "b",
            checkpoint_every=1,
            callback=lambda s: os.kill(os.getpid(), signal.SIGTERM),
            **tiny,
        )


# Ctrl-C in a terminal: the process sends itself SIGINT once the first chunk of updates is
# logged, with Python's own handler installed as a terminal leaves it.
INTERRUPTED_AFTER_FIRST_CHUNK = textwrap.dedent("""
    import os, signal, sys
    import fppo_jax.run.training as training
    from fppo_jax.cli import entry_point

    signal.signal(signal.SIGINT, signal.default_int_handler)
    run_chunks = training.run_chunks

    def chunks_then_interrupt(*args):
        for index, chunk in enumerate(run_chunks(*args)):
            if index == 1:
                os.kill(os.getpid(), signal.SIGINT)
            yield chunk

    training.run_chunks = chunks_then_interrupt
    sys.argv[1:] = sys.argv[2:]
    entry_point()
""")


def test_ctrl_c_ends_the_command_in_a_line_keeping_what_it_wrote(tmp_path):
    flags = [*FLAGS[:-2], "--steps", "4096", "--output", str(tmp_path / "run")]
    done = subprocess.run(
        [sys.executable, "-c", INTERRUPTED_AFTER_FIRST_CHUNK, "--", *flags],
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        capture_output=True,
        text=True,
    )
    assert done.returncode == 128 + signal.SIGINT, done.stderr[-3000:]
    assert "Traceback" not in done.stderr, done.stderr[-3000:]
    assert done.stderr.splitlines()[-1] == INTERRUPTED
    logged = (tmp_path / "run" / "metrics.csv").read_text().splitlines()
    assert 2 <= len(logged) < 1 + 4096 // 128  # a header and whole rows, stopped mid-run
    assert all(row.count(",") == logged[0].count(",") for row in logged)


# The command in a process of its own, which sends itself a signal as it first imports JAX:
# seconds into its start, before which a command that caught signals once it had imported what
# its flags need ended at once, with no line.
SIGNALLED_AS_JAX_IS_IMPORTED = textwrap.dedent("""
    import os, sys

    number, sys.argv[1:] = int(sys.argv[1]), sys.argv[2:]

    class SignalledOnImport:
        def find_spec(self, name, path=None, target=None):
            if name == "jax":
                sys.meta_path.remove(self)
                os.kill(os.getpid(), number)

    sys.meta_path.insert(0, SignalledOnImport())
    from fppo_jax.cli import entry_point

    entry_point()
""")
TUNE_FLAGS = ["tune", "--variants", ",".join(TUNE_ARMS), "--tasks", "cartpole", "--trials", "4"]
TUNE_FLAGS += ["--eta", "2", "--steps", "1024", *FLAGS[7:15], "--score", "train", "--quiet"]
TUNE_FLAGS += ["--finalists", "1", "--validation-seeds", "4", "--race-level", "0.1"]


def signalled_as_jax_is_imported(number, flags):
    return subprocess.run(
        [sys.executable, "-c", SIGNALLED_AS_JAX_IS_IMPORTED, str(int(number)), *flags],
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        capture_output=True,
        text=True,
    )


def test_a_signal_as_the_command_imports_jax_stops_a_checkpointed_run_once_compiled(tmp_path):
    flags = [*FLAGS, "--checkpoint-dir", str(tmp_path)]
    done = signalled_as_jax_is_imported(signal.SIGTERM, flags)
    assert done.returncode == 143, done.stderr[-3000:]
    assert done.stderr.splitlines()[-1].startswith(
        "fppo-jax: stopped by SIGTERM before training (while starting or compiling)"
    )


def test_a_signal_as_the_command_imports_jax_stops_a_tune_before_its_first_rung(tmp_path):
    done = signalled_as_jax_is_imported(signal.SIGUSR1, [*TUNE_FLAGS, "--output", str(tmp_path)])
    assert done.returncode == 138, done.stderr[-3000:]
    assert done.stderr.splitlines()[-1] == (
        "fppo-jax: stopped by SIGUSR1 at rung 1 of 4 of cartpole; the same command goes on "
        "from rung 1"
    )
    assert (tmp_path / "tune.json").is_file() and not list(tmp_path.glob("cartpole/rung-*"))


def test_a_command_that_does_not_catch_signals_gets_the_one_that_came_as_it_started():
    # Held while the command imported JAX, then acting as it would have: the end of the process.
    done = signalled_as_jax_is_imported(signal.SIGTERM, ["list"])
    assert done.returncode == -signal.SIGTERM and done.stdout == ""


def signal_in_first_call(monkeypatch, number):
    """The process sends itself `number` while the first compiled call of the next program a
    tune compiles is in flight."""
    compile_program = population.compile_program

    def compiled(*args, **kwargs):
        program = compile_program(*args, **kwargs)
        run = program.run

        def signalled(*inputs):
            output = run(*inputs)
            if not sent:
                sent.append(os.kill(os.getpid(), number))
            return output

        return dataclasses.replace(program, run=signalled)

    sent: list[None] = []
    monkeypatch.setattr(population, "compile_program", compiled)


def test_a_tune_stops_after_the_call_in_flight_and_goes_on_bit_for_bit(
    tmp_path, monkeypatch, capsys
):
    whole, stopped = tmp_path / "whole", tmp_path / "stopped"
    tune("cartpole", TUNE_ARMS, output=whole, rungs=1, **TUNE_SMALL)
    before = {n: signal.getsignal(n) for n in STOP_SIGNALS}
    with monkeypatch.context() as patch:
        signal_in_first_call(patch, signal.SIGUSR1)  # the first of rung 1's 2 calls
        with pytest.raises(StoppedAtSafePoint) as raised:
            tune("cartpole", TUNE_ARMS, output=stopped, **TUNE_SMALL)
    assert str(raised.value) == (
        "stopped by SIGUSR1 at rung 1 of 4 of cartpole; the same command goes on from rung 1"
    )
    assert isinstance(raised.value, fppo_jax.StoppedBySignal) and raised.value.signal == 10
    assert {n: signal.getsignal(n) for n in STOP_SIGNALS} == before
    assert not (stopped / "cartpole/rung-0").exists()  # nothing of the rung stopped in
    # Gone on with, its program (the process's own, here said to be the compilation cache's).
    compile_program = population.compile_program

    def loaded(*args, **kwargs):
        return dataclasses.replace(compile_program(*args, **kwargs), loaded=True)

    with monkeypatch.context() as patch:
        patch.setattr(population, "compile_program", loaded)
        tune("cartpole", TUNE_ARMS, output=stopped, rungs=1, **{**TUNE_SMALL, "progress": True})
    said = capsys.readouterr().err
    line = r"^cartpole: rung 1 loaded from the compilation cache in \d+\.\d s$"
    assert re.search(line, said, re.MULTILINE), said
    assert [r["arms"] for r in rung_scores(stopped)] == [r["arms"] for r in rung_scores(whole)]
    with (
        np.load(whole / "cartpole/rung-0/state.npz") as a,
        np.load(stopped / "cartpole/rung-0/state.npz") as b,
    ):
        assert all(np.array_equal(a[name], b[name], equal_nan=True) for name in a.files)
    # A share of a split rung (here its one group, the program above) trains again whole.
    signal_in_first_call(monkeypatch, signal.SIGTERM)
    with pytest.raises(StoppedAtSafePoint, match="at rung 1 of 4 of cartpole, part 1 of 2; the"):
        tune("cartpole", TUNE_ARMS, output=tmp_path / "part", chunk=16, part=(1, 2), **TUNE_SMALL)
    assert not (tmp_path / "part/cartpole/rung-0/part-1").exists()


def test_a_study_stops_after_the_chunk_in_flight_and_goes_on_from_its_groups(tmp_path, monkeypatch):
    arguments = dict(max_seeds=4, group_size=2, total_steps=8 * 128, progress=False, **TINY)
    whole = study("cartpole", "fppo-lp", "ppo", output=tmp_path / "whole", **arguments)
    run_chunks, sweeps = training.run_chunks, []

    def second_group_signalled(*args):  # the second group's sweep, after its first chunk
        sweeps.append(None)
        for index, chunk in enumerate(run_chunks(*args)):
            if len(sweeps) == 2 and index == 0:
                os.kill(os.getpid(), signal.SIGTERM)
            yield chunk

    monkeypatch.setattr(training, "run_chunks", second_group_signalled)
    with pytest.raises(StoppedAtSafePoint) as raised:
        study("cartpole", "fppo-lp", "ppo", output=tmp_path / "stopped", **arguments)
    assert str(raised.value) == (
        "stopped by SIGTERM at cartpole's group-2 (seeds 2–3), the groups before it recorded; "
        "the same command goes on from there"
    )
    monkeypatch.undo()
    again = study("cartpole", "fppo-lp", "ppo", output=tmp_path / "stopped", **arguments)
    assert again.decisions == whole.decisions
    for name, values in whole.results["cartpole"].metrics.items():
        assert np.array_equal(again.results["cartpole"].metrics[name], values, equal_nan=True)


# A checkpointed run that a signal stops after its first chunk, in a process whose interpreter
# crashes as it tears down, as it did when the compiled call dispatched ahead of that chunk was
# still running (3 stops in 27 here, status 139).
CRASHES_AS_IT_ENDS = textwrap.dedent("""
    import atexit, ctypes, os, signal, sys
    import fppo_jax.run.training as training
    from fppo_jax.cli import entry_point

    run_chunks = training.run_chunks

    def chunks_then_signal(*args):
        for index, chunk in enumerate(run_chunks(*args)):
            if index == 0:
                os.kill(os.getpid(), signal.SIGTERM)
            yield chunk

    training.run_chunks = chunks_then_signal
    atexit.register(ctypes.string_at, 0)  # a segmentation fault
    sys.argv[1:] = sys.argv[2:]
    entry_point()
""")


def test_a_stopped_command_exits_with_its_status_whatever_the_teardown_would_do(tmp_path):
    flags = [*FLAGS, "--checkpoint-dir", str(tmp_path)]
    done = subprocess.run(
        [sys.executable, "-c", CRASHES_AS_IT_ENDS, "--", *flags],
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        capture_output=True,
        text=True,
    )
    assert done.returncode == 143, done.stderr[-3000:]
    assert done.stderr.splitlines()[-1].startswith("fppo-jax: stopped by SIGTERM after update 1")
    assert read_policy(tmp_path)[1]["update"] == 1
