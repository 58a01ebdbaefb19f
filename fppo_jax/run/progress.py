"""Progress of a training program: what a report holds and how it is counted, a bar on a
terminal, lines otherwise."""

from __future__ import annotations

import contextlib
import math
import sys
import time
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np

PROGRESS_LINES = 20  # chunks of updates a run is split into when progress is reported


class Progress(NamedTuple):
    """What a progress callback receives: once compiled (update 0, or the update a resumed run
    starts from), then after each chunk.

    `env_steps` and `total_steps` count every run; `average_return` is the mean over runs of
    each run's latest average return; `steps_per_second` and `eta` (seconds left) are measured
    over the updates run by this call. `loaded`: the program was loaded from the persistent
    compilation cache in its `compile_seconds`, not compiled.
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
    loaded: bool = False


class Counter:
    """Counts the progress of `num_runs` runs of `num_updates` updates of `samples` env steps
    each, trained in groups of `group_size` runs one after another, from update `update` of
    group `group` (where a resumed run starts); its clock starts when it is made."""

    def __init__(
        self,
        num_runs: int,
        group_size: int,
        num_updates: int,
        samples: int,
        compile_seconds: float,
        group: int = 0,
        update: int = 0,
        loaded: bool = False,
    ):
        self.num_runs, self.group_size = num_runs, group_size
        self.num_updates, self.samples = num_updates, samples
        self.compile_seconds, self.loaded = compile_seconds, loaded
        self.began = time.perf_counter()
        self.steps_before = self.steps(group, update)

    def elapsed(self) -> float:
        return time.perf_counter() - self.began

    def steps(self, group: int, update: int) -> int:
        """Env steps of every run, with groups before `group` done and `update` of this one."""
        runs_done = min(group * self.group_size, self.num_runs)
        in_group = min(self.group_size, self.num_runs - runs_done)
        return (runs_done * self.num_updates + in_group * update) * self.samples

    def progress(
        self, group: int, update: int, average_return: np.ndarray | None = None
    ) -> Progress:
        """The report at `update` of group `group`, given the group's latest average returns
        (None before training, when the clock has not run)."""
        total = self.num_runs * self.num_updates * self.samples
        steps = self.steps(group, update)
        elapsed = self.elapsed() if average_return is not None else 0.0
        rate = (steps - self.steps_before) / elapsed if elapsed > 0 else 0.0
        latest = math.nan
        if average_return is not None and np.isfinite(average_return).any():
            latest = float(np.nanmean(average_return))
        eta = (total - steps) / rate if rate > 0 else math.nan
        return Progress(
            update,
            self.num_updates,
            steps,
            total,
            latest,
            rate,
            elapsed,
            self.compile_seconds,
            eta,
            self.loaded,
        )


def print_progress(p: Progress) -> None:
    """The default progress line, on stderr."""
    if p.elapsed == 0:
        resumed = f"; resuming at update {p.update}" if p.update else ""
        compiled = "reusing the compiled program"
        if p.compile_seconds:
            done = "loaded from the compilation cache" if p.loaded else "compiled"
            compiled = f"{done} in {p.compile_seconds:.1f} s"
        print(f"{compiled}{resumed}", file=sys.stderr, flush=True)
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
