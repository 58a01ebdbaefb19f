"""Running a training program: compiled once, then called in equal chunks of updates.

One run, or many vmapped along a leading run axis. Between chunks the host reports progress
and checks the state; every chunk, and every group of runs of the same size, reuses the one
compiled program.
"""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from collections.abc import Callable
from typing import Any, NamedTuple

import jax
import numpy as np

from fppo_jax.config import Hyperparameters
from fppo_jax.trainer import METRICS, Trainer, TrainState

PROGRESS_LINES = 20  # chunks of updates a run is split into when progress is reported


class Progress(NamedTuple):
    """What a progress callback receives: once compiled (update 0), then after each chunk.

    `env_steps` and `total_steps` count every run; `average_return` is the mean over runs of
    each run's latest average return.
    """

    update: int
    num_updates: int
    env_steps: int
    total_steps: int
    average_return: float
    steps_per_second: float
    elapsed: float
    compile_seconds: float


def print_progress(p: Progress) -> None:
    """The default progress line, on stderr."""
    if p.update == 0:
        print(f"compiled in {p.compile_seconds:.1f} s", file=sys.stderr, flush=True)
        return
    avg = "-" if math.isnan(p.average_return) else f"{p.average_return:.1f}"
    print(
        f"update {p.update:>5}/{p.num_updates}  steps {p.env_steps:>10,}/{p.total_steps:,}  "
        f"{p.steps_per_second:>9,.0f} steps/s  average return {avg:>8}  ({p.elapsed:.1f} s)",
        file=sys.stderr,
        flush=True,
    )


@dataclasses.dataclass(frozen=True)
class Program:
    """A trainer's compiled init and chunk of updates, for one run or a batch of `runs`."""

    trainer: Trainer
    init: Callable[[jax.Array, Hyperparameters], TrainState]
    run: Callable[[TrainState, Hyperparameters], tuple[TrainState, Any]]
    runs: int | None  # None: unbatched
    compile_seconds: float


def compile_program(
    trainer: Trainer, keys: jax.Array, hps: Hyperparameters, chunks: int = 1
) -> Program:
    """Compile `trainer` for these keys and hyperparameters (a leading run axis if `keys` has
    one), running its updates in `chunks` equal calls."""
    num_updates = trainer.config.num_updates
    per_call = -(-num_updates // max(1, min(chunks, num_updates)))
    init = trainer.init

    def run(state: TrainState, hp: Hyperparameters) -> tuple[TrainState, Any]:
        return trainer.run(state, hp, per_call)

    runs = keys.shape[0] if keys.ndim else None
    if runs is not None:
        init, run = jax.vmap(init), jax.vmap(run)
    # Both programs are compiled here, ahead of time, so that compilation is never counted as
    # training time.
    start = time.perf_counter()
    state = jax.eval_shape(init, keys, hps)
    compiled_init = jax.jit(init).lower(keys, hps).compile()
    compiled_run = jax.jit(run).lower(state, hps).compile()
    return Program(trainer, compiled_init, compiled_run, runs, time.perf_counter() - start)


def execute(
    program: Program,
    keys: jax.Array,
    hps: Hyperparameters,
    report: Callable[[Progress], None] | None = None,
    check: Callable[[TrainState], None] | None = None,
) -> tuple[TrainState, dict[str, np.ndarray], float]:
    """Train from `keys`: (final state, metrics per update — [run, update] when batched —,
    seconds). `check` sees the state after every chunk (and may raise)."""
    config = program.trainer.config
    runs = program.runs or 1
    total = config.num_updates * config.samples_per_update * runs
    if report:
        report(
            Progress(0, config.num_updates, 0, total, math.nan, 0.0, 0.0, program.compile_seconds)
        )
    start = time.perf_counter()
    state = program.init(keys, hps)
    rows = []
    while int(np.max(state.update)) < config.num_updates:
        state, metrics = program.run(state, hps)
        rows.append(jax.device_get(metrics))
        if check:
            check(state)
        if report:
            elapsed = time.perf_counter() - start
            done = min(int(np.max(state.update)), config.num_updates)
            steps = done * config.samples_per_update * runs
            latest = _latest(rows[-1])
            report(
                Progress(
                    done,
                    config.num_updates,
                    steps,
                    total,
                    latest,
                    steps / max(elapsed, 1e-9),
                    elapsed,
                    program.compile_seconds,
                )
            )
    seconds = time.perf_counter() - start
    stacked = {name: np.concatenate([getattr(r, name) for r in rows], axis=-1) for name in METRICS}
    # Updates past the run's end (the last chunk's padding) are marked with env_steps −1.
    ran = stacked["env_steps"].reshape(-1, stacked["env_steps"].shape[-1])[0] >= 0
    return state, {name: values[..., ran] for name, values in stacked.items()}, seconds


def _latest(metrics: Any) -> float:
    ran = np.asarray(metrics.env_steps).reshape(-1, metrics.env_steps.shape[-1])[0] >= 0
    latest = np.asarray(metrics.average_return)[..., ran][..., -1]
    return float(np.nanmean(latest)) if np.isfinite(latest).any() else math.nan
