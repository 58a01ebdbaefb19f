"""The boundaries of a group-sequential test: Lan–DeMets' O'Brien–Fleming-type α-spending
function (:func:`spent`) and the critical values that spend it over a design's looks
(:func:`boundaries`), two-sided or one-sided. The rule that holds scores against them is
:mod:`fppo_jax.stats.sequential`'s, whose docstring derives them.
"""

from __future__ import annotations

import functools

import numpy as np

from fppo_jax.errors import InvalidInput

# Points per look of the boundaries' integration grid, odd for Simpson's rule: enough for the
# published boundaries to four decimals (tests/test_spending.py).
GRID_POINTS = 801


def spent(alpha: float, fraction: float) -> float:
    """Lan–DeMets' O'Brien–Fleming-type spending: the two-sided error spent by information
    fraction `fraction`, each side spending α/2 as 2 − 2Φ(Φ⁻¹(1 − α/4) / √t)."""
    from scipy import special

    return float(4 * special.ndtr(-special.ndtri(1 - alpha / 4) / np.sqrt(fraction)))


def _excess_crossing(
    bound: float,
    points: np.ndarray,
    weighted: np.ndarray,
    step: float,
    spend: float,
    sides: int,
) -> float:
    """The probability that a path not yet stopped, at `points` with density × weights
    `weighted`, crosses +`bound` (or, with two `sides`, ±`bound`) after an increment of sd
    `step`, less `spend`."""
    from scipy import special

    outside = special.ndtr((points - bound) / step)
    if sides == 2:
        outside = outside + special.ndtr((-bound - points) / step)
    return float(weighted @ outside) - spend


@functools.lru_cache(maxsize=256)
def boundaries(alpha: float, fractions: tuple[float, ...], sides: int = 2) -> tuple[float, ...]:
    """The critical values c_k on the Z scale at the information `fractions` (0 < t_1 < … ≤ 1)
    that spend `alpha` by :func:`spent`: P(first |Z_k| ≥ c_k at look k) = a*(t_k) − a*(t_{k−1})
    under the null hypothesis, by Simpson's rule over the values S = Z√t of the paths that have
    not crossed. With ``sides=1``, the one-sided test at level `alpha`: the upper boundary
    alone, spending ``spent(2·alpha, t) / 2`` (one side of the two-sided function at 2·alpha),
    so that P(first Z_k ≥ c_k at look k) is that spending's increment; it differs from the
    two-sided boundary at 2·alpha only by the paths that would cross both boundaries (in the
    fourth decimal at the levels of a study)."""
    from scipy import optimize

    if not fractions or any(b <= a for a, b in zip((0.0, *fractions), fractions, strict=False)):
        raise InvalidInput(f"information fractions must increase from above 0, got {fractions}")
    if fractions[-1] > 1:
        raise InvalidInput(f"information fractions must be at most 1, got {fractions}")
    if sides not in (1, 2):
        raise InvalidInput(f"a boundary has 1 or 2 sides, got {sides!r}")

    def spending(fraction: float) -> float:
        return spent(alpha, fraction) if sides == 2 else spent(2 * alpha, fraction) / 2

    critical: list[float] = []
    # The density of the paths that have not crossed, at the previous look, on its grid and
    # times Simpson's weights; before the first look every path is at 0.
    points, weighted = np.zeros(1), np.ones(1)
    previous, before = 0.0, 0.0
    for fraction in fractions:
        spend = spending(fraction) - before
        step = np.sqrt(fraction - previous)

        if spend <= 0:  # nothing left to spend at this look: it cannot decide
            bound = np.inf
        else:
            problem = (points, weighted, step, spend, sides)
            bound = optimize.brentq(_excess_crossing, 1e-9, 40.0, args=problem, xtol=1e-12)
        critical.append(float(bound / np.sqrt(fraction)))
        far = 12.0 * np.sqrt(fraction)  # beyond 12 sd no path is left to count
        top = min(bound, far)
        grid = np.linspace(-top if sides == 2 else -far, top, GRID_POINTS)
        simpson = np.full(GRID_POINTS, 2.0)
        simpson[1::2], simpson[[0, -1]] = 4.0, 1.0
        simpson *= (grid[1] - grid[0]) / 3
        gaussian = np.exp(-0.5 * ((grid[:, None] - points[None, :]) / step) ** 2)
        density = gaussian @ weighted / (step * np.sqrt(2 * np.pi))
        points, weighted = grid, simpson * density
        previous, before = fraction, spending(fraction)
    return tuple(critical)
