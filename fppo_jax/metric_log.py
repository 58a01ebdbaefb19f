"""Per-update metrics written as they arrive: ``metrics.csv`` and TensorBoard event files."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from fppo_jax.trainer import METRICS


class MetricLog:
    """``<directory>/metrics.csv`` (one row per update, the columns of
    :data:`~fppo_jax.trainer.METRICS`) and ``<directory>/tensorboard/`` (one scalar per metric
    and update, against env steps).

    `previous` are the metrics of a resumed run up to its checkpoint: the CSV is rewritten with
    them, and TensorBoard is told to drop any later points an interrupted run had logged.
    """

    def __init__(self, directory: str | Path, previous: dict[str, np.ndarray] | None = None):
        from tensorboardX import SummaryWriter

        self.directory = Path(directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        self._csv = open(self.directory / "metrics.csv", "w", newline="")
        self._rows = csv.writer(self._csv)
        self._rows.writerow(METRICS)
        self._written = 0
        purge = None
        if previous is not None and len(previous["env_steps"]):
            self._write_csv(previous)
            purge = int(previous["env_steps"][-1]) + 1
        self._tensorboard = SummaryWriter(str(self.directory / "tensorboard"), purge_step=purge)

    def write(self, metrics: dict[str, np.ndarray]) -> None:
        """Log the updates of `metrics` (every update so far) not logged yet."""
        start = self._written
        self._write_csv(metrics)
        for u in range(start, self._written):
            step = int(metrics["env_steps"][u])
            for name in METRICS[1:]:
                self._tensorboard.add_scalar(name, float(metrics[name][u]), step)
        self._tensorboard.flush()

    def close(self) -> None:
        self._csv.close()
        self._tensorboard.close()

    def _write_csv(self, metrics: dict[str, np.ndarray]) -> None:
        count = len(metrics["env_steps"])
        columns = [np.asarray(metrics[name])[self._written : count].tolist() for name in METRICS]
        self._rows.writerows(zip(*columns, strict=True))
        self._csv.flush()
        self._written = count
