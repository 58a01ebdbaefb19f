"""The validation race: does a tuned setting beat the default it would replace? Each of k
finalists and the default train on the same n validation seeds, paired by seed (the seed draws
the environments' and the network's randomness alike for both). For finalist j the one-sided
Wilcoxon signed-rank test of H₀: the paired differences dᵢ = xⱼᵢ − x₀ᵢ are symmetric about 0,
against larger finalist scores, gives pⱼ (exact; zero differences dropped; p = 1 when every
difference is zero). Holm's procedure over the k finalists keeps the chance that the default is
replaced by a setting no better than it at most the level α, whatever the dependence between
the finalists. Among the finalists whose adjusted p is below α the one with the best mean score
over the validation seeds wins; if none, the default stays.

A run that diverged or finished no episode has no score: it loses its pair (its difference is
taken beyond every finite one, against it). With n seeds the smallest one-sided p is 2⁻ⁿ, so a
race of k finalists can replace the default only if 2⁻ⁿ < α/k: n ≥ 7 for k = 3 at α = 0.05
(:func:`smallest_p`)."""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np

from fppo_jax.errors import InvalidInput
from fppo_jax.stats.statistics import holm


@dataclasses.dataclass(frozen=True)
class RaceOutcome:
    """Each finalist's one-sided `p` against the default and its Holm-`adjusted` p, the
    finalists that beat it (`beat`, their indices) and the `winner` (an index, or None: the
    default stays)."""

    p: tuple[float, ...]
    adjusted: tuple[float, ...]
    beat: tuple[int, ...]
    winner: int | None


def smallest_p(seeds: int) -> float:
    """The smallest one-sided p of the signed-rank test on `seeds` pairs: every difference
    positive."""
    return float(2.0**-seeds)


def paired_differences(candidate: np.ndarray, default: np.ndarray) -> np.ndarray:
    """`candidate` − `default`, seed by seed; a pair where one run has no score (non-finite)
    goes against that run by more than any finite difference, a pair where neither has one
    counts as a tie."""
    x, y = np.asarray(candidate, float), np.asarray(default, float)
    if x.shape != y.shape or x.ndim != 1:
        raise InvalidInput(f"paired scores need one per seed each, got {x.shape} and {y.shape}")
    finite = np.isfinite(x) & np.isfinite(y)
    d = np.where(finite, x - y, 0.0)
    beyond = (np.max(np.abs(d)) if d.size else 0.0) + 1.0
    d = np.where(np.isfinite(x) & ~np.isfinite(y), beyond, d)
    return np.where(~np.isfinite(x) & np.isfinite(y), -beyond, d)


def signed_rank_p(candidate: np.ndarray, default: np.ndarray) -> float:
    """The one-sided p of the Wilcoxon signed-rank test that `candidate` scores above
    `default`, paired by seed (see the module)."""
    d = paired_differences(candidate, default)
    if not np.any(d != 0):
        return 1.0
    from scipy import stats

    with warnings.catch_warnings():  # scipy warns that zeros leave the exact distribution
        warnings.simplefilter("ignore", UserWarning)
        found = stats.wilcoxon(d, alternative="greater", zero_method="wilcox", method="exact")
    return float(found.pvalue)


def race(default: np.ndarray, finalists: np.ndarray, level: float) -> RaceOutcome:
    """The race of `finalists` (k × n scores, seed by seed) against the `default` (n scores) at
    family-wise level `level` (see the module)."""
    finalists = np.asarray(finalists, float)
    if finalists.ndim != 2 or finalists.shape[0] == 0:
        raise InvalidInput(f"a race needs at least one finalist's scores, got {finalists.shape}")
    p = [signed_rank_p(scores, default) for scores in finalists]
    adjusted = [float(a) for a in holm(p)]
    beat = tuple(j for j, a in enumerate(adjusted) if a < level)
    means = [float(np.mean(np.where(np.isfinite(s), s, -np.inf))) for s in finalists]
    winner = max(beat, key=lambda j: (means[j], -j)) if beat else None
    return RaceOutcome(tuple(p), tuple(adjusted), beat, winner)
