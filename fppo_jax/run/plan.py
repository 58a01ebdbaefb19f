"""What the driver trains and what it hands back: a :class:`Plan` (a batch of runs along a
leading run axis, a single run a batch of one) and its :class:`Outcome`. A sweep's runs train in
groups of one size, so every group reuses the one compiled program. The groups are the whole
sweep's: a part of a split sweep trains whole groups of them (:func:`part_runs`), so that each
run is computed by the same program, at the same place in its group, as in the unsplit sweep.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path
from typing import Any, cast

import jax
import numpy as np
from jax.sharding import Mesh

from fppo_jax.core.checks import check_part
from fppo_jax.core.config import Hyperparameters, Setting
from fppo_jax.core.trainer import Trainer, TrainState
from fppo_jax.errors import InvalidInput
from fppo_jax.run.execution import one_run
from fppo_jax.store.checkpoint import CheckpointRecord, ConfigMismatch, RunKind
from fppo_jax.store.record import RunRecord


@dataclasses.dataclass(frozen=True)
class Plan:
    """What to train: `keys`, a [run] array of keys, and `hps` alike (one run's for a "train"
    plan); `record` is the configuration that checkpoints and outputs record, and `runs` (a
    sweep's only) each run's setting and seed, which its logs name it by.
    `runs_per_call` fixes a sweep's group size (None: as many of its runs as fit in memory),
    and `data_parallel` the devices each run's environments are split over. `share`, a
    ``(K, N)`` part of a split sweep, trains the K-th of N shares of the whole sweep's groups
    (:func:`part_runs`): `keys`, `hps` and `runs` are then the whole sweep's. `after_group`, if
    given, is called on the process that writes with the :class:`Outcome` of the runs finished
    so far, after each group (a sweep writes its curves with it)."""

    kind: RunKind
    trainer: Trainer
    keys: jax.Array
    hps: Hyperparameters
    record: RunRecord
    description: str  # a few words, for the progress bar
    header: str  # a line, printed before compiling when progress is shown
    runs: tuple[Setting, ...] | None = None
    runs_per_call: int | None = None
    data_parallel: int | None = None
    after_group: Callable[[Outcome], None] | None = None
    share: tuple[int, int] | None = None

    def __post_init__(self) -> None:
        sweep = self.kind == "sweep"
        if (self.runs is not None) != sweep or (sweep and len(self.runs or ()) != self.num_runs):
            raise InvalidInput("a sweep's plan names each of its runs, and only a sweep's")
        if not sweep and self.num_runs != 1:
            raise InvalidInput(f"a train plan trains one run, not {self.num_runs}")
        if self.share is not None and not sweep:
            raise InvalidInput("only a sweep is split into parts")

    @property
    def num_runs(self) -> int:
        return int(self.keys.shape[0])

    @property
    def along_runs(self) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
        """How one run's functions take the run axis: a sweep's are vmapped (even over one
        run); a single run is its own program, so that its bits are those of one run
        compiled alone."""
        return jax.vmap if self.kind == "sweep" else one_run


@dataclasses.dataclass
class Outcome:
    """What the driver hands back: the last group's final state, every run's metrics
    ([run, update]), the update each run diverged at (from 1) or 0, and
    the times. `stopped_at` is the update where a callback stopped training, if it did."""

    state: TrainState
    metrics: dict[str, np.ndarray]
    diverged: np.ndarray
    compile_seconds: float
    train_seconds: float
    resumed_from: int
    runs_per_call: int
    stopped_at: int | None


def group_inputs(plan: Plan, group: int, size: int) -> tuple[jax.Array, Hyperparameters]:
    """The keys and hyperparameters of group `group`: runs group·size … (group+1)·size − 1,
    the last run repeated past the end, so that every group has one shape."""
    if group == 0 and size == plan.num_runs:
        return plan.keys, plan.hps  # as they are: a gather would compile a program per leaf
    index = _padded(group * size, size, plan.num_runs)
    return plan.keys[index], jax.tree.map(lambda x: x[index], plan.hps)


def group_size(
    plan: Plan,
    mesh: Mesh | None,
    checkpointed: CheckpointRecord | None,
    checkpoint_dir: str | Path | None,
) -> int:
    """Runs per compiled call: the sweep's chunk, or its recorded one when resuming, rounded
    up to split evenly over the devices that share the runs."""
    chunk = plan.runs_per_call
    directory = None if checkpoint_dir is None else Path(checkpoint_dir).absolute()
    if checkpointed is not None:
        if chunk is not None and chunk != checkpointed["runs_per_call"]:
            raise ConfigMismatch(
                f"{directory} holds a sweep of {checkpointed['runs_per_call']} runs "
                f"per compiled call, not {chunk}; resume without chunk, or with that"
            )
        chunk = checkpointed["runs_per_call"]
    across = mesh.shape["runs"] if mesh else 1
    size = _multiple(min(chunk or plan.num_runs, plan.num_runs), across)
    if checkpointed is not None and size != checkpointed["runs_per_call"]:
        raise ConfigMismatch(
            f"{directory} holds a sweep of {checkpointed['runs_per_call']} runs per "
            f"call, which does not split evenly over {across} devices; resume with devices "
            "that divide it"
        )
    return size


def part_plan(plan: Plan, size: int, across: int) -> Plan:
    """The plan of `plan`'s part: its share of the whole sweep's groups of
    `size` runs (:func:`part_runs`), whose groups are then the sweep's own (each starts at a
    multiple of `size`, and only the sweep's last is padded, by the sweep's last run)."""
    assert plan.share is not None
    start, stop = part_runs(plan.share, plan.num_runs, size, across)
    index = slice(start, stop)
    return dataclasses.replace(
        plan,
        keys=plan.keys[index],
        hps=jax.tree.map(lambda x: x[index], plan.hps),
        runs=cast(tuple[Setting, ...], plan.runs)[index],
        share=None,
    )


def share_bounds(part: object, count: int) -> tuple[int, int]:
    """Where the K-th of N shares of `count` things starts and stops, for ``part=(K, N)``:
    shares as equal as they can be, the first ones one longer; with fewer things than shares,
    the shares past them are empty."""
    k, n = check_part(part)
    size, extra = divmod(count, n)
    start = (k - 1) * size + min(k - 1, extra)
    return start, start + size + (k <= extra)


def part_bounds(part: object, count: int) -> tuple[int, int]:
    """:func:`share_bounds` of a sweep's `count` runs, which has one for each of its parts."""
    k, n = check_part(part)
    if n > count:
        raise InvalidInput(f"part {k} of {n}: the sweep has only {count} runs to share")
    return share_bounds(part, count)


def part_runs(part: tuple[int, int], num_runs: int, size: int, across: int = 1) -> tuple[int, int]:
    """Where the runs of ``part=(K, N)`` start and stop among a sweep's `num_runs` runs trained
    in groups of `size` (the sweep's runs per call, rounded to the `across` devices that share
    a group's runs): the K-th of N shares of the groups (:func:`part_bounds`), so that a part
    trains whole groups of the sweep, each as the unsplit sweep trains it."""
    groups = -(-num_runs // size)
    if part[1] > groups:
        # The most runs per call that make N groups, a multiple of `across`.
        most = (-(-num_runs // (part[1] - 1)) - 1) // across * across
        fewer = f"split it into at most {groups} part{'s' * (groups > 1)}"
        fix = f"give runs per call (chunk, --chunk) of at most {most}, or {fewer}"
        fix = fix if 0 < most < size else fewer
        raise InvalidInput(
            f"part {part[0]} of {part[1]}: the sweep's {num_runs} runs train as {groups} "
            f"group{'s' * (groups > 1)} of {size} per compiled call, and a part trains whole "
            f"groups of the sweep (so that it merges into the sweep run unsplit, bit for bit): "
            f"{fix}"
        )
    first, stop = part_bounds(part, groups)
    return first * size, min(stop * size, num_runs)


def _multiple(size: int, of: int) -> int:
    """`size` rounded up to a multiple of `of`."""
    return -(-size // of) * of


def _padded(begin: int, size: int, num_runs: int) -> np.ndarray:
    return np.minimum(np.arange(begin, begin + size), num_runs - 1)
