"""What a bootstrap interval says against a value, in words, for the reports that
``verdict.py``, ``planned_verdict.py`` and ``dose_response.py`` write: *better*, *worse* or
*not resolved* for a probability of improvement against ½, and *at the edge* where the bound
nearest the value lies within the bootstrap's Monte Carlo error of it (the range of that bound
over :data:`EDGE_SEEDS` resampling seeds), so that the interval neither holds nor excludes the
value to the bootstrap's resolution.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np


def outcome(probability: tuple[float, float, float], edge: Edge | None = None) -> str:
    """What the interval of a probability of improvement says, in words: *at the edge* where
    `edge` (:func:`edge`, of the interval against 0.5) says a bound is within its Monte Carlo
    error of 0.5."""
    _, low, high = probability
    if edge is not None:
        return "at the edge"
    if low > 0.5:
        return "better"
    if high < 0.5:
        return "worse"
    return "not resolved"


# The bootstrap's Monte Carlo error: an interval is drawn again with this many resampling seeds
# (0 is the reported one), and a bound's error is the range of its values over them.
EDGE_SEEDS = 20
# A bound further from the value than this share of its interval's width is taken as clear of it
# without drawing again: every bound measured here moves over the seeds by under a tenth of its
# interval's width.
EDGE_SCREEN = 0.25


@dataclass(frozen=True)
class Edge:
    """A bound within its Monte Carlo error of a value: which bound, its range over
    :data:`EDGE_SEEDS` resampling seeds, and the value."""

    bound: str  # "lower" or "upper"
    low: float
    high: float
    value: float

    def text(self, form: str = ".3f") -> str:
        return (
            f"its {self.bound} bound runs {self.low:{form}} to {self.high:{form}} over "
            f"{EDGE_SEEDS} resampling seeds"
        )


def edge_note(edges: list[str], value: str) -> list[str]:
    """The sentence under a table that names its intervals at the edge of `value`."""
    if not edges:
        return []
    return [
        "",
        f"At the edge: an interval whose bound lies within the bootstrap's Monte Carlo error of "
        f"{value} (the range of that bound over {EDGE_SEEDS} resampling seeds), so that it "
        f"neither holds nor excludes {value} to the resolution of the bootstrap: "
        + "; ".join(edges)
        + ".",
    ]


def edge(
    interval: tuple[float, float, float], draw: Callable[[int], Any], value: float
) -> Edge | None:
    """Whether `interval` (``draw(0)``, as reported) holds or excludes `value` only within the
    bootstrap's Monte Carlo error: the bound nearest `value` is no further from it than the
    range of that bound over :data:`EDGE_SEEDS` seeds of ``draw(seed)`` (which returns the
    interval resampled with `seed`). None where the interval clears `value` or its bound does
    not move with the seed (every resample the same, as when all runs tie)."""
    point, low, high = interval
    if np.isnan(point):
        return None
    index = 1 if abs(low - value) <= abs(high - value) else 2
    if abs(interval[index] - value) > EDGE_SCREEN * (high - low):
        return None
    bounds = np.array([interval[index], *(draw(seed)[index] for seed in range(1, EDGE_SEEDS))])
    error = float(bounds.max() - bounds.min())
    if error == 0 or abs(interval[index] - value) > error:
        return None
    return Edge(("lower", "upper")[index - 1], float(bounds.min()), float(bounds.max()), value)
