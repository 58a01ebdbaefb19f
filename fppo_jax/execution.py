"""Running a training program: compiled once, then called in equal chunks of updates.

One run, or many vmapped along a leading run axis. Between chunks the host reports progress
and checks the state; every chunk, and every group of runs of the same size, reuses the one
compiled program.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import sys
import time
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from fppo_jax.config import Hyperparameters
from fppo_jax.distributed import input_sharding, place, state_shardings
from fppo_jax.trainer import METRICS, Trainer, TrainState

PROGRESS_LINES = 20  # chunks of updates a run is split into when progress is reported


class Progress(NamedTuple):
    """What a progress callback receives: once compiled (update 0, or the update a resumed run
    starts from), then after each chunk.

    `env_steps` and `total_steps` count every run; `average_return` is the mean over runs of
    each run's latest average return; `steps_per_second` and `eta` (seconds left) are measured
    over the updates run by this call.
    """

    update: int
    num_updates: int
    env_steps: int
    total_steps: int
    average_return: float
    steps_per_second: float
    elapsed: float
    compile_seconds: float
    eta: float = math.nan


def print_progress(p: Progress) -> None:
    """The default progress line, on stderr."""
    if p.elapsed == 0:
        resumed = f"; resuming at update {p.update}" if p.update else ""
        print(f"compiled in {p.compile_seconds:.1f} s{resumed}", file=sys.stderr, flush=True)
        return
    avg = "-" if math.isnan(p.average_return) else f"{p.average_return:.1f}"
    print(
        f"update {p.update:>5}/{p.num_updates}  steps {p.env_steps:>10,}/{p.total_steps:,}  "
        f"{p.steps_per_second:>9,.0f} steps/s  average return {avg:>8}  "
        f"({p.elapsed:.1f} s, ETA {format_seconds(p.eta)})",
        file=sys.stderr,
        flush=True,
    )


def format_seconds(seconds: float) -> str:
    """``42 s``, ``3 min 05 s`` or ``2 h 07 min``; ``-`` if unknown."""
    if not math.isfinite(seconds):
        return "-"
    seconds = round(seconds)
    if seconds < 60:
        return f"{seconds} s"
    if seconds < 3600:
        return f"{seconds // 60} min {seconds % 60:02d} s"
    return f"{seconds // 3600} h {seconds % 3600 // 60:02d} min"


class ProgressBar:
    """A progress bar on the terminal (rich): env steps, steps/s, average return and ETA.
    A context manager; call it with each :class:`Progress`."""

    def __init__(self, description: str):
        from rich.console import Console
        from rich.progress import BarColumn, MofNCompleteColumn, TextColumn
        from rich.progress import Progress as RichProgress

        self._bar = RichProgress(
            TextColumn("{task.description}"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn(
                "steps  {task.fields[speed]}  average return {task.fields[ret]}  "
                "ETA {task.fields[eta]}"
            ),
            transient=False,
            console=Console(stderr=True),
        )
        self._task = self._bar.add_task(description, total=None, speed="-", ret="-", eta="-")

    def __enter__(self) -> ProgressBar:
        self._bar.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._bar.stop()

    def __call__(self, p: Progress) -> None:
        self._bar.update(
            self._task,
            total=p.total_steps,
            completed=p.env_steps,
            speed=f"{p.steps_per_second:,.0f}/s" if p.elapsed else "-",
            ret="-" if math.isnan(p.average_return) else f"{p.average_return:.1f}",
            eta=format_seconds(p.eta),
        )


def reporter(progress: bool | Callable[[Progress], None], description: str) -> Any:
    """The context manager that reports progress for `train` and `sweep`'s `progress`
    argument: a bar on a terminal, lines otherwise, the user's callable, or nothing (None)."""
    if callable(progress):
        return contextlib.nullcontext(progress)
    if not progress:
        return contextlib.nullcontext(None)
    if sys.stderr.isatty():
        return ProgressBar(description)
    return contextlib.nullcontext(print_progress)


def updates_per_call(num_updates: int, calls: int) -> int:
    """Updates per compiled call to run `num_updates` in (at most) `calls` equal calls."""
    return -(-num_updates // max(1, min(calls, num_updates)))


@dataclasses.dataclass(frozen=True)
class Program:
    """A trainer's compiled init and chunk of updates, for one run or a batch of `runs`."""

    trainer: Trainer
    init: Callable[[jax.Array, Hyperparameters], TrainState]
    run: Callable[[TrainState, Hyperparameters], tuple[TrainState, Any]]
    runs: int | None  # None: unbatched
    updates_per_call: int
    compile_seconds: float


def compile_program(
    trainer: Trainer,
    keys: jax.Array,
    hps: Hyperparameters,
    updates_per_call: int,
    mesh: Mesh | None = None,
) -> Program:
    """Compile `trainer` for these keys and hyperparameters (a leading run axis if `keys` has
    one), running `updates_per_call` updates per call, on `mesh` if given (see
    :mod:`fppo_jax.distributed`) or on the default device."""
    init = trainer.init

    def run(state: TrainState, hp: Hyperparameters) -> tuple[TrainState, Any]:
        return trainer.run(state, hp, updates_per_call)

    runs = keys.shape[0] if keys.ndim else None
    if runs is not None:
        init, run = jax.vmap(init), jax.vmap(run)
    # Both programs are compiled here, ahead of time, so that compilation is never counted as
    # training time.
    start = time.perf_counter()
    state = jax.eval_shape(init, keys, hps)
    if mesh is None:
        compiled_init = jax.jit(init).lower(keys, hps).compile()
        compiled_run = jax.jit(run).lower(state, hps).compile()
    else:
        inputs = input_sharding(mesh, runs is not None)
        placed = state_shardings(mesh, state, runs is not None)
        compiled_init = _Placed(
            jax.jit(init, in_shardings=(inputs, inputs), out_shardings=placed)
            .lower(keys, hps)
            .compile(),
            (inputs, inputs),
        )
        # Metrics are small: replicated, so that every process of a multi-process run can read
        # them all.
        metrics = NamedSharding(mesh, PartitionSpec())
        compiled_run = _Placed(
            jax.jit(run, in_shardings=(placed, inputs), out_shardings=(placed, metrics))
            .lower(state, hps)
            .compile(),
            (placed, inputs),
        )
    seconds = time.perf_counter() - start
    return Program(trainer, compiled_init, compiled_run, runs, updates_per_call, seconds)


@dataclasses.dataclass(frozen=True)
class _Placed:
    """A compiled program whose arguments are first laid out as it expects (a no-op for arrays
    already so, such as the state it returned)."""

    compiled: Any
    shardings: tuple

    def __call__(self, *args: Any) -> Any:
        return self.compiled(*(place(a, s) for a, s in zip(args, self.shardings, strict=True)))

    def memory_analysis(self) -> Any:
        return self.compiled.memory_analysis()


def execute(
    program: Program,
    keys: jax.Array,
    hps: Hyperparameters,
    *,
    start: tuple[TrainState, dict[str, np.ndarray]] | None = None,
    report: Callable[[Progress], None] | None = None,
    after_chunk: Callable[[TrainState, dict[str, np.ndarray]], None] | None = None,
) -> tuple[TrainState, dict[str, np.ndarray], float]:
    """Train from `keys`, or from `start` (a state and the metrics that led to it): (final
    state, metrics per update — [run, update] when batched —, seconds). `after_chunk` sees the
    state and the metrics so far after every compiled call, and may raise to stop."""
    config = program.trainer.config
    runs = program.runs or 1
    total = config.num_updates * config.samples_per_update * runs
    state, rows = (program.init(keys, hps), []) if start is None else (start[0], [start[1]])
    first = int(np.max(state.update)) if start is not None else 0
    if report:
        steps = first * config.samples_per_update * runs
        report(
            Progress(
                first, config.num_updates, steps, total, math.nan, 0.0, 0.0, program.compile_seconds
            )
        )
    calls = -(-(config.num_updates - first) // program.updates_per_call)
    began = time.perf_counter()
    pending = program.run(state, hps) if calls else None
    for call in range(calls):
        state, metrics = pending
        if call + 1 < calls:
            # Dispatched before the host's work on this chunk, so that the work overlaps it.
            pending = program.run(state, hps)
        rows.append(_ran(jax.device_get(metrics._asdict())))
        if after_chunk:
            after_chunk(state, _concatenate(rows))
        if report:
            elapsed = time.perf_counter() - began
            done = min(first + (call + 1) * program.updates_per_call, config.num_updates)
            steps = done * config.samples_per_update * runs
            rate = (done - first) * config.samples_per_update * runs / max(elapsed, 1e-9)
            report(
                Progress(
                    done,
                    config.num_updates,
                    steps,
                    total,
                    _latest(rows[-1]),
                    rate,
                    elapsed,
                    program.compile_seconds,
                    (total - steps) / max(rate, 1e-9),
                )
            )
    return state, _concatenate(rows), time.perf_counter() - began


def _ran(metrics: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Without the updates past the run's end (the last chunk's padding, env_steps −1)."""
    steps = metrics["env_steps"]
    ran = steps.reshape(-1, steps.shape[-1])[0] >= 0
    return {name: values[..., ran] for name, values in metrics.items()}


def _concatenate(rows: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    return {name: np.concatenate([r[name] for r in rows], axis=-1) for name in METRICS}


def _latest(metrics: dict[str, np.ndarray]) -> float:
    returns = np.asarray(metrics["average_return"])
    if returns.shape[-1] == 0:
        return math.nan
    latest = returns[..., -1]
    return float(np.nanmean(latest)) if np.isfinite(latest).any() else math.nan
