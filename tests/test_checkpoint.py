import csv
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import textwrap
import time
import warnings
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import IN_CHUNKS, TINY
from helpers import NaNRewardAfter, assert_bitwise_equal

import fppo_jax
from fppo_jax import (
    ConfigMismatch,
    DamagedCheckpoint,
    IncompatibleFormat,
    TrainingDiverged,
    load_policy,
    train,
)
from fppo_jax.cli import main
from fppo_jax.core.trainer import METRICS
from fppo_jax.store import checkpoint
from fppo_jax.store.checkpoint import Checkpoints

RUN = {"env": "cartpole", "variant": "fppo-qp", "seed": 3, "total_steps": 128 * 20, **TINY}


def steps_on_disk(directory: Path) -> list[int]:
    """Complete checkpoints: orbax renames a step's directory to its number once written."""
    return sorted(int(p.name) for p in directory.iterdir() if p.name.isdigit())


def assert_same_run(a, b) -> None:
    assert_bitwise_equal(a.state, b.state)
    assert set(a.metrics) == set(b.metrics) == set(METRICS)
    assert_bitwise_equal(a.metrics, b.metrics)


def test_run_killed_with_sigkill_resumes_to_the_same_bits(tmp_path):
    checkpoints, logs = tmp_path / "checkpoints", tmp_path / "logs"
    # The child sleeps between chunks only so that the kill surely lands mid-run.
    child = subprocess.Popen(
        [
            sys.executable,
            "-c",
            textwrap.dedent(f"""
                import time, fppo_jax
                fppo_jax.train(**{RUN!r}, checkpoint_dir={str(checkpoints)!r},
                               checkpoint_every=1, log_dir={str(logs)!r},
                               progress=lambda p: time.sleep(0.3))
            """),
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    while not (checkpoints.is_dir() and len(steps_on_disk(checkpoints)) >= 2):
        assert child.poll() is None, child.stderr.read().decode()[-2000:]
        time.sleep(0.02)
    time.sleep(0.15)  # now somewhere in a chunk, a save or a sleep
    os.kill(child.pid, signal.SIGKILL)
    assert child.wait() == -signal.SIGKILL
    child.stderr.close()
    assert max(steps_on_disk(checkpoints)) < 20  # killed before the end

    resumed = train(
        **RUN, checkpoint_dir=checkpoints, resume=True, checkpoint_every=1, log_dir=logs
    )
    uninterrupted = train(**RUN, **IN_CHUNKS)  # in the resumed run's chunks
    assert resumed.resumed_from > 0
    assert_same_run(resumed, uninterrupted)
    # The log holds each update once, even those the killed run logged after its checkpoint.
    rows = list(csv.DictReader(open(logs / "metrics.csv")))
    assert [int(r["env_steps"]) for r in rows] == list(range(128, 128 * 21, 128))
    np.testing.assert_array_equal(
        [float(r["policy_loss"]) for r in rows], uninterrupted.metrics["policy_loss"]
    )


def damage(step_dir: Path, how: str) -> None:
    """Truncate or alter the largest data file of a checkpoint's state. Altered bytes are spread
    over the whole file: a data file may hold bytes that no array refers to (a few KiB that
    vary from one write to the next), and damage there is no damage."""
    files = [p for p in (step_dir / "state").rglob("*") if p.is_file()]
    target = max(files, key=lambda p: p.stat().st_size)
    data = bytearray(target.read_bytes())
    if how == "truncated":
        target.write_bytes(data[: len(data) // 2])
    else:
        for i in range(0, len(data), 1024):
            data[i] ^= 0xFF
        target.write_bytes(bytes(data))


@pytest.mark.parametrize("how", ["truncated", "altered"])
def test_damaged_latest_checkpoint_is_reported_and_the_previous_one_used(tmp_path, how):
    run = {**RUN, "total_steps": 128 * 4}
    first = train(**run, checkpoint_dir=tmp_path, checkpoint_every=1)
    assert steps_on_disk(tmp_path) == [2, 3, 4]
    damage(tmp_path / "4", how)

    with pytest.warns(DamagedCheckpoint, match="step 4 .* damaged"):
        again = train(**run, checkpoint_dir=tmp_path, resume=True, checkpoint_every=1)
    assert again.resumed_from == 3  # and update 4 was trained again, to the same bits
    assert_same_run(again, first)
    assert (tmp_path / "damaged" / "4").is_dir()  # set aside, not deleted
    assert steps_on_disk(tmp_path) == [2, 3, 4]


def test_a_checkpoint_is_deleted_only_once_a_newer_one_is_complete(tmp_path):
    state = {"x": jnp.arange(100_000.0), "key": jax.random.key(0)}
    curves = {"env_steps": np.arange(1, dtype=np.int32)}
    checkpoints = Checkpoints(tmp_path, keep=np.int64(1))  # numpy integers are integers
    checkpoints.save(1, state, curves, {"kind": "test"})
    checkpoints.wait()
    seen = []
    checkpoints.save(2, state, curves, {"kind": "test"})
    # While step 2 is being written, and until step 1 is deleted, a complete one is on disk.
    while len(seen) < 10_000 and (not seen or seen[-1] != [2]):
        seen.append(steps_on_disk(tmp_path))
    checkpoints.close()
    assert seen and all(seen)  # never without a complete checkpoint
    assert {tuple(steps) for steps in seen} <= {(1,), (1, 2), (2,)}
    assert steps_on_disk(tmp_path) == [2]
    restored = Checkpoints(tmp_path).restore(state)
    assert restored.step == 2
    assert_bitwise_equal(restored.state, state)


def test_resume_with_another_configuration_is_refused_naming_the_fields(tmp_path):
    run = {**RUN, "total_steps": 128 * 4}
    train(**run, checkpoint_dir=tmp_path, checkpoint_every=2)
    with pytest.raises(
        ConfigMismatch,
        match=r"differing: k: 0\.4 in the checkpoint, 0\.3 now; num_envs: 4 in the checkpoint, 8",
    ):
        train(**{**run, "num_envs": 8}, k=0.3, checkpoint_dir=tmp_path, resume=True)
    with pytest.raises(ValueError, match="already holds checkpoints; pass resume=True"):
        train(**run, checkpoint_dir=tmp_path)
    assert steps_on_disk(tmp_path) == [2, 4]  # untouched


def test_cli_refuses_to_overwrite_checkpoints_and_resumes_with_the_flag(tmp_path, capsys):
    flags = ["train", "--steps", "512", "--checkpoint-dir", str(tmp_path), "--quiet"]
    flags += ["--num-envs", "4", "--num-steps", "32", "--minibatches", "4", "--epochs", "2"]
    assert main(flags) == 0
    assert main(flags) == 2
    assert "already holds checkpoints; pass resume=True (--resume)" in capsys.readouterr().err
    assert main([*flags, "--resume"]) == 0
    assert "resumed at update 4" in capsys.readouterr().out


def test_load_policy_acts_as_the_trained_policy(tmp_path):
    result = train(**RUN, checkpoint_dir=tmp_path)
    policy = load_policy(tmp_path)
    obs = np.random.default_rng(0).normal(size=(64, 4)).astype(np.float32)
    np.testing.assert_array_equal(policy(obs), result.policy(obs))
    key = jax.random.key(1)
    np.testing.assert_array_equal(policy(obs, key), result.policy(obs, key))
    assert_bitwise_equal(policy.params, result.params["policy"])
    assert policy.observation_size == 4
    for wrong in (np.zeros(5, np.float32), np.zeros((64, 3), np.float32)):
        with pytest.raises(ValueError, match=r"takes observations of size 4 .*got shape"):
            policy(wrong)


def test_nan_guard_stops_the_run_and_keeps_the_last_good_checkpoint(tmp_path):
    run = {**TINY, "total_steps": 128 * 40}
    with pytest.raises(TrainingDiverged, match=r"update 3 .*checkpoint, at update 2, is in"):
        train(NaNRewardAfter(40), "fppo-lp", checkpoint_dir=tmp_path, checkpoint_every=1, **run)
    assert steps_on_disk(tmp_path) == [1, 2]
    assert Checkpoints(tmp_path).latest_record()["update"] == 2
    policy = load_policy(tmp_path)
    assert all(np.isfinite(x).all() for x in jax.tree.leaves(policy.params))


def test_interrupted_sweep_resumes_at_its_group_and_update(tmp_path):
    grid = {"variant": ["ppo", "fppo-lp"]}
    run = {"seeds": [0, 1], "chunk": 2, "total_steps": 128 * 6, **TINY}
    whole = fppo_jax.sweep("cartpole", grid, **run, **IN_CHUNKS)

    calls = []

    def interrupt(progress):
        calls.append(progress)
        # The second group of runs (3-4), after its update 4.
        if len(calls) > 5 and progress.update == 4:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        fppo_jax.sweep(
            "cartpole", grid, **run, progress=interrupt, checkpoint_dir=tmp_path, checkpoint_every=1
        )
    assert max(steps_on_disk(tmp_path)) == 6 + 4  # group 1, update 4
    resumed = fppo_jax.sweep(
        "cartpole", grid, **{**run, "chunk": None}, checkpoint_dir=tmp_path, resume=True
    )
    assert resumed.config["runs_per_call"] == 2
    assert_bitwise_equal(resumed.metrics, whole.metrics)
    np.testing.assert_array_equal(resumed.diverged, whole.diverged)


@pytest.mark.parametrize(
    "options, message",
    [
        ({"resume": True}, "resume needs a checkpoint directory"),
        ({"checkpoint_every": 3}, "checkpoint_every needs a checkpoint directory"),
        ({"checkpoint_dir": "unused", "keep": 0}, "keep must be a positive integer"),
        ({"checkpoint_dir": "unused", "checkpoint_every": 0}, "checkpoint_every must be"),
    ],
)
def test_bad_checkpoint_options_are_refused_before_compiling(tmp_path, options, message):
    if "checkpoint_dir" in options:
        options = {**options, "checkpoint_dir": tmp_path / "ckpt"}
    with pytest.raises(ValueError, match=message):
        train(**RUN, **options)
    with pytest.raises(ValueError, match=message):
        fppo_jax.sweep("cartpole", {"variant": "ppo"}, seeds=1, total_steps=512, **TINY, **options)


def test_all_checkpoints_damaged_is_an_error_never_a_silent_fresh_start(tmp_path):
    run = {**RUN, "total_steps": 128 * 4}
    train(**run, checkpoint_dir=tmp_path, checkpoint_every=2)
    for step in steps_on_disk(tmp_path):
        damage(tmp_path / str(step), "altered")
    with (
        pytest.warns(DamagedCheckpoint),
        pytest.raises(fppo_jax.CheckpointsUnavailable, match=r"no checkpoint in .* is intact"),
    ):
        train(**run, checkpoint_dir=tmp_path, resume=True, checkpoint_every=2)


def test_the_command_line_says_in_a_line_each_that_the_checkpoints_are_damaged(tmp_path):
    # Files cut short fail orbax's reads mid-way, and the reads still in flight then find its
    # event loop closed: Python would print a traceback for each (the library leaves them to
    # the process; the command, which owns its process, drops them). What fppo-jax says is one
    # line per damaged checkpoint and one error.
    flags = [
        *["train", "--env", "cartpole", "--variant", "fppo-qp", "--seed", "3", "--steps", "512"],
        *["--num-envs", "4", "--num-steps", "32", "--minibatches", "4", "--epochs", "2"],
        *["--quiet", "--checkpoint-dir", str(tmp_path), "--checkpoint-every", "2"],
    ]
    assert main(flags) == 0
    for step in steps_on_disk(tmp_path):
        damage(tmp_path / str(step), "truncated")
    path = os.pathsep.join(
        [str(Path(__file__).resolve().parents[1]), os.environ.get("PYTHONPATH", "")]
    )
    resumed = subprocess.run(
        [sys.executable, "-m", "fppo_jax", *flags, "--resume"],
        capture_output=True,
        text=True,
        env={**os.environ, "PYTHONPATH": path},
    )
    assert resumed.returncode == 2
    said = re.findall(
        r"fppo-jax: (?:warning: .*?trying the previous one|error: .*?choose another)",
        resumed.stderr,
    )
    assert len(said) == 3, resumed.stderr
    assert resumed.stderr.splitlines() == said, resumed.stderr  # and nothing else
    for line, step in zip(said, (4, 2), strict=False):
        assert line.startswith(
            f"fppo-jax: warning: checkpoint at step {step} in {tmp_path} is damaged (ValueError: "
        )
        assert line.endswith(
            f"moved to {tmp_path / 'damaged' / str(step)}, trying the previous one"
        )
    assert said[2] == (
        f"fppo-jax: error: no checkpoint in {tmp_path} is intact (each was moved to "
        f"{tmp_path / 'damaged'}); nothing was restored. To start afresh, remove the directory or "
        "choose another"
    )


def test_one_writer_per_checkpoint_directory_and_no_lock_outlives_its_process(tmp_path):
    from fppo_jax.store.checkpoint import open_checkpoints

    held, _ = open_checkpoints(tmp_path, False, 3, "train", {})
    try:
        with pytest.raises(fppo_jax.CheckpointsUnavailable, match=rf"pid {os.getpid()}"):
            train(**RUN, checkpoint_dir=tmp_path)
    finally:
        held.close()
    # A writer killed while it holds the lock: the next one is not blocked.
    holder = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import sys, threading; from fppo_jax.store.checkpoint import open_checkpoints; "
            "open_checkpoints(sys.argv[1], False, 3, 'train', {}); print('locked', flush=True); "
            "threading.Event().wait()",  # holds the lock until the test kills it
            str(tmp_path),
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout.readline().strip() == "locked"
        with pytest.raises(fppo_jax.CheckpointsUnavailable, match=rf"pid {holder.pid}"):
            train(**RUN, checkpoint_dir=tmp_path)
    finally:
        holder.kill()
        holder.wait()
    result = train(**RUN, checkpoint_dir=tmp_path)
    assert len(result.metrics["env_steps"]) == 20


def test_a_fallback_checkpoint_is_checked_against_the_run_too(tmp_path):
    run = {**RUN, "total_steps": 128 * 4}
    train(**run, checkpoint_dir=tmp_path / "mine", checkpoint_every=2)
    train(**{**run, "seed": 4}, checkpoint_dir=tmp_path / "other", checkpoint_every=2)
    # The older checkpoint is another run's (copied in by hand), the newer one damaged.
    shutil.rmtree(tmp_path / "mine" / "2")
    shutil.copytree(tmp_path / "other" / "2", tmp_path / "mine" / "2")
    damage(tmp_path / "mine" / "4", "altered")
    with (
        pytest.warns(DamagedCheckpoint),
        pytest.raises(ConfigMismatch, match="seed: 4 in the checkpoint, 3 now"),
    ):
        train(**run, checkpoint_dir=tmp_path / "mine", resume=True, checkpoint_every=2)


def test_checkpoints_whose_every_file_is_garbage_are_set_aside_never_a_fresh_start(tmp_path, capfd):
    flags = ["train", "--quiet", "--checkpoint-dir", str(tmp_path), "--checkpoint-every", "1"]
    flags += ["--steps", "512", "--num-envs", "4", "--num-steps", "32", "--minibatches", "4"]
    assert main([*flags, "--epochs", "2"]) == 0
    for path in tmp_path.glob("[0-9]*/**/*"):
        if path.is_file():
            path.write_text("garbage\n")
    capfd.readouterr()
    assert main([*flags, "--epochs", "2"]) == 2  # without --resume: refused, nothing written
    assert "already holds checkpoints (none of whose records can be read)" in capfd.readouterr().err
    assert main([*flags, "--epochs", "2", "--resume"]) == 2
    err = capfd.readouterr().err
    assert err.count("is damaged (ValueError: its record cannot be read)") == 3
    assert f"error: no checkpoint in {tmp_path} is intact" in err
    assert "Failed to json parse" not in err and "Traceback" not in err
    assert sorted(p.name for p in (tmp_path / "damaged").iterdir()) == ["2", "3", "4"]


def test_training_checkpointing_resuming_and_reading_leave_the_process_as_they_found_it(tmp_path):
    # In a process of its own, so that this one's logging, hooks and warning filters do not
    # interfere: the loggers that existed before (the root's, absl's, asyncio's, jax's,
    # orbax's...: level, filters, handlers), the unraisable hook and the warning filters are
    # as they were after importing fppo_jax, a run that checkpoints, its resume, load_policy
    # of its checkpoints and of a saved policy, a checkpointed sweep read back, and a resume
    # that finds its newest checkpoint damaged (orbax's own report of that failure may reach
    # the screen at its own level; nothing else of orbax's does). The libraries
    # the run uses set up their own on import (urllib3 and botocore add warning filters, absl
    # and jax loggers): the process imports them first, as a first process running the same
    # calls did (`modules`), so that what is compared is what the calls do.
    def calls(where: Path) -> str:
        return textwrap.dedent(
            f"""
            import sys
            import fppo_jax
            from fppo_jax import SweepResult
            shape = dict(num_envs=4, num_steps=32, num_minibatches=4, num_epochs=2,
                         progress=False)
            run = dict(env="cartpole", variant="ppo", checkpoint_dir={str(where / "run")!r},
                       checkpoint_every=2, **shape)
            fppo_jax.train(total_steps=512, **run)
            fppo_jax.train(total_steps=768, resume=True, **run)
            fppo_jax.load_policy({str(where / "run")!r})
            fppo_jax.sweep("cartpole", {{"variant": "ppo"}}, seeds=2, chunk=2, total_steps=256,
                           checkpoint_dir={str(where / "sweep-checkpoints")!r},
                           log_dir={str(where / "sweep")!r}, **shape)
            SweepResult.read({str(where / "sweep")!r})
            result = fppo_jax.train("cartpole", variant="ppo", total_steps=256, **shape)
            result.save({str(where / "policy")!r})
            fppo_jax.load_policy({str(where / "policy")!r})
            print("DAMAGED", file=sys.stderr, flush=True)  # orbax may speak from here on
            import pathlib
            steps = [p for p in pathlib.Path({str(where / "run")!r}).iterdir() if p.name.isdigit()]
            for file in (max(steps, key=lambda p: int(p.name)) / "state").rglob("*"):
                if file.is_file():
                    file.write_bytes(file.read_bytes()[: file.stat().st_size // 2])
            fppo_jax.train(total_steps=768, resume=True, **run)  # warns, and trains on
            """
        )

    def python(code: str) -> subprocess.CompletedProcess:
        return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)

    listed = python(
        calls(tmp_path / "first")
        + "\nimport json, sys\nprint(json.dumps([m for m in sys.modules if 'fppo_jax' not in m]))"
    )
    assert listed.returncode == 0, listed.stderr
    modules = json.loads(listed.stdout.splitlines()[-1])
    snapshot = textwrap.dedent(
        """
        import importlib, logging, sys, warnings

        def snapshot():
            loggers = {"": logging.getLogger()}
            for name, logger in logging.root.manager.loggerDict.items():
                if isinstance(logger, logging.Logger):
                    loggers[name] = logger
            state = {
                name: [logger.level, logger.propagate, logger.disabled,
                       [id(f) for f in logger.filters], [id(h) for h in logger.handlers]]
                for name, logger in loggers.items()
            }
            return state, logging.root.manager.disable, sys.unraisablehook, list(warnings.filters)

        for module in MODULES:
            try:
                importlib.import_module(module)
            except Exception:  # one that only its package may import
                pass
        before = snapshot()
        assert {"absl", "asyncio", "jax"} <= set(before[0]), sorted(before[0])
        """
    ).replace("MODULES", repr(modules))
    compare = textwrap.dedent(
        """
        after = snapshot()
        changed = {n: (v, after[0].get(n)) for n, v in before[0].items() if after[0].get(n) != v}
        assert not changed, changed
        assert after[1:] == before[1:], (before[1:], after[1:])
        logging.getLogger("absl").warning("the user's own absl warning")
        """
    )
    done = python(snapshot + calls(tmp_path / "second") + compare)
    assert done.returncode == 0, done.stderr
    assert "the user's own absl warning" in done.stderr
    quiet, failing = done.stderr.split("DAMAGED\n")
    assert "orbax" not in quiet.lower(), quiet  # quiet on its own where nothing fails
    assert "DamagedCheckpoint: checkpoint at step 6" in failing, failing


def test_a_checkpoint_of_another_format_is_refused_as_incompatible_and_left_as_it_is(
    tmp_path, monkeypatch
):
    run = {**RUN, "total_steps": 128 * 4}
    newer = checkpoint.FORMAT + 1
    monkeypatch.setattr(checkpoint, "FORMAT", newer)  # as a newer fppo-jax would write it
    train(**run, checkpoint_dir=tmp_path, checkpoint_every=2)
    monkeypatch.undo()
    before = sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*"))
    incompatible = rf"newer version of fppo-jax \(format {newer}; this one reads format"
    with warnings.catch_warnings():
        warnings.simplefilter("error", DamagedCheckpoint)  # not damage: nothing set aside
        with pytest.raises(IncompatibleFormat, match=rf"newest checkpoint in .*{incompatible}"):
            train(**run, checkpoint_dir=tmp_path, resume=True, checkpoint_every=2)
        with pytest.raises(IncompatibleFormat, match=rf"step 4 in .*{incompatible}"):
            load_policy(tmp_path)
        like = train(**{**run, "total_steps": 128}).state
        with pytest.raises(IncompatibleFormat, match=rf"step 4 in .*{incompatible}"):
            Checkpoints(tmp_path).restore(like)
    assert sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*")) == before
    assert not (tmp_path / "damaged").exists()


def test_a_checkpoint_of_the_first_format_gives_its_policy_but_does_not_resume(tmp_path):
    # The first format held a single run's state without the run axis; its policy is laid out
    # as now. A record without a format is of the first, written before formats were recorded.
    run = {**RUN, "total_steps": 128 * 2}
    first = train(**run, checkpoint_dir=tmp_path, checkpoint_every=2)
    written = tmp_path / "2" / "record" / "metadata"  # orbax's file of the JSON item
    record = json.loads(written.read_text())
    assert record.pop("format") == checkpoint.FORMAT == 2
    written.write_text(json.dumps(record))  # as fppo-jax wrote it before
    policy = load_policy(tmp_path)
    np.testing.assert_array_equal(policy(np.zeros(4)), first.policy(np.zeros(4)))
    with pytest.raises(IncompatibleFormat, match=r"\(format 1; this one reads format 2\)"):
        train(**{**run, "total_steps": 128 * 4}, checkpoint_dir=tmp_path, resume=True)
    assert not (tmp_path / "damaged").exists()


def test_orbax_custom_metadata_reads_damage_as_nothing_so_the_record_stays_an_item(tmp_path):
    # Why a checkpoint's record (its format, configuration and digests) is an item of its own,
    # written and read through orbax, rather than orbax's custom_metadata: a damaged
    # _CHECKPOINT_METADATA reads back as {}, as a checkpoint saved without any does (orbax
    # logs it, and raises nothing), so the record's own format and digests could not be told
    # from no record; and moving the record would hide its format from every earlier fppo-jax,
    # which would take each new checkpoint for damaged and set it aside, not refuse it.
    import orbax.checkpoint as ocp

    options = ocp.CheckpointManagerOptions(create=True, enable_async_checkpointing=False)
    manager = ocp.CheckpointManager(tmp_path, options=options)
    state = ocp.args.Composite(state=ocp.args.StandardSave({"x": np.arange(3.0)}))
    manager.save(1, args=state, custom_metadata={"format": 3})
    manager.save(2, args=state)
    assert manager.metadata(1).custom_metadata == {"format": 3}
    (tmp_path / "1" / "_CHECKPOINT_METADATA").write_text("garbage")
    assert manager.metadata(1).custom_metadata == {} == manager.metadata(2).custom_metadata
    manager.close()


def test_orbax_reads_a_flipped_byte_as_other_values_so_checkpoints_keep_their_digests(tmp_path):
    # Why each checkpoint's record holds a digest of its arrays: orbax checks no content of its
    # own, and an altered data file reads back without an error, as other values.
    import orbax.checkpoint as ocp

    options = ocp.CheckpointManagerOptions(create=True, enable_async_checkpointing=False)
    manager = ocp.CheckpointManager(tmp_path, options=options)
    x = np.random.default_rng(0).normal(size=100_000)
    manager.save(1, args=ocp.args.Composite(state=ocp.args.StandardSave({"x": x})))
    data = max(
        (p for p in (tmp_path / "1" / "state").rglob("*") if p.is_file()), key=os.path.getsize
    )
    altered = bytearray(data.read_bytes())
    altered[len(altered) // 2] ^= 0x01
    data.write_bytes(bytes(altered))
    read = manager.restore(1, args=ocp.args.Composite(state=ocp.args.StandardRestore()))
    assert np.sum(read.state["x"] != x) > 0  # compressed, one byte alters a block of values
    manager.close()
