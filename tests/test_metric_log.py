"""fppo_jax.store.metric_log: config.json, metrics.csv, TensorBoard and W&B logs, written as
training goes, each update once, and a log directory never shared or overwritten unasked."""

import csv
import dataclasses
import json
import struct
import sys
import types
from pathlib import Path

import numpy as np
import pytest
from tensorboardX.proto.event_pb2 import Event

from fppo_jax import train
from fppo_jax.core.config import TrainConfig
from fppo_jax.core.trainer import METRICS
from fppo_jax.errors import FppoError
from fppo_jax.store.metric_log import (
    MetricLog,
    WandbLog,
    environment_record,
    open_logs,
    prepare_log_dir,
    require_wandb,
)
from fppo_jax.store.record import RunRecord

TINY = {"num_envs": 4, "num_steps": 32, "num_minibatches": 4, "num_epochs": 2}
RUN = {"env": "cartpole", "variant": "fppo-qp", "seed": 3, "total_steps": 128 * 20, **TINY}


def read_events(directory: Path) -> list[Event]:
    """Every event in the TFRecord files under `directory`."""
    events = []
    for path in sorted(directory.glob("events.out.tfevents.*")):
        data = path.read_bytes()
        while data:
            (length,) = struct.unpack("<Q", data[:8])
            events.append(Event.FromString(data[12 : 12 + length]))
            data = data[12 + length + 4 :]
    return events


def test_metrics_are_logged_to_csv_and_tensorboard_as_training_goes(tmp_path):
    seen = []

    def progress(p):
        seen.append((p.update, len(list(csv.reader(open(tmp_path / "metrics.csv"))))))

    result = train(**RUN, log_dir=tmp_path, progress=progress)
    # After each chunk the CSV already holds its rows (plus the header).
    assert [(u, rows - 1) for u, rows in seen[1:]] == [(u, u) for u, _ in seen[1:]]
    assert seen[-1][0] == 20
    values, texts = {}, []
    for event in read_events(tmp_path / "tensorboard"):
        for value in event.summary.value:
            if value.HasField("simple_value"):
                values.setdefault(value.tag, {})[event.step] = value.simple_value
            else:
                texts.append(value.tag)
    assert set(values) == set(METRICS) - {"env_steps"}
    assert texts == ["config/text_summary"]  # every setting, as TensorBoard's text
    loss = values["policy_loss"]
    assert sorted(loss) == list(result.metrics["env_steps"])
    np.testing.assert_array_equal([loss[s] for s in sorted(loss)], result.metrics["policy_loss"])


def metrics(updates: int, runs: int | None = None) -> dict[str, np.ndarray]:
    """`updates` updates of three metrics and a host-side one (NaN at its first update), in an
    order of their own; [run, update] if `runs`."""
    steps = 128 * np.arange(1, updates + 1, dtype=np.int32)
    values = {
        "eval_return": np.where(steps > 128, steps / 10.0, np.nan),
        "policy_loss": 1.0 / steps,
        "env_steps": steps,
        "average_return": steps / 100.0,
    }
    if runs is None:
        return values
    return {
        name: np.stack([v + (run if name != "env_steps" else 0) for run in range(runs)])
        for name, v in values.items()
    }


def scalars(directory: Path) -> dict[str, dict[int, float]]:
    """Each scalar tag's values by step, every point logged (a repeated one raises)."""
    found: dict[str, dict[int, float]] = {}
    for event in read_events(directory):
        for value in event.summary.value:
            if value.HasField("simple_value"):
                points = found.setdefault(value.tag, {})
                assert event.step not in points, f"{value.tag} logged twice at {event.step}"
                points[event.step] = value.simple_value
    return found


def test_the_csv_takes_metrics_order_then_the_hosts_and_each_update_once(tmp_path):
    log = MetricLog(tmp_path, {"env": "test"}, sweep=False)
    log.write(metrics(2, runs=1), range(1))
    log.write(metrics(5, runs=1), range(1))  # every update so far: the first two not repeated
    log.close()
    rows = list(csv.reader(open(tmp_path / "metrics.csv")))
    assert rows[0] == ["env_steps", "average_return", "policy_loss", "eval_return"]
    expected = metrics(5)
    assert [int(r[0]) for r in rows[1:]] == expected["env_steps"].tolist()
    for column, name in enumerate(rows[0]):
        np.testing.assert_array_equal([float(r[column]) for r in rows[1:]], expected[name])
    assert not (tmp_path / ".metrics.csv.tmp").exists()
    # TensorBoard: each metric but env_steps against env steps, its NaN points left out.
    logged = scalars(tmp_path / "tensorboard")
    assert set(logged) == {"average_return", "policy_loss", "eval_return"}
    assert sorted(logged["policy_loss"]) == [128, 256, 384, 512, 640]
    assert sorted(logged["eval_return"]) == [256, 384, 512, 640]
    assert logged["eval_return"][384] == pytest.approx(38.4)


def test_a_sweeps_runs_are_logged_side_by_side(tmp_path):
    log = MetricLog(tmp_path, {"env": "test"}, sweep=True)
    log.write(metrics(1, runs=2), range(0, 2))  # the first group of runs, update by update
    log.write(metrics(2, runs=2), range(0, 2))
    log.write(metrics(2, runs=2), range(2, 4))  # the second group, both updates at once
    log.close()
    rows = list(csv.DictReader(open(tmp_path / "metrics.csv")))
    assert list(rows[0]) == ["run", "env_steps", "average_return", "policy_loss", "eval_return"]
    assert [(int(r["run"]), int(r["env_steps"])) for r in rows] == [
        (0, 128), (1, 128), (0, 256), (1, 256), (2, 128), (2, 256), (3, 128), (3, 256)
    ]  # fmt: skip
    # Runs 2 and 3 are the second group's runs 0 and 1.
    assert float(rows[-1]["policy_loss"]) == pytest.approx(1 / 256 + 1)
    runs = sorted(p.name for p in (tmp_path / "tensorboard").iterdir())
    assert runs == ["run-000", "run-001", "run-002", "run-003"]
    logged = scalars(tmp_path / "tensorboard" / "run-003")
    assert logged["average_return"] == {128: pytest.approx(2.28), 256: pytest.approx(3.56)}


def test_a_resumed_log_rewrites_the_csv_from_the_restored_metrics_and_purges_the_rest(tmp_path):
    # An interrupted run had logged 5 updates; its checkpoint holds 2.
    interrupted = MetricLog(tmp_path, {"env": "test"}, sweep=False)
    interrupted.write(metrics(5, runs=1), range(1))
    interrupted.close()
    restored = {name: values[:, :2] for name, values in metrics(5, runs=1).items()}
    log = MetricLog(tmp_path, {"env": "test"}, sweep=False, previous=[(range(1), restored)])
    rows = list(csv.reader(open(tmp_path / "metrics.csv")))
    assert [r[0] for r in rows] == ["env_steps", "128", "256"]
    log.write(metrics(3, runs=1), range(1))  # the run goes on from update 3
    log.close()
    rows = list(csv.reader(open(tmp_path / "metrics.csv")))
    assert [r[0] for r in rows] == ["env_steps", "128", "256", "384"]
    # TensorBoard is told to drop what the interrupted run logged after the checkpoint.
    events = read_events(tmp_path / "tensorboard")
    purges = [e.step for e in events if e.HasField("session_log")]
    assert purges == [257]


RECORD = RunRecord("test", None, "paper", TrainConfig(), seed=3)


def test_open_logs_writes_the_config_with_versions_and_devices_at_once(tmp_path):
    assert open_logs(None, None, RECORD, None) is None
    logs = open_logs(tmp_path / "logs", None, RECORD, None)
    record = json.loads((tmp_path / "logs" / "config.json").read_text())
    logs.close()
    machine = environment_record()
    assert record == {**RECORD.to_json(), **json.loads(json.dumps(machine))}
    assert {"python", "jax", "jaxlib", "flax", "optax"} <= set(machine["versions"])
    assert machine["platform"] in ("cpu", "gpu", "tpu") and machine["devices"]


def test_a_log_directory_holding_a_run_is_refused_unless_it_is_the_run_resumed(tmp_path):
    config = RECORD
    open_logs(tmp_path, None, config, None).close()
    with pytest.raises(ValueError, match=r"already holds a run's outputs \(config.json, metrics.c"):
        prepare_log_dir(tmp_path, None)
    with pytest.raises(ValueError, match=r"than the one resumed \(seed: 3 in config.json, 4 resu"):
        prepare_log_dir(tmp_path, dataclasses.replace(config, seed=4))
    # A refusal lets go of the directory: the run resumed may hold it.
    held = prepare_log_dir(tmp_path, config)
    with pytest.raises(ValueError, match=r"another process \(pid \d+\) is writing a run's outp"):
        prepare_log_dir(tmp_path, config)
    held.release()
    prepare_log_dir(tmp_path / "new", None).release()  # made if missing


def test_without_wandb_the_error_says_how_to_install_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "wandb", None)
    with pytest.raises(
        ImportError,
        match=r"wandb_project needs Weights & Biases: pip install 'fppo-jax\[wandb\]' \(from a",
    ):
        require_wandb()


class FakeWandb(types.ModuleType):
    """What WandbLog uses of wandb, recording each run's settings, logs and finish."""

    def __init__(self):
        super().__init__("wandb")
        self.runs = []

    def init(self, **settings):
        run = types.SimpleNamespace(settings=settings, logged=[], finished=False)
        run.define_metric = lambda *a, **k: None
        run.log = run.logged.append
        run.finish = lambda: setattr(run, "finished", True)
        self.runs.append(run)
        return run


def test_wandb_gets_one_run_per_run_finished_once_its_group_is_done(monkeypatch):
    fake = FakeWandb()
    monkeypatch.setitem(sys.modules, "wandb", fake)
    settings = [{"variant": "ppo", "seed": s} for s in range(3)]
    log = WandbLog("project", {"env": "test"}, settings, None)
    log.write(metrics(2, runs=2), range(0, 2))
    log.write(metrics(2, runs=1), range(2, 3))  # the first group is done
    assert [run.finished for run in fake.runs] == [True, True, False]
    log.close()
    assert all(run.finished for run in fake.runs)
    names = [run.settings["name"] for run in fake.runs]
    assert names == [f"run-00{i} variant=ppo seed={i}" for i in range(3)]
    assert len({run.settings["group"] for run in fake.runs}) == 1
    assert fake.runs[1].settings["config"] == {"env": "test", "variant": "ppo", "seed": 1, "run": 1}
    # Each update once, against env steps, without its NaN values.
    assert fake.runs[1].logged == [
        pytest.approx({"env_steps": 128, "policy_loss": 1 / 128 + 1, "average_return": 2.28}),
        pytest.approx(
            {
                "env_steps": 256,
                "eval_return": 26.6,
                "policy_loss": 1 / 256 + 1,
                "average_return": 3.56,
            }
        ),
    ]


def test_wandb_without_an_account_is_the_user_s_error_saying_what_to_do(monkeypatch):
    fake = FakeWandb()
    fake.errors = types.SimpleNamespace(UsageError=type("UsageError", (Exception,), {}))

    def refuse(**settings):
        raise fake.errors.UsageError("No API key configured. Use `wandb login` to log in.")

    fake.init = refuse
    monkeypatch.setitem(sys.modules, "wandb", fake)
    log = WandbLog("project", {"env": "test"}, None, None)
    with pytest.raises(FppoError, match=r"could not start a run: No API key .* WANDB_MODE=off"):
        log.write(metrics(2, runs=1), range(0, 1))
