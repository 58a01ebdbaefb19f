"""Statistics of training runs that a reviewer accepts: endpoints, interval estimates, comparisons.

Following Agarwal et al. (2021), *Deep reinforcement learning at the edge of the statistical
precipice* (NeurIPS), whose library, rliable, these reproduce on ``scipy.stats``:

- a run's score is an **endpoint** of its learning curve (:data:`ENDPOINTS`);
- a setting is summarised by a point estimate of its runs' scores — the mean, the median or
  the **interquartile mean** (IQM: the mean of the middle 50%, ``scipy.stats.trim_mean(x,
  0.25)``) — with a **percentile bootstrap** confidence interval over its runs;
- two settings are compared by the **probability of improvement** P(X > Y) + ½ P(X = Y), the
  Mann–Whitney U statistic over n·m, and by the difference of their IQMs, each with a bootstrap
  interval that resamples both settings' runs independently;
- a family of comparisons is tested with the Mann–Whitney U test of each probability of
  improvement against ½, its p-values adjusted by Holm's step-down method;
- across tasks, scores are first normalised per task, and resampling is **stratified**: each
  task's runs are resampled among themselves (scipy's bootstrap of several independent samples);
- a dose-response (runs at several strengths of one hyperparameter) is summarised by **Spearman's
  rank correlation** ρ between dose and score over every run, with a bootstrap interval that
  resamples each dose's runs among themselves, and tested by a **permutation test** of ρ = 0
  (the doses relabelled at random).

Spreads are sample standard deviations (``ddof=1``). Every interval is seeded, so it repeats.
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Callable, Sequence
from typing import cast

import numpy as np

from fppo_jax.core.checks import check_fraction, positive_int
from fppo_jax.errors import InvalidInput

CONFIDENCE = 0.95
RESAMPLES = 2000

# A run's score from its curve of the last-100-episode average return, [run, update].
ENDPOINTS: dict[str, str] = {
    "final": "the last-100-episode average return after the last update",
    "max": "the largest last-100-episode average return after any update (the run's best)",
    "auc": "the area under the learning curve: the average return averaged over updates",
    "eval": "the last evaluation's return (eval_every): the deterministic policy's mean return",
}
# The endpoints a study decides on (fppo_jax.analysis.studies; eval where its runs are evaluated);
# those not chosen are reported beside it, with max.
STUDY_ENDPOINTS = ("final", "auc", "eval")
STATISTICS: dict[str, str] = {
    "iqm": "IQM",
    "mean": "mean",
    "median": "median",
}


def endpoint(curves: np.ndarray, name: str = "final") -> np.ndarray:
    """Each run's score (:data:`ENDPOINTS`) from `curves`, [run, update]: the average return's,
    or for ``eval`` the evaluation return's (NaN between evaluations). Updates before a run's
    first finished episode (NaN) are left out of ``max`` and ``auc``; a run with no finished
    episode (or no evaluation) scores NaN."""
    curves = np.asarray(curves, dtype=float)
    if name not in ENDPOINTS:
        raise InvalidInput(f"unknown endpoint {name!r}; valid endpoints: {', '.join(ENDPOINTS)}")
    if curves.ndim != 2:
        raise InvalidInput(f"curves must be [run, update], got shape {curves.shape}")
    if name == "final":
        return curves[:, -1]
    finite = np.isfinite(curves)
    if name == "eval":
        last = np.where(finite.any(axis=1), curves.shape[1] - 1 - np.argmax(finite[:, ::-1], 1), 0)
        return np.where(finite.any(axis=1), curves[np.arange(len(curves)), last], np.nan)
    filled = np.where(finite, curves, 0.0)
    counts = finite.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        if name == "max":
            best = np.where(finite, curves, -np.inf).max(axis=1)
            return np.where(counts > 0, best, np.nan)
        return np.where(counts > 0, filled.sum(axis=1) / counts, np.nan)


def steps_to_threshold(curves: np.ndarray, steps: np.ndarray, threshold: float) -> np.ndarray:
    """The env steps at which each run's curve, [run, update], first reaches `threshold`
    (``steps``: the env steps after each update, [update] or [run, update]); ``inf`` for a run
    that never does. Lower is better: how fast, where ``auc`` mixes speed and level."""
    curves = np.asarray(curves, dtype=float)
    steps = np.broadcast_to(np.asarray(steps, dtype=float), curves.shape)
    with np.errstate(invalid="ignore"):
        reached = curves >= threshold  # NaN (no episode finished yet) never reaches
    first = np.argmax(reached, axis=1)
    return np.where(reached.any(axis=1), steps[np.arange(len(curves)), first], np.inf)


def iqm(x: np.ndarray, axis: int = -1) -> np.ndarray:
    """The interquartile mean: the mean after ⌊n/4⌋ of the n values are cut from each end, as
    ``scipy.stats.trim_mean(x, 0.25)`` (and so rliable) computes it; NaNs are left out first."""
    x = np.moveaxis(np.asarray(x, dtype=float), axis, -1)
    ordered = np.sort(x, axis=-1)  # NaNs last
    n = np.isfinite(x).sum(axis=-1, keepdims=True)
    cut = n // 4
    position = np.arange(x.shape[-1])
    kept = (position >= cut) & (position < n - cut)
    with np.errstate(invalid="ignore"):
        return cast(np.ndarray, np.sum(np.where(kept, ordered, 0.0), axis=-1) / kept.sum(axis=-1))


def _mean(x: np.ndarray, axis: int = -1) -> np.ndarray:
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all NaN: stays NaN
        return cast(np.ndarray, np.nanmean(x, axis=axis))


def _median(x: np.ndarray, axis: int = -1) -> np.ndarray:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return cast(np.ndarray, np.nanmedian(x, axis=axis))


ESTIMATORS: dict[str, Callable[..., np.ndarray]] = {"iqm": iqm, "mean": _mean, "median": _median}


def estimator(name: str) -> Callable[..., np.ndarray]:
    """The point estimate called `name` (:data:`STATISTICS`), as ``f(x, axis=-1)``."""
    if name not in ESTIMATORS:
        raise InvalidInput(f"unknown statistic {name!r}; valid statistics: {', '.join(STATISTICS)}")
    return ESTIMATORS[name]


def sample_std(x: np.ndarray) -> float:
    """The sample standard deviation (``ddof=1``; NaN for fewer than two values)."""
    x = _finite(x)
    return float(np.std(x, ddof=1)) if x.size > 1 else float("nan")


def _finite(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, dtype=float).ravel()
    return cast(np.ndarray, x[np.isfinite(x)])


def check_confidence(confidence: object) -> float:
    """`confidence` if it is a level in (0, 1)."""
    return check_fraction("the confidence level", confidence)


def bootstrap(
    samples: Sequence[np.ndarray],
    statistic: Callable[..., np.ndarray],
    *,
    confidence: float = CONFIDENCE,
    resamples: int = RESAMPLES,
    seed: int = 0,
) -> tuple[float, float, float]:
    """`statistic` of the independent `samples` and its percentile bootstrap interval at level
    `confidence`: each sample is resampled with replacement among its own values (a stratified
    bootstrap when the samples are tasks). `statistic(*samples, axis=-1)` must be vectorised.
    Non-finite values are dropped first; a sample left empty gives NaNs."""
    confidence = check_confidence(confidence)
    resamples = positive_int("resamples", resamples)
    samples = [_finite(s) for s in samples]
    if any(s.size == 0 for s in samples):
        return float("nan"), float("nan"), float("nan")
    point = float(statistic(*samples, axis=-1))
    if all(np.ptp(s) == 0 for s in samples):  # nothing to resample: the interval is the point
        return point, point, point
    from scipy import stats  # on first use: a second's import that training never needs

    result = stats.bootstrap(
        samples,
        statistic,
        n_resamples=resamples,
        confidence_level=confidence,
        method="percentile",
        vectorized=True,
        paired=False,
        rng=np.random.default_rng(seed),
    )
    low, high = result.confidence_interval
    return point, float(low), float(high)


def interval(
    x: np.ndarray,
    statistic: str = "iqm",
    *,
    confidence: float = CONFIDENCE,
    resamples: int = RESAMPLES,
    seed: int = 0,
) -> tuple[float, float, float]:
    """A setting's `statistic` (:data:`STATISTICS`) of its runs' scores `x`, with its percentile
    bootstrap interval: ``(point, low, high)``."""
    f = estimator(statistic)
    return bootstrap([x], f, confidence=confidence, resamples=resamples, seed=seed)


def curve_interval(
    curves: np.ndarray,
    statistic: str = "iqm",
    *,
    confidence: float = CONFIDENCE,
    resamples: int = 1000,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`statistic` of `curves` [run, update] over runs at every update, with a percentile
    bootstrap band: each resample draws runs (whole curves) with replacement, the same draw for
    every update. NaN (a run with no finished episode yet) is left out of its update."""
    confidence = check_confidence(confidence)
    resamples = positive_int("resamples", resamples)
    f = estimator(statistic)
    curves = np.asarray(curves, dtype=float)
    runs = np.random.default_rng(seed).integers(0, len(curves), (resamples, len(curves)))
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # updates before any episode: NaN
        point = f(curves.T, axis=-1)
        draws = f(np.moveaxis(curves[runs], -2, -1), axis=-1)  # [resample, update]
        tail = 100 * (1 - confidence) / 2
        low, high = np.nanpercentile(draws, [tail, 100 - tail], axis=0)
    return point, low, high


def probability_of_improvement(x: np.ndarray, y: np.ndarray, axis: int = -1) -> np.ndarray:
    """P(X > Y) + ½ P(X = Y) for a score X of `x`'s setting and Y of `y`'s, from all n·m pairs:
    the Mann–Whitney U statistic of `x` over n·m (Agarwal et al. 2021, Sect. 4)."""
    x, y = np.moveaxis(np.asarray(x, float), axis, -1), np.moveaxis(np.asarray(y, float), axis, -1)
    difference = x[..., :, None] - y[..., None, :]
    return cast(np.ndarray, np.mean((difference > 0) + 0.5 * (difference == 0), axis=(-2, -1)))


def improvement_test(x: np.ndarray, y: np.ndarray) -> float:
    """The two-sided p-value of the Mann–Whitney U test that a score of `x`'s setting is as
    likely to be above one of `y`'s as below it, P(X > Y) + ½ P(X = Y) = ½: the test that goes
    with :func:`probability_of_improvement` (``scipy.stats.mannwhitneyu``: exact for small
    samples without ties, the normal approximation with a tie correction otherwise).
    Non-finite scores are left out; NaN if either setting has none."""
    x, y = _finite(x), _finite(y)
    if x.size == 0 or y.size == 0:
        return float("nan")
    if np.ptp(np.concatenate([x, y])) == 0:  # every score tied: no evidence either way
        return 1.0
    from scipy import stats

    return float(stats.mannwhitneyu(x, y, alternative="two-sided").pvalue)


def holm(p_values: Sequence[float]) -> np.ndarray:
    """Holm's (1979) step-down adjustment of a family of m p-values: the i-th smallest becomes
    max over j ≤ i of min(1, (m − j + 1)·p₍ⱼ₎). Rejecting every hypothesis whose adjusted p is
    below α keeps the chance of any false rejection in the family at most α, whatever the
    dependence between the tests. A comparison not yet made can be entered as 1."""
    p = np.asarray(p_values, dtype=float)
    if p.ndim != 1 or np.any(~np.isfinite(p)) or np.any((p < 0) | (p > 1)):
        raise InvalidInput(f"Holm's adjustment needs finite p-values in [0, 1], got {p_values!r}")
    order = np.argsort(p, kind="stable")
    scaled = np.minimum(1.0, (len(p) - np.arange(len(p))) * p[order])
    adjusted = np.empty_like(p)
    adjusted[order] = np.maximum.accumulate(scaled)
    return adjusted


def compare(
    x: np.ndarray,
    y: np.ndarray,
    *,
    confidence: float = CONFIDENCE,
    resamples: int = RESAMPLES,
    seed: int = 0,
) -> dict[str, tuple[float, float, float]]:
    """`x`'s runs against `y`'s: the probability of improvement and the difference in IQM
    (x − y), each ``(point, low, high)`` with a bootstrap interval over both settings' runs."""
    of_both = functools.partial(
        bootstrap, [x, y], confidence=confidence, resamples=resamples, seed=seed
    )
    return {
        "probability_of_improvement": of_both(probability_of_improvement),
        "iqm_difference": of_both(lambda a, b, axis=-1: iqm(a, axis) - iqm(b, axis)),
    }


def max_average_difference(
    x: np.ndarray,
    y: np.ndarray,
    *,
    confidence: float = CONFIDENCE,
    resamples: int = RESAMPLES,
    seed: int = 0,
) -> tuple[float, float, float]:
    """The paper's statistic — the maximum over updates of the seed-mean learning curve — of
    `x`'s curves [run, update] minus that of `y`'s, with a percentile bootstrap interval that
    resamples each setting's runs (whole curves) independently. This is the interval a gap in
    the paper's Table 1 can be set against."""
    confidence = check_confidence(confidence)
    resamples = positive_int("resamples", resamples)
    rng = np.random.default_rng(seed)

    def paper_statistic(curves: np.ndarray) -> np.ndarray:  # [..., run, update] -> [...]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # updates before any episode
            return cast(np.ndarray, np.nanmax(np.nanmean(curves, axis=-2), axis=-1))

    x, y = np.asarray(x, float), np.asarray(y, float)
    point = float(paper_statistic(x) - paper_statistic(y))
    draws = np.empty(resamples)
    for start in range(0, resamples, 250):  # in blocks, to bound the memory of [draw, run, update]
        count = min(250, resamples - start)
        pick_x = rng.integers(0, len(x), (count, len(x)))
        pick_y = rng.integers(0, len(y), (count, len(y)))
        draws[start : start + count] = paper_statistic(x[pick_x]) - paper_statistic(y[pick_y])
    tail = 100 * (1 - confidence) / 2
    low, high = np.percentile(draws, [tail, 100 - tail])
    return point, float(low), float(high)


def normalise(scores: np.ndarray, low: float, high: float) -> np.ndarray:
    """Scores on a task's own scale mapped so that `low` is 0 and `high` is 1."""
    if not np.isfinite(low) or not np.isfinite(high) or high == low:
        raise InvalidInput(f"normalising needs two different finite scores, got {low} and {high}")
    return (np.asarray(scores, float) - low) / (high - low)


def _pooled(statistic: Callable[..., np.ndarray]) -> Callable[..., np.ndarray]:
    """`statistic` of every task's normalised scores pooled, as ``f(*tasks, axis=-1)``."""

    def pooled(*tasks: np.ndarray, axis: int = -1) -> np.ndarray:
        return statistic(np.concatenate(tasks, axis=axis), axis=axis)

    return pooled


def optimality_gap(x: np.ndarray, axis: int = -1, threshold: float = 1.0) -> np.ndarray:
    """The mean shortfall of normalised scores below `threshold`: mean(max(0, threshold − x))."""
    return cast(np.ndarray, np.mean(threshold - np.minimum(x, threshold), axis=axis))


AGGREGATES: dict[str, Callable[..., np.ndarray]] = {
    "iqm": iqm,
    "mean": _mean,
    "median": _median,
    "optimality_gap": optimality_gap,
}


def aggregate(
    tasks: Sequence[np.ndarray],
    statistic: str = "iqm",
    *,
    confidence: float = CONFIDENCE,
    resamples: int = RESAMPLES,
    seed: int = 0,
) -> tuple[float, float, float]:
    """`statistic` (:data:`AGGREGATES`) of one setting's normalised scores pooled over `tasks`
    (one array of runs per task), with a stratified bootstrap interval."""
    if statistic not in AGGREGATES:
        raise InvalidInput(f"unknown aggregate {statistic!r}; valid: {', '.join(AGGREGATES)}")
    f = _pooled(AGGREGATES[statistic])
    return bootstrap(tasks, f, confidence=confidence, resamples=resamples, seed=seed)


def aggregate_improvement(
    pairs: Sequence[tuple[np.ndarray, np.ndarray]],
    *,
    confidence: float = CONFIDENCE,
    resamples: int = RESAMPLES,
    seed: int = 0,
) -> tuple[float, float, float]:
    """The probability of improvement averaged over tasks, one ``(x, y)`` pair of run scores per
    task (no normalisation needed: it compares ranks within each task), with a stratified
    bootstrap interval that resamples every task's runs of both settings independently."""

    def mean_over_tasks(*samples: np.ndarray, axis: int = -1) -> np.ndarray:
        values = [
            probability_of_improvement(x, y, axis)
            for x, y in zip(samples[::2], samples[1::2], strict=True)
        ]
        return cast(np.ndarray, np.mean(values, axis=0))

    samples = [s for pair in pairs for s in pair]
    return bootstrap(
        samples, mean_over_tasks, confidence=confidence, resamples=resamples, seed=seed
    )


def performance_profile(scores: np.ndarray, thresholds: np.ndarray) -> np.ndarray:
    """The fraction of runs whose normalised score exceeds each of `thresholds` (Agarwal et al.
    2021, Sect. 4: the score distribution's tail, run by run)."""
    scores = _finite(scores)
    return cast(
        np.ndarray, np.mean(scores[None, :] > np.asarray(thresholds, float)[:, None], axis=1)
    )


def spearman(doses: np.ndarray, scores: np.ndarray, axis: int = -1) -> np.ndarray:
    """Spearman's rank correlation between `doses` [run] and `scores` [..., run] along `axis`:
    the Pearson correlation of their ranks, ties given their mid-rank. NaN where the scores are
    all tied (no ranking to correlate)."""
    from scipy import stats

    scores = np.moveaxis(np.asarray(scores, float), axis, -1)
    dose_ranks = stats.rankdata(np.asarray(doses, float))
    score_ranks = stats.rankdata(scores, axis=-1)
    dose_ranks = dose_ranks - dose_ranks.mean()
    score_ranks = score_ranks - score_ranks.mean(axis=-1, keepdims=True)
    spread = np.sqrt(np.sum(score_ranks**2, axis=-1) * np.sum(dose_ranks**2))
    with np.errstate(invalid="ignore", divide="ignore"):
        return cast(np.ndarray, score_ranks @ dose_ranks / spread)


def _dose_runs(
    doses: Sequence[float], groups: Sequence[np.ndarray]
) -> tuple[list[np.ndarray], np.ndarray]:
    """Each dose's finite scores, and the dose of every one of them in order."""
    if len(doses) != len(groups) or len(set(doses)) < 2:
        raise InvalidInput(
            f"a dose-response needs one group of scores per dose and two doses or more, got "
            f"{len(groups)} group(s) for doses {list(doses)}"
        )
    kept = [_finite(g) for g in groups]
    return kept, np.repeat(np.asarray(doses, float), [g.size for g in kept])


def dose_trend(
    doses: Sequence[float],
    groups: Sequence[np.ndarray],
    *,
    confidence: float = CONFIDENCE,
    resamples: int = RESAMPLES,
    seed: int = 0,
) -> tuple[float, float, float]:
    """Spearman's ρ between dose and score over the runs of every dose (`groups[i]`: the scores
    of the runs at `doses[i]`), with a percentile bootstrap interval that resamples each dose's
    runs among themselves: ``(ρ, low, high)``. ρ > 0: more dose, higher scores."""
    kept, labels = _dose_runs(doses, groups)

    def rho(*samples: np.ndarray, axis: int = -1) -> np.ndarray:
        return spearman(labels, np.concatenate(samples, axis=axis), axis)

    return bootstrap(kept, rho, confidence=confidence, resamples=resamples, seed=seed)


def trend_test(
    doses: Sequence[float],
    groups: Sequence[np.ndarray],
    *,
    permutations: int = 10_000,
    seed: int = 0,
) -> float:
    """The two-sided p-value of no monotone trend, ρ = 0 (:func:`dose_trend`), by permutation:
    the share of `permutations` seeded relabellings of the runs' doses whose |ρ| is at least the
    observed, the observed labelling counted among them ((1 + count) / (1 + permutations), so
    never 0). Exact in its error rate whatever the scores' distribution."""
    permutations = positive_int("permutations", permutations)  # none would answer 1.0
    kept, labels = _dose_runs(doses, groups)
    scores = np.concatenate(kept)
    observed = spearman(labels, scores)
    if not np.isfinite(observed):  # every score tied: no evidence of a trend
        return 1.0
    shuffled = np.random.default_rng(seed).permuted(np.tile(scores, (permutations, 1)), axis=-1)
    # The same ρ computed in another order may differ in its last bit: compare with a tolerance.
    extreme = np.abs(spearman(labels, shuffled)) >= abs(observed) - 1e-12
    return float((1 + np.sum(extreme)) / (1 + permutations))
