"""What a report of comparisons is made of, public so that a report written outside the
library (a script's, a notebook's) says each thing as the library's own reports do:

- :func:`interval_cell`: a point estimate with its interval, ``12.3 [10.1, 14.0]``.
- :func:`ruled_out`: the relative effects an IQM difference's interval [l, h] excludes, as a
  share of the baseline's IQM b: a gain above h / |b| and a loss above −l / |b| (every gain
  where h ≤ 0, every loss where l ≥ 0).
- :func:`holm_verdicts` and :func:`mann_whitney_verdicts`: the fixed-design verdict of a family
  of m comparisons, decided once, at the seeds recorded. Each comparison has a two-sided
  p-value (Mann–Whitney's U test of P(candidate > baseline) + ½ P(=) = ½, or any other test of
  no effect); Holm's step-down method adjusts them over the family, the i-th smallest becoming
  p̃₍ᵢ₎ = max over j ≤ i of min(1, (m − j + 1)·p₍ⱼ₎); a comparison is *better* where p̃ < α and
  its effect lies above no effect (P(candidate > baseline) > ½), *worse* where p̃ < α and it
  does not, and otherwise shows *no measurable difference*. The chance of a better or worse
  anywhere in the family where the settings score alike is then at most α (:data:`LEVEL`
  unless given), whatever the dependence between the tests.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from fppo_jax.errors import InvalidInput
from fppo_jax.stats import statistics

# The family-wise error of a fixed-design verdict unless a plan names another.
LEVEL = 0.05
# A verdict where Holm's adjusted p is not below the level: neither better nor worse is shown.
NO_DIFFERENCE = "no measurable difference"


def interval_cell(values: tuple[float, float, float], form: str) -> str:
    """``(point, low, high)`` as a table cell in the format `form` (``".2f"``):
    ``"0.61 [0.52, 0.70]"``, or "–" where the point is NaN (nothing to estimate it from)."""
    point, low, high = values
    return "–" if np.isnan(point) else f"{point:{form}} [{low:{form}}, {high:{form}}]"


def ruled_out(difference: tuple[float, float, float], baseline_iqm: float) -> str:
    """The relative effects an IQM difference's interval excludes, as a share of the
    baseline's IQM: "a gain above 12% and a loss above 30% of the baseline's IQM"; in the
    scores' own units where that IQM is 0 or not finite, "–" where the interval is not."""
    _, low, high = difference
    if not (np.isfinite(low) and np.isfinite(high)):
        return "–"
    if not np.isfinite(baseline_iqm) or baseline_iqm == 0:
        return f"a gain above {max(high, 0):.1f} and a loss above {max(-low, 0):.1f}"
    scale = abs(baseline_iqm)
    gain = "any gain" if high <= 0 else f"a gain above {high / scale:.0%}"
    loss = "any loss" if low >= 0 else f"a loss above {-low / scale:.0%}"
    return f"{gain} and {loss} of the baseline's IQM"


@dataclasses.dataclass(frozen=True)
class Verdict:
    """One comparison of a family: its test's two-sided `p` (NaN where it could not be tested),
    that p adjusted by Holm's method over the family (`holm`) and the `verdict` at the family's
    level: ``"better"``, ``"worse"`` or :data:`NO_DIFFERENCE`."""

    p: float
    holm: float
    verdict: str


def holm_verdicts(
    p_values: Sequence[float],
    effects: Sequence[float],
    *,
    level: float = LEVEL,
    no_effect: float = 0.5,
) -> list[Verdict]:
    """The family's verdicts from each comparison's two-sided p-value and its effect's point
    estimate (P(candidate > baseline), or a correlation with `no_effect` 0): better where Holm's
    adjusted p is below `level` and the effect above `no_effect`, worse where it is below and
    the effect not above, else :data:`NO_DIFFERENCE`. A NaN p (a comparison not recorded yet,
    or with no scores) enters the adjustment as 1, so that it can only fall as the family
    fills in."""
    if len(p_values) != len(effects):
        raise InvalidInput(
            f"{len(p_values)} p-values for {len(effects)} effects: one of each a comparison"
        )
    tested = [1.0 if np.isnan(p) else float(p) for p in p_values]
    adjusted = statistics.holm(tested)
    verdicts = []
    for p, holm, effect in zip(p_values, adjusted, effects, strict=True):
        if holm >= level:
            verdict = NO_DIFFERENCE
        else:
            verdict = "better" if effect > no_effect else "worse"
        verdicts.append(Verdict(float(p), float(holm), verdict))
    return verdicts


def mann_whitney_verdicts(
    comparisons: Sequence[tuple[np.ndarray, np.ndarray]], *, level: float = LEVEL
) -> list[Verdict]:
    """The family's verdicts (:func:`holm_verdicts`) on each comparison's (candidate's scores,
    baseline's scores): Mann–Whitney's two-sided p of P(candidate > baseline) = ½
    (:func:`~fppo_jax.stats.statistics.improvement_test`), the direction that probability's
    point estimate over the same scores. Non-finite scores (runs that failed) are left out of
    both, as the test leaves them out; a comparison with no scores on a side is untested."""
    p_values, effects = [], []
    for candidate, baseline in comparisons:
        x, y = _finite(candidate), _finite(baseline)
        p_values.append(statistics.improvement_test(x, y))
        effect = statistics.probability_of_improvement(x, y) if x.size and y.size else np.nan
        effects.append(float(effect))
    return holm_verdicts(p_values, effects, level=level)


def _finite(scores: np.ndarray) -> np.ndarray:
    values = np.asarray(scores, dtype=float).ravel()
    finite: np.ndarray = values[np.isfinite(values)]
    return finite
