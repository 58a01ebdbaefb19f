"""The driver that train and sweep share (fppo_jax.run.driver): logs and tracking, options and
outputs checked before compiling, the group size chosen once, programs compiled once and
reused, and a finished run going on for more steps."""

import csv
import json
import os
import re
import sys
from pathlib import Path

import jax
import numpy as np
import pytest
from conftest import IN_CHUNKS, TINY
from helpers import BAD_SEEDS, assert_bitwise_equal

import fppo_jax
import fppo_jax.run.driver
from fppo_jax import ConfigMismatch, make_env, sweep, train
from fppo_jax.cli import main
from fppo_jax.envs import native

RUN = {"env": "cartpole", "variant": "fppo-lp", "seed": 1, "total_steps": 128 * 12, **TINY}


def test_config_json_is_written_before_training_with_versions_and_devices(tmp_path):
    seen = {}

    def progress(p):
        if p.update == 0:  # reported once compiled, before the first update
            seen.update(json.loads((tmp_path / "config.json").read_text()))

    train(**RUN, log_dir=tmp_path, progress=progress)
    assert seen["variant"] == "fppo-lp" and seen["alpha"] == 1.3 and seen["num_envs"] == 4
    assert seen["versions"]["jax"] == __import__("jax").__version__
    assert seen["platform"] == "cpu" and seen["devices"]


def test_a_sweep_logs_every_run_and_its_evaluations(tmp_path):
    result = sweep(
        "cartpole",
        {"variant": ["ppo", "fppo-qp"]},
        seeds=2,
        chunk=2,
        total_steps=128 * 4,
        **TINY,
        log_dir=tmp_path,
        eval_every=2,
        eval_episodes=2,
    )
    with open(tmp_path / "metrics.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 4 * 4  # runs × updates
    for row in rows:
        run, update = int(row["run"]), int(row["env_steps"]) // 128 - 1
        assert float(row["policy_loss"]) == pytest.approx(
            float(result.metrics["policy_loss"][run, update])
        )
    assert sorted(p.name for p in (tmp_path / "tensorboard").iterdir()) == [
        f"run-00{i}" for i in range(4)
    ]
    assert np.isfinite(result.metrics["eval_return"][:, [1, 3]]).all()
    assert json.loads((tmp_path / "config.json").read_text())["grid"]["variant"] == [
        "ppo",
        "fppo-qp",
    ]
    # curves.csv carries the host's metrics too: the evaluations reach tables and plots.
    back = fppo_jax.SweepResult.read(tmp_path)
    np.testing.assert_array_equal(back.metrics["eval_return"], result.metrics["eval_return"])
    last = [scores.tolist() for scores in back.scores("eval")]
    assert last == [result.metrics["eval_return"][2 * i : 2 * i + 2, 3].tolist() for i in (0, 1)]
    assert "| ppo |" in back.table("iqm", "eval")
    # The program of test_a_callback_can_stop_a_sweep (two runs, one-update chunks).
    unevaluated = sweep(
        "cartpole",
        {"variant": "ppo"},
        seeds=2,
        total_steps=128 * 4,
        **TINY,
        **IN_CHUNKS,
    )
    with pytest.raises(ValueError, match="recorded none: train it with eval_every"):
        unevaluated.scores("eval")


def test_train_with_a_log_dir_writes_the_summary_as_the_cli_does(tmp_path):
    result = train(**RUN, log_dir=tmp_path)
    assert (tmp_path / "summary.txt").read_text() == result.summary() + "\n"
    assert {p.name for p in tmp_path.iterdir()} >= {"config.json", "metrics.csv", "summary.txt"}


def test_a_finished_run_goes_on_for_more_steps_as_if_it_had_been_longer(tmp_path):
    short = {**RUN, "total_steps": 128 * 6}
    train(**short, checkpoint_dir=tmp_path)
    longer = train(**RUN, checkpoint_dir=tmp_path, resume=True)
    whole = train(**RUN, **IN_CHUNKS)  # in the resumed run's chunks
    assert longer.resumed_from == 6 and len(longer.metrics["env_steps"]) == 12
    assert_bitwise_equal(longer.metrics, whole.metrics)
    assert_bitwise_equal(longer.params, whole.params)


def test_going_on_is_refused_where_the_learning_rate_schedule_depends_on_the_budget(tmp_path):
    short = {**RUN, "total_steps": 128 * 6, "anneal_learning_rate": True}
    train(**short, checkpoint_dir=tmp_path)
    with pytest.raises(ConfigMismatch, match="its learning rate anneals over the run"):
        train(**{**short, "total_steps": 128 * 12}, checkpoint_dir=tmp_path, resume=True)
    # A run that did not anneal, resumed with annealing: the schedules differ, and are named.
    constant = {**RUN, "total_steps": 128 * 6}
    train(**constant, checkpoint_dir=tmp_path / "constant")
    with pytest.raises(
        ConfigMismatch, match="anneal_learning_rate: false in the checkpoint, true now"
    ):
        train(
            **{**constant, "total_steps": 128 * 12, "anneal_learning_rate": True},
            checkpoint_dir=tmp_path / "constant",
            resume=True,
        )


def test_weights_and_biases_logs_offline(tmp_path, monkeypatch):
    wandb = pytest.importorskip("wandb")
    monkeypatch.setenv("WANDB_MODE", "offline")
    monkeypatch.setenv("WANDB_SILENT", "true")
    monkeypatch.setenv("WANDB_DIR", str(tmp_path))
    train(**RUN, wandb_project="fppo-test", log_dir=tmp_path)
    # W&B's service writes the run file on its own schedule; teardown waits until it has.
    wandb.teardown()
    (record,) = Path(tmp_path).glob("wandb/offline-run-*/run-*.wandb")
    data = record.read_bytes()
    for name in (b"average_return", b"negative_fraction_after", b"fppo-lp"):
        assert name in data


def test_weights_and_biases_logs_each_run_of_a_sweep_as_one_run_grouped(tmp_path, monkeypatch):
    wandb = pytest.importorskip("wandb")
    monkeypatch.setenv("WANDB_MODE", "offline")
    monkeypatch.setenv("WANDB_SILENT", "true")
    grid = {"variant": ["ppo", "fppo-qp"]}
    sweep(
        "cartpole",
        grid,
        seeds=[0, 7],
        chunk=2,
        total_steps=128 * 4,
        **TINY,
        wandb_project="fppo-test",
        log_dir=tmp_path,
    )
    wandb.teardown()
    records = [p.read_bytes() for p in sorted(tmp_path.glob("wandb/offline-run-*/run-*.wandb"))]
    assert len(records) == 4  # one W&B run per run of the sweep
    groups = {re.search(rb"sweep-[a-z0-9]+", data).group() for data in records}
    assert len(groups) == 1  # all in the sweep's group
    names = sorted(
        re.search(rb"run-00\d variant=[a-z-]+ [^\x00-\x1f]*seed=\d", d).group() for d in records
    )
    assert names == [
        b"run-000 variant=ppo seed=0",
        b"run-001 variant=ppo seed=7",
        b"run-002 variant=fppo-qp k=0.4 seed=0",
        b"run-003 variant=fppo-qp k=0.4 seed=7",
    ]
    for data in records:
        assert b"average_return" in data and b"run-00" in data


def test_weights_and_biases_missing_is_a_clear_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "wandb", None)
    with pytest.raises(ImportError, match=r"pip install 'fppo-jax\[wandb\]'"):
        train(**RUN, wandb_project="fppo-test")


@pytest.mark.parametrize(
    "options, message",
    [
        ({"eval_every": 0}, "eval_every must be a positive integer"),
        ({"eval_episodes": 1.5}, "eval_episodes must be a positive integer"),
        ({"callback": 3}, "callback must be a callable"),
        ({"resume": "yes"}, "resume must be True or False"),
        ({"seed": "1"}, "a seed must be an integer"),
        ({"checkpoint_dir": 5}, "checkpoint_dir must be a path, got 5"),
        ({"log_dir": ""}, "log_dir is an empty path"),
        ({"hidden_sizes": 64}, r"hidden_sizes must be a sequence .* got 64"),
        ({"total_steps": 10**23}, "total_steps must be at most 2,147,483,647"),
    ],
)
def test_bad_driver_options_are_refused_before_compiling(options, message, monkeypatch):
    monkeypatch.setattr(fppo_jax.run.driver, "compile_program", lambda *_: pytest.fail("compiled"))
    with pytest.raises(ValueError, match=message):
        train(**{**RUN, **options})


def test_bad_inputs_from_the_command_line_and_python_are_named(capsys):
    assert main(["train", "--steps", "1" + "0" * 22, "--quiet"]) == 2
    assert "total_steps must be at most 2,147,483,647" in capsys.readouterr().err
    for flag in ("--output", "--checkpoint-dir", "--save-policy"):
        with pytest.raises(SystemExit):
            main(["train", flag, ""])
        assert "an empty path: name one" in capsys.readouterr().err
    with pytest.raises(ValueError, match="learning_rate must be a number, got None"):
        sweep("cartpole", {"variant": "ppo", "learning_rate": None}, seeds=1, **TINY)
    # Not pytest.importorskip: envpool's own import sets MPLBACKEND=Agg in this process, which
    # would silence the figures of the notebooks a later test runs from it.
    if not native.envpool_installed():
        pytest.skip("the native backend's envpool is Linux-only")
    with pytest.raises(ValueError, match="envpool's Pong-v5 is not a MuJoCo task"):
        make_env("native/Pong-v5")


def test_a_finished_sweep_resumed_reports_its_results_again(tmp_path):
    grid = {"variant": ["ppo", "fppo-lp"]}
    run = {"seeds": 1, "chunk": 1, "total_steps": 128 * 4, **TINY, "checkpoint_dir": tmp_path}
    first = sweep("cartpole", grid, **run)
    again = sweep("cartpole", grid, **run, resume=True)
    assert_bitwise_equal(again.metrics, first.metrics)
    assert again.diverged.tolist() == first.diverged.tolist() == [0, 0]


def test_a_sweep_chooses_its_runs_per_call_once_before_compiling(monkeypatch):
    from fppo_jax.run import driver, memory

    trainer = fppo_jax.make_train(
        fppo_jax.TrainConfig(total_steps=128 * 2, **TINY), make_env("cartpole")
    )
    one_run = memory.run_bytes(trainer, jax.random.key(0), fppo_jax.hyperparameters())
    monkeypatch.setattr(memory, "free_bytes", lambda: 2 * 2.5 * one_run)  # 2 runs fit in half
    compiled = []
    compile_program = driver.compile_program
    monkeypatch.setattr(
        driver, "compile_program", lambda *a, **k: compiled.append(1) or compile_program(*a, **k)
    )
    grid, shape = {"variant": "ppo"}, {"total_steps": 128 * 2, **TINY, **IN_CHUNKS}
    result = sweep("cartpole", grid, seeds=8, **shape)
    assert result.config["runs_per_call"] == 2 and len(compiled) == 1
    assert result.metrics["env_steps"].shape == (8, 2)
    # A part's groups are the whole sweep's: of its 4 groups, part 2 of 3 trains the third.
    part = sweep("cartpole", grid, seeds=8, part=(2, 3), **shape)
    assert part.config["runs_per_call"] == 2 and part.runs == result.runs[4:6]
    assert_bitwise_equal(part.metrics, {k: v[4:6] for k, v in result.metrics.items()})


def test_a_run_that_cannot_fit_is_refused_before_compiling(monkeypatch):
    from fppo_jax.run import driver, memory

    monkeypatch.setattr(memory, "free_bytes", lambda: 1024.0)
    monkeypatch.setattr(driver, "compile_program", lambda *a, **k: pytest.fail("compiled"))
    with pytest.raises(MemoryError, match=r"one run needs about .* GiB .* lower num_envs"):
        train(**RUN)


def compiled(*_):
    pytest.fail("compiled before refusing")


def test_a_log_dir_that_cannot_be_written_is_refused_before_compiling(tmp_path, monkeypatch):
    loop = tmp_path / "checkpoint-loop"
    loop.symlink_to(loop)
    with pytest.raises(ValueError, match=r"is not a directory .*a link that leads to none"):
        train(**RUN, checkpoint_dir=loop)
    monkeypatch.setattr(fppo_jax.run.driver, "compile_program", compiled)
    file = tmp_path / "file"
    file.write_text("")
    loop = tmp_path / "loop"
    loop.symlink_to(loop)
    # Directories that no one can make, whatever the permissions: a file, one under a file, and
    # a link that leads to itself.
    cases = [(file, "it is not a directory"), (file / "sub", "Not a directory")]
    for path, why in [*cases, (loop, "it is not a directory")]:
        with pytest.raises(ValueError, match=f"cannot write to {path}: {why}"):
            train(**RUN, log_dir=path)
        with pytest.raises(ValueError, match=f"cannot write to {path}: {why}"):
            train(**RUN, checkpoint_dir=path)
        with pytest.raises(ValueError, match=f"cannot write to {path}: {why}"):
            sweep("cartpole", {"variant": "ppo"}, seeds=2, **TINY, log_dir=path)


def test_a_log_dir_holding_a_run_is_refused_unless_that_run_is_resumed(tmp_path, monkeypatch):
    logs, checkpoints = tmp_path / "logs", tmp_path / "checkpoints"
    driven = {"log_dir": logs, "checkpoint_every": 3}
    train(**RUN, **driven, checkpoint_dir=checkpoints, callback=lambda s: s.update < 6)
    written = {p.name: p.read_bytes() for p in logs.iterdir() if p.is_file()}
    with monkeypatch.context() as m:
        m.setattr(fppo_jax.run.driver, "compile_program", compiled)
        with pytest.raises(ValueError, match=r"already holds a run's outputs \(config.json, "):
            train(**RUN, log_dir=logs)
        with pytest.raises(ValueError, match="outputs of another run than the one resumed"):
            other = {**RUN, "seed": 2}
            train(**other, **driven, checkpoint_dir=tmp_path / "other", resume=True)
    assert {p.name: p.read_bytes() for p in logs.iterdir() if p.is_file()} == written
    # Resumed from its checkpoint, the run goes on logging where it stopped.
    resumed = train(**RUN, **driven, checkpoint_dir=checkpoints, resume=True)
    rows = list(csv.DictReader(open(logs / "metrics.csv")))
    assert [int(r["env_steps"]) for r in rows] == resumed.metrics["env_steps"].tolist()
    assert len(rows) == 12 and not list(logs.glob(".*.tmp"))


@pytest.mark.parametrize(
    "settings, message",
    [
        ({"num_envs": 4.0}, "num_envs must be a positive integer, got 4.0"),
        ({"num_envs": True}, "num_envs must be a positive integer, got True"),
        ({"normalize_rewards": "no"}, "normalize_rewards must be True or False, got 'no'"),
        ({"hidden_sizes": "64"}, "positive layer widths such as (64, 64), got '64'"),
        ({"hidden_sizes": (64, 0)}, "each of hidden_sizes must be a positive integer, got 0"),
        ({"resets_per_rollout": 0}, "resets_per_rollout must be a positive integer, got 0"),
    ],
)
def test_config_fields_are_checked_for_type_and_range(settings, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        fppo_jax.TrainConfig(**settings)


def test_numpy_integers_are_integers():
    config = fppo_jax.TrainConfig(total_steps=np.int64(4096), num_envs=np.int32(4))
    assert config.num_envs == 4 and type(config.num_envs) is int


@pytest.mark.parametrize(
    "seeds, message",
    BAD_SEEDS,
)
def test_seeds_are_checked_before_anything_is_made(seeds, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        sweep("cartpole", {"variant": "ppo"}, seeds=seeds)


def test_a_sweep_s_variants_are_its_grid_s():
    with pytest.raises(
        ValueError, match=re.escape("give {'variant': ...} in the grid, not variant=")
    ):
        sweep("cartpole", {"learning_rate": [1e-3, 3e-4]}, variant="ppo")


class _Compilations:
    """Counts XLA compilations while it is entered."""

    def __enter__(self) -> list[str]:
        self.events: list[str] = []
        jax.monitoring.register_event_duration_secs_listener(self._heard)
        return self.events

    def __exit__(self, *exc: object) -> None:
        jax.monitoring.unregister_event_duration_listener(self._heard)

    def _heard(self, event: str, duration: float, **kwargs: object) -> None:
        if event == "/jax/core/compile/backend_compile_duration":
            self.events.append(event)


def test_a_repeated_train_or_sweep_with_the_same_shapes_compiles_nothing(monkeypatch):
    from fppo_jax.run import execution

    # An empty store of compiled programs: the first call here prepares its own whatever ran
    # before it in this process (loading it from the session's cache where a test compiled it).
    monkeypatch.setattr(execution, "_PROGRAMS", execution._Programs())
    first = train(**RUN, **IN_CHUNKS)
    assert first.compile_seconds > 0
    with _Compilations() as compiled:
        again = train(
            **{**RUN, "variant": "fppo-qp", "seed": 7, "learning_rate": 1e-3}, **IN_CHUNKS
        )
    assert compiled == [] and again.compile_seconds == 0
    assert not np.array_equal(again.metrics["policy_loss"], first.metrics["policy_loss"])
    # A shape that differs is compiled for: layer widths no other test uses.
    with _Compilations() as compiled:
        train(**{**RUN, "hidden_sizes": (24, 24)}, **IN_CHUNKS)
    assert compiled

    settings = {"total_steps": 128 * 4, **TINY, **IN_CHUNKS}
    grid = {"variant": ["ppo", "fppo-lp"]}
    assert sweep("cartpole", grid, seeds=1, **settings).compile_seconds > 0
    with _Compilations() as compiled:
        other = sweep("cartpole", {"variant": ["tr-ppo", "fppo-qp"]}, seeds=[5], **settings)
    assert compiled == [] and other.compile_seconds == 0


def test_another_step_budget_reuses_the_program_and_anneals_over_its_own_length(monkeypatch):
    """The budget is traced: a run of another length compiles nothing, ends where its own
    budget ends, and its learning rate anneals over its own length, bit for bit as the
    trainer compiled for that budget alone."""
    from fppo_jax import hyperparameters, make_env, make_train
    from fppo_jax.core.config import TrainConfig
    from fppo_jax.core.trainer import METRICS
    from fppo_jax.run import execution

    monkeypatch.setattr(execution, "_PROGRAMS", execution._Programs())
    longer = train(**RUN, **IN_CHUNKS)  # 12 updates
    with _Compilations() as compiled:
        shorter = train(**{**RUN, "total_steps": 128 * 5}, **IN_CHUNKS)
    assert compiled == [] and shorter.compile_seconds == 0
    assert shorter.metrics["env_steps"].tolist() == [128 * u for u in range(1, 6)]
    for name in METRICS:  # a constant learning rate: the first updates are the same
        assert_bitwise_equal(shorter.metrics[name], longer.metrics[name][:5])

    annealed = {**RUN, "anneal_learning_rate": True}
    train(**annealed, **IN_CHUNKS)
    with _Compilations() as compiled:
        short = train(**{**annealed, "total_steps": 128 * 5}, **IN_CHUNKS)
    assert compiled == []
    config = TrainConfig(total_steps=128 * 5, anneal_learning_rate=True, **TINY)
    trainer = make_train(config, make_env("cartpole"))
    _, alone = jax.jit(trainer)(jax.random.key(1), hyperparameters("fppo-lp", alpha=1.3))
    for name in METRICS:
        assert_bitwise_equal(short.metrics[name], np.asarray(getattr(alone, name)))


def test_one_writer_per_output_directory_from_the_first_moment(tmp_path):
    from fppo_jax.store.files import DirectoryLock

    held = DirectoryLock(tmp_path, "a run's outputs")  # as another sweep starting on it would
    with pytest.raises(ValueError, match=rf"another process \(pid {os.getpid()}\) is writing"):
        sweep("cartpole", {"variant": "ppo"}, seeds=1, total_steps=512, **TINY, log_dir=tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == [".lock"]  # nothing written
    held.release()
    sweep("cartpole", {"variant": "ppo"}, seeds=1, total_steps=512, **TINY, log_dir=tmp_path)
    assert (tmp_path / "sweep.json").exists()


def test_metrics_csv_keeps_its_columns_in_order_across_a_resume(tmp_path):
    driven = {"checkpoint_dir": tmp_path / "ckpt", "log_dir": tmp_path / "logs", "eval_every": 3}
    train(**{**RUN, "total_steps": 128 * 6}, **driven)
    header = (tmp_path / "logs" / "metrics.csv").read_text().splitlines()[0]
    assert header.split(",") == [*fppo_jax.METRICS, "eval_return"]
    train(**RUN, **driven, resume=True)  # goes on to 12 updates, rewriting metrics.csv
    lines = (tmp_path / "logs" / "metrics.csv").read_text().splitlines()
    assert lines[0] == header and len(lines) == 13
