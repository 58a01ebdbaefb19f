"""Progress of a training program: what a report holds, a bar on a terminal, lines otherwise."""

from __future__ import annotations

import contextlib
import math
import sys
from collections.abc import Callable
from typing import Any, NamedTuple

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
        compiled = "reusing the compiled program"
        if p.compile_seconds:
            compiled = f"compiled in {p.compile_seconds:.1f} s"
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
