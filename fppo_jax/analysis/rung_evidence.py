"""What a rung's own scores say about cutting on them: whether its trials tie, how far apart
they are against the noise between seeds (the one-way ANOVA's F, the ratio of the
between-trial to the within-trial mean square, and its p), and whether the ranks carry from the
rung before (Spearman's ρ over the trials that ran both). A rung whose trials tie cuts none
(:class:`~fppo_jax.analysis.halving.SuccessiveHalving`): their numbers would choose. The rest
is recorded and reported: a rung that cannot tell its trials apart (a large p), or whose ranks
do not carry (ρ near 0 or below), cut on noise."""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from typing import Any, cast

import numpy as np

from fppo_jax.analysis.tuning_records import RungEvidence, TrialScore


def tied(rows: Sequence[TrialScore]) -> bool:
    """Whether every trial that did not diverge scored alike (one score, or none at all)."""
    scores = {row["score"] for row in rows if not row["diverged"]}
    return len(rows) > 1 and len(scores) <= 1


def evidence(rows: Sequence[TrialScore], before: Sequence[TrialScore] | None) -> RungEvidence:
    """The rung's evidence (see the module); None where it cannot be computed (fewer than two
    trials with two finite seed scores each, or fewer than three trials in both rungs)."""
    groups = [
        finite
        for row in rows
        if not row["diverged"] and (finite := _finite(row["seed_scores"])).size >= 2
    ]
    ratio = p = None
    if len(groups) >= 2 and np.ptp(np.concatenate(groups)) > 0:
        from scipy import stats

        with warnings.catch_warnings():  # a constant group: scipy warns, F is inf or nan
            warnings.simplefilter("ignore")
            found = stats.f_oneway(*groups)
        ratio, p = _number(found.statistic), _number(found.pvalue)
    carry = _carry(rows, before)
    return {"tied": tied(rows), "variance_ratio": ratio, "p": p, "rank_correlation": carry}


def _carry(rows: Sequence[TrialScore], before: Sequence[TrialScore] | None) -> float | None:
    if before is None:
        return None
    earlier = {row["trial"]: row["score"] for row in before}
    pairs = [
        (earlier[row["trial"]], row["score"])
        for row in rows
        if row["score"] is not None and earlier.get(row["trial"]) is not None
    ]
    if len(pairs) < 3:
        return None
    from scipy import stats

    with warnings.catch_warnings():  # constant ranks: scipy warns, ρ is nan
        warnings.simplefilter("ignore")
        rho = stats.spearmanr(*zip(*pairs, strict=True)).statistic
    return _number(rho)


def _finite(values: Sequence[float | None]) -> np.ndarray:
    x = np.array([math.nan if v is None else v for v in values], float)
    return cast(np.ndarray, x[np.isfinite(x)])


def _number(x: Any) -> float | None:
    value = float(x)
    return value if math.isfinite(value) else None
