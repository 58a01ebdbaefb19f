"""The report kit: an interval's cell, what an IQM difference's interval rules out, and the
fixed-design verdict of a family (Mann–Whitney, Holm, better / worse at the level)."""

import numpy as np
import pytest

from fppo_jax.analysis import report_kit
from fppo_jax.analysis.report_kit import (
    LEVEL,
    NO_DIFFERENCE,
    Verdict,
    holm_verdicts,
    interval_cell,
    mann_whitney_verdicts,
    ruled_out,
)
from fppo_jax.errors import InvalidInput
from fppo_jax.stats import statistics


def test_an_interval_cell_is_the_point_then_its_bounds_in_the_form_given():
    assert interval_cell((0.612, 0.5249, 0.7), ".2f") == "0.61 [0.52, 0.70]"
    assert interval_cell((-1234.56, -2000.0, 3.04), ".1f") == "-1234.6 [-2000.0, 3.0]"
    assert interval_cell((float("nan"), float("nan"), float("nan")), ".2f") == "–"


def test_what_an_interval_rules_out_is_a_share_of_the_baseline_s_iqm():
    assert ruled_out((5.0, -30.0, 12.0), 100.0) == (
        "a gain above 12% and a loss above 30% of the baseline's IQM"
    )
    # A negative baseline IQM scales by its size; an interval on one side rules out all of
    # the other.
    assert ruled_out((-20.0, -40.0, -10.0), -200.0) == (
        "any gain and a loss above 20% of the baseline's IQM"
    )
    assert (
        ruled_out((20.0, 10.0, 40.0), 200.0)
        == "a gain above 20% and any loss of the baseline's IQM"
    )
    # No scale to share of: the scores' own units.
    assert ruled_out((1.0, -2.5, 3.25), 0.0) == "a gain above 3.2 and a loss above 2.5"
    assert ruled_out((1.0, float("nan"), float("nan")), 100.0) == "–"


def _family(shifts: list[float], runs: int = 30) -> list[tuple[np.ndarray, np.ndarray]]:
    """A seeded family: each candidate's scores shifted from its baseline's by a shift."""
    rng = np.random.default_rng(7)
    return [(rng.normal(shift, 1.0, runs), rng.normal(0.0, 1.0, runs)) for shift in shifts]


def test_the_family_is_tested_by_mann_whitney_and_decided_by_holm_at_its_level():
    family = _family([2.0, -2.0, 0.0, -0.1])
    verdicts = mann_whitney_verdicts(family)
    raw = [statistics.improvement_test(x, y) for x, y in family]
    assert [v.p for v in verdicts] == pytest.approx(raw)
    assert [v.holm for v in verdicts] == pytest.approx(statistics.holm(raw))
    assert all(v.holm >= v.p for v in verdicts)
    assert [v.verdict for v in verdicts] == ["better", "worse", NO_DIFFERENCE, NO_DIFFERENCE]
    # Holm's adjustment, not each p alone, decides: the last p is below 0.05, and the
    # family's size lifts it above.
    assert verdicts[3].p < LEVEL <= verdicts[3].holm


def test_the_level_is_the_family_s_and_a_stricter_one_decides_less():
    family = _family([0.6, 2.0])
    at_default = mann_whitney_verdicts(family)
    assert report_kit.LEVEL == 0.05 and at_default[1].verdict == "better"
    strict = mann_whitney_verdicts(family, level=at_default[0].holm)
    assert strict[0].verdict == NO_DIFFERENCE  # the adjusted p must be below the level
    assert mann_whitney_verdicts(family, level=1.0)[0].verdict == "better"


def test_failed_runs_are_left_out_of_the_test_and_of_its_direction():
    candidate, baseline = _family([2.0])[0]
    failed = np.concatenate([candidate, [-np.inf, np.nan]])
    assert mann_whitney_verdicts([(failed, baseline)]) == mann_whitney_verdicts(
        [(candidate, baseline)]
    )


def test_a_comparison_not_recorded_yet_enters_holm_as_p_1():
    family = _family([2.0, 2.0])
    verdicts = mann_whitney_verdicts([*family, (np.array([]), np.array([1.0]))])
    assert np.isnan(verdicts[2].p) and verdicts[2].holm == 1.0
    assert verdicts[2].verdict == NO_DIFFERENCE
    # It counts in the family: the others' adjustment is over three comparisons.
    assert [v.holm for v in verdicts[:2]] == pytest.approx(
        statistics.holm([verdicts[0].p, verdicts[1].p, 1.0])[:2]
    )


def test_any_test_s_p_values_decide_by_the_side_of_their_effect():
    # A trend's test: the effect a correlation, no effect at 0.
    verdicts = holm_verdicts([0.001, 0.004, 0.3], [0.4, -0.2, 0.5], no_effect=0.0)
    assert verdicts == [
        Verdict(0.001, pytest.approx(0.003), "better"),
        Verdict(0.004, pytest.approx(0.008), "worse"),
        Verdict(0.3, pytest.approx(0.3), NO_DIFFERENCE),
    ]
    with pytest.raises(InvalidInput, match="2 p-values for 1 effects"):
        holm_verdicts([0.1, 0.2], [0.5])
