"""The work between two compiled calls of a batch of runs, one object per concern.

After each chunk of updates the driver hands every hook the :class:`Chunk` it ended, in the
order the driver lists them: the checkpoint, the output directory's check, the metric logs,
the user's callback, the progress report. Each hook owns its state and its format; its
``after_chunk`` returns True to stop training after this chunk (only the callback does). Two of
them are the stored things themselves, whose ``after_chunk`` is their own:
:class:`~fppo_jax.store.files.DirectoryLock` (the output directory's check) and
:class:`~fppo_jax.store.metric_log.Logs`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any, Protocol

import jax
import jax.numpy as jnp
import numpy as np

from fppo_jax.core.policy import Policy, make_policy
from fppo_jax.core.trainer import Trainer, TrainState
from fppo_jax.envs import Environment
from fppo_jax.run.distributed import fetch_tree
from fppo_jax.run.evaluation import evaluation_key, make_evaluator
from fppo_jax.run.execution import concatenate, first_run
from fppo_jax.run.options import Callback, Snapshot, callback_stops
from fppo_jax.run.progress import Counter, Progress
from fppo_jax.store.checkpoint import CheckpointedRun, Checkpoints, ResumePoint


@dataclasses.dataclass(frozen=True)
class Chunk:
    """Where a chunk left group `group` (the runs `runs`): `update` updates done, the state and
    its policy (along runs), and `metrics`, every update of the group so far
    (``[run, update]``)."""

    group: int
    runs: range
    update: int
    state: TrainState
    policy: Policy
    metrics: dict[str, np.ndarray]


class Hook(Protocol):
    def after_chunk(self, chunk: Chunk) -> bool:
        """This hook's work after `chunk`; True stops training there."""
        ...


@dataclasses.dataclass
class Finished:
    """The groups trained to their end so far: each one's metrics, and the update each of
    their runs diverged at (from 1) or 0."""

    metrics: list[dict[str, np.ndarray]] = dataclasses.field(default_factory=list)
    diverged: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0, np.int32))

    def add(self, metrics: dict[str, np.ndarray], diverged: np.ndarray) -> None:
        self.metrics.append(metrics)
        self.diverged = np.concatenate([self.diverged, diverged])

    def joined(self) -> dict[str, np.ndarray]:
        """Every finished run's metrics along runs (nothing before the first group ends)."""
        return concatenate(self.metrics, axis=0) if self.metrics else {}


class Checkpoint:
    """Saves the point each chunk reached, beside the groups finished before it. Every process
    fetches the state (a collective); the one given `checkpoints` (None on the others) writes.
    `run` is what each checkpoint records with the point (its kind, configuration, runs per
    call and updates); a single run's (`single_run` is its trainer) also carries its policy,
    for ``load_policy``.
    `saved` lists the updates checkpointed, from the one a resumed run started at."""

    def __init__(
        self,
        checkpoints: Checkpoints | None,
        finished: Finished,
        run: CheckpointedRun,
        single_run: Trainer | None,
        resumed_from: int | None,
    ):
        self.checkpoints, self.finished, self.run = checkpoints, finished, run
        self.single_run = single_run
        self.saved: list[int] = [] if resumed_from is None else [resumed_from]

    def after_chunk(self, chunk: Chunk) -> bool:
        host = fetch_tree(chunk.state)
        if self.checkpoints:
            finished = self.finished
            point = ResumePoint(
                chunk.group, chunk.update, chunk.metrics, finished.joined(), finished.diverged
            )
            policy = None
            if self.single_run is not None:
                policy = make_policy(self.single_run, first_run(host))
            self.checkpoints.save_point(point, host, **self.run, policy=policy)
        self.saved.append(chunk.update)
        return False


class UserCallback:
    """Shows the user's callback a :class:`~fppo_jax.run.options.Snapshot`, of the one run alone
    if `single_run` (without the run axis); its answer may stop."""

    def __init__(self, callback: Callback, single_run: bool):
        self.callback, self.single_run = callback, single_run

    def after_chunk(self, chunk: Chunk) -> bool:
        seen = (chunk.metrics, chunk.state, chunk.policy)
        if self.single_run:
            seen = first_run(seen)
        return callback_stops(self.callback(Snapshot(chunk.update, *seen, chunk.runs)))


class ProgressReport:
    """Reports the steps done, the speed and the latest average return, as `counter` counts."""

    def __init__(self, report: Callable[[Progress], None], counter: Counter):
        self.report, self.counter = report, counter

    def after_chunk(self, chunk: Chunk) -> bool:
        returns = chunk.metrics["average_return"][..., -1]
        self.report(self.counter.progress(chunk.group, chunk.update, returns))
        return False


class Evaluation:
    """`eval_return` beside a chunk's training metrics: the deterministic policy's mean return
    over `episodes` episodes every `every` updates and at the last, NaN between. It runs before
    the hooks, as it adds a column to the chunk's own metrics before they join the group's."""

    def __init__(
        self,
        env: Environment,
        episodes: int,
        every: int,
        num_updates: int,
        along_runs: Callable[[Callable[..., Any]], Callable[..., Any]],
    ):
        self.evaluate = jax.jit(along_runs(make_evaluator(env, episodes)))
        self.key = evaluation_key()
        self.every, self.num_updates = every, num_updates

    def add_column(self, policy: Policy, chunk: dict[str, np.ndarray], update: int) -> None:
        column = np.full(chunk["env_steps"].shape, np.nan, np.float32)
        if update % self.every == 0 or update == self.num_updates:
            # Every run's episodes alike, each run with environments of its own.
            keys = jnp.broadcast_to(self.key, (len(column), *self.key.shape))
            column[..., -1] = np.asarray(self.evaluate(policy, keys)).mean(axis=-1)
        chunk["eval_return"] = column
