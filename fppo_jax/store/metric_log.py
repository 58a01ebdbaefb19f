"""Per-update metrics written as they arrive: ``config.json`` first, then ``metrics.csv`` and
TensorBoard event files, and optionally Weights & Biases.

One run logs its metrics as they are. A sweep's runs log theirs side by side: ``metrics.csv``
gains a leading ``run`` column, TensorBoard gets one directory per run (``tensorboard/run-007``)
and W&B one run per run, grouped by the sweep.
"""

from __future__ import annotations

import csv
import json
import os
import platform
import secrets
from collections.abc import Mapping, Sequence
from importlib import metadata
from pathlib import Path
from typing import Any, Protocol, TypedDict

import jax
import numpy as np

from fppo_jax.core.config import Setting
from fppo_jax.core.trainer import METRICS
from fppo_jax.errors import InvalidInput, MissingPackage, first_line, install_hint
from fppo_jax.store.files import DirectoryLock, writable_directory, write_json
from fppo_jax.store.record import RunRecord

LoggedRuns = tuple[range, dict[str, np.ndarray]]  # runs (a range of run indices) and their metrics

# What a run writes in its log directory; a directory holding any of them is another run's.
OUTPUTS = ("config.json", "metrics.csv", "curves.csv", "sweep.json", "summary.txt")


class EnvironmentRecord(TypedDict):
    """Where a run ran, as its ``config.json`` records it beside the run's record: the versions
    of Python and of the packages installed of those it may use, JAX's platform and the kinds of
    its devices."""

    versions: dict[str, str]
    platform: str
    devices: list[str]


def environment_record() -> EnvironmentRecord:
    """Versions and devices, for the record of a run."""
    versions = {}
    for package in (
        "fppo-jax",
        "jax",
        "jaxlib",
        "flax",
        "optax",
        "brax",
        "mujoco",
        "gymnax",
        "envpool",
    ):
        try:
            versions[package] = metadata.version(package)
        except metadata.PackageNotFoundError:
            continue
    return {
        "versions": {"python": platform.python_version(), **versions},
        "platform": jax.default_backend(),
        "devices": [str(d.device_kind) for d in jax.devices()],
    }


def prepare_log_dir(directory: str | Path, resumed: RunRecord | None) -> DirectoryLock:
    """Make `directory` for a run's logs and hold it as its one writer, or raise InvalidInput,
    before anything is compiled: if it cannot be written, if another process writes there, or
    if it holds a run's outputs (:data:`OUTPUTS`), which are never overwritten unasked. Only
    the run resumed, recorded as `resumed`, continues there, when the ``config.json`` there
    records that run. The caller releases the lock when the run ends."""
    directory = writable_directory(directory)
    lock = DirectoryLock(directory, "a run's outputs")
    try:
        _check_outputs(directory, resumed)
    except ValueError:
        lock.release()
        raise
    return lock


def _check_outputs(directory: Path, resumed: RunRecord | None) -> None:
    found = [name for name in OUTPUTS if (directory / name).exists()]
    if not found:
        return
    if resumed is None:
        raise InvalidInput(
            f"{directory} already holds a run's outputs ({', '.join(found)}); choose another "
            "directory, or resume that run (resume=True, --resume) from its checkpoint "
            "directory to continue it"
        )
    recorded = _recorded(directory)
    if recorded is None:
        differing = "config.json records no run"
    else:
        differing = "; ".join(recorded.differences(resumed, "in config.json", "resumed"))
    if differing:
        raise InvalidInput(
            f"{directory} holds the outputs of another run than the one resumed ({differing}); "
            "choose another directory"
        )


def _recorded(directory: Path) -> RunRecord | None:
    """The run ``config.json`` in `directory` records, without the versions and devices,
    which may change between a run and its resumption (None if it records none)."""
    try:
        record = json.loads((directory / "config.json").read_text())
        machine = environment_record()
        run = {name: value for name, value in record.items() if name not in machine}
        return RunRecord.from_json(run, f"{directory / 'config.json'}")
    except (OSError, ValueError, AttributeError):
        return None


class MetricLog:
    """``<directory>/metrics.csv`` (one row per update, and per run for a sweep) and
    ``<directory>/tensorboard/`` (one scalar per metric and update, against env steps).

    `previous` are the metrics a resumed run restored: the CSV is rewritten with them (under a
    temporary name, then renamed over the old one), and TensorBoard is told to drop any later
    points an interrupted run had logged.
    """

    def __init__(
        self,
        directory: str | Path,
        config: Mapping[str, object],
        sweep: bool,
        previous: Sequence[LoggedRuns] = (),
    ):
        from tensorboardX import SummaryWriter

        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        self._sweep = sweep  # a run column, and a TensorBoard folder per run
        temporary = self.directory / ".metrics.csv.tmp"
        self._csv = open(temporary, "w", newline="")
        self._rows = csv.writer(self._csv)
        self._columns: list[str] | None = None
        self._writers: dict[int, Any] = {}
        self._written: dict[int, int] = {}  # updates logged, per run
        self._make_writer = SummaryWriter
        self._purge: dict[int, int] = {}
        for runs, metrics in previous:
            self._write_csv(runs, metrics)
            for index, run in enumerate(runs):
                steps = _of_run(metrics, index)["env_steps"]
                if len(steps):
                    self._purge[run] = int(steps[-1]) + 1
        os.fsync(self._csv.fileno())
        os.replace(temporary, self.directory / "metrics.csv")  # the open file goes on there
        text = json.dumps(config, indent=2, default=str)
        self._writer(0).add_text("config", f"```\n{text}\n```")

    def write(self, metrics: dict[str, np.ndarray], runs: range) -> None:
        """Log the updates of `metrics` (every update so far of `runs`) not logged yet."""
        logged = {run: self._written.get(run, 0) for run in runs}
        self._write_csv(runs, metrics)
        for index, run in enumerate(runs):
            values = _of_run(metrics, index)
            writer = self._writer(run)
            for u in range(logged[run], len(values["env_steps"])):
                step = int(values["env_steps"][u])
                for name, series in values.items():
                    if name != "env_steps" and np.isfinite(series[u]):
                        writer.add_scalar(name, float(series[u]), step)
            writer.flush()

    def close(self) -> None:
        self._csv.close()
        for writer in self._writers.values():
            writer.close()

    def _writer(self, run: int) -> Any:
        if run not in self._writers:
            where = self.directory / "tensorboard"
            if self._sweep:
                where = where / f"run-{run:03d}"
            self._writers[run] = self._make_writer(str(where), purge_step=self._purge.get(run))
        return self._writers[run]

    def _write_csv(self, runs: range, metrics: dict[str, np.ndarray]) -> None:
        if self._columns is None:  # METRICS' order, then the host's (eval_return), however
            # the metrics came (a checkpoint restores them in another order)
            self._columns = sorted(metrics, key=lambda m: (m not in METRICS, _rank(m)))
            self._rows.writerow((["run"] if self._sweep else []) + self._columns)
        for index, run in enumerate(runs):
            values = _of_run(metrics, index)
            count = len(values["env_steps"])
            nan = np.full(count, np.nan)
            columns = [np.asarray(values.get(name, nan)).tolist() for name in self._columns]
            rows = list(zip(*columns, strict=True))[self._written.get(run, 0) :]
            self._rows.writerows([run, *row] if self._sweep else row for row in rows)
            self._written[run] = count
        self._csv.flush()


def _rank(metric: str) -> tuple[int, str]:
    return (METRICS.index(metric), "") if metric in METRICS else (0, metric)


def require_wandb() -> Any:
    """The ``wandb`` module, or an ImportError that says how to install it."""
    try:
        import wandb
    except ImportError:
        raise MissingPackage(
            f"wandb_project needs Weights & Biases: {install_hint('wandb')}"
        ) from None
    return wandb


class WandbLog:
    """The same scalars in Weights & Biases (``pip install wandb``; ``WANDB_MODE=offline``
    works without an account or a network), plotted against ``env_steps``.

    One run is one W&B run. A sweep's runs are one W&B run each, grouped by the sweep (W&B's
    ``group``), each named by its index, setting and seed and holding them in its config; a
    run's W&B run is finished once its group of runs is done."""

    def __init__(
        self,
        project: str,
        config: Mapping[str, object],
        runs: Sequence[Setting] | None,
        directory: Any,
    ):
        self._wandb = require_wandb()
        self._project, self._config, self._runs = project, config, runs
        self._directory = str(directory) if directory is not None else None
        self._group = None if runs is None else f"sweep-{secrets.token_hex(4)}"
        self._open: dict[int, Any] = {}
        self._written: dict[int, int] = {}

    def _run(self, index: int) -> Any:
        if index not in self._open:
            config, name = self._config, None
            if self._runs is not None:
                setting = self._runs[index]
                config = {**config, **setting, "run": index}
                name = f"run-{index:03d} " + " ".join(f"{k}={v}" for k, v in setting.items())
            try:
                run = self._wandb.init(
                    project=self._project,
                    config=config,
                    name=name,
                    group=self._group,
                    dir=self._directory,
                    reinit="create_new",
                )
            except self._wandb.errors.UsageError as error:  # no account set up: the user's to fix
                raise InvalidInput(
                    f"Weights & Biases could not start a run: {first_line(error)} (or set "
                    "WANDB_MODE=offline to log without an account)"
                ) from error
            run.define_metric("env_steps")
            run.define_metric("*", step_metric="env_steps")
            self._open[index] = run
        return self._open[index]

    def write(self, metrics: dict[str, np.ndarray], runs: range) -> None:
        for done in set(self._open) - set(runs):  # an earlier group's runs are complete
            self._open.pop(done).finish()
        for index, run in enumerate(runs):
            values = _of_run(metrics, index)
            logged = self._run(run)
            for u in range(self._written.get(run, 0), len(values["env_steps"])):
                row = {
                    name: float(series[u])
                    for name, series in values.items()
                    if name != "env_steps" and np.isfinite(series[u])
                }
                logged.log({"env_steps": int(values["env_steps"][u]), **row})
            self._written[run] = len(values["env_steps"])

    def close(self) -> None:
        for run in self._open.values():
            run.finish()
        self._open.clear()


class Chunk(Protocol):
    """What a chunk of updates gives the logs: every update of its group so far
    (``[run, update]``) and the group's runs (the driver's chunk, :mod:`fppo_jax.run.hooks`)."""

    @property
    def metrics(self) -> dict[str, np.ndarray]: ...

    @property
    def runs(self) -> range: ...


class Logs:
    """Every log a run writes to, written and closed together; one of the driver's hooks."""

    def __init__(self, sinks: list[MetricLog | WandbLog]):
        self._sinks = sinks

    def after_chunk(self, chunk: Chunk) -> bool:
        """Appends the chunk's updates to the CSV, TensorBoard and W&B logs asked for; never
        stops training."""
        for sink in self._sinks:
            sink.write(chunk.metrics, chunk.runs)
        return False

    def close(self) -> None:
        for sink in self._sinks:
            sink.close()


def open_logs(
    directory: str | Path | None,
    wandb_project: str | None,
    config: RunRecord,
    runs: Sequence[Setting] | None,
    previous: Sequence[LoggedRuns] = (),
) -> Logs | None:
    """The logs asked for (None if none): `directory` gets ``config.json`` (`config` with the
    versions and devices) at once, then ``metrics.csv`` and TensorBoard files as training goes;
    `wandb_project` names a W&B project. `runs` is a sweep's runs (each one's setting and
    seed), None for a single run."""
    record = {**config.to_json(), **environment_record()}
    sinks: list[MetricLog | WandbLog] = []
    if directory is not None:
        Path(directory).mkdir(parents=True, exist_ok=True)
        write_json(Path(directory) / "config.json", record)
        sinks.append(MetricLog(directory, record, runs is not None, previous))
    if wandb_project is not None:
        sinks.append(WandbLog(wandb_project, record, runs, directory))
    return Logs(sinks) if sinks else None


def _of_run(metrics: dict[str, np.ndarray], index: int) -> dict[str, np.ndarray]:
    return {name: np.asarray(v)[index] for name, v in metrics.items()}
