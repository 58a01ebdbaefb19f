"""The decision rule of a study that adds seeds (fppo_jax.stats.sequential): its repeated
confidence levels, its statistic against SciPy's, its replay of the looks, Holm's recycling and
its equivalence test."""

import numpy as np
import pytest
from scipy import stats

from fppo_jax.stats import statistics
from fppo_jax.stats.sequential import (
    Design,
    decide,
    improvement_estimate,
    mann_whitney_z,
    repeated_confidence,
)
from fppo_jax.stats.spending import boundaries


def test_a_repeated_confidence_interval_s_level_is_set_by_the_boundary_of_its_look():
    # One look: the fixed design's Bonferroni interval, 1 − α/m.
    assert repeated_confidence(Design(20, 20), 4, 20) == pytest.approx(1 - 0.05 / 4)
    # Five looks at α = 0.05 over one comparison: 2Φ(c_k) − 1 for the published boundaries,
    # wide at the first look (c = 4.88) and near the fixed design's 95% at the last (2.03).
    design = Design(4, 20)
    levels = [repeated_confidence(design, 1, n) for n in design.looks]
    expected = [2 * stats.norm.cdf(c) - 1 for c in (4.8769, 3.3570, 2.6803, 2.2898, 2.0310)]
    np.testing.assert_allclose(levels, expected, atol=1e-5)
    assert levels[-1] > 0.95 and levels == sorted(levels, reverse=True)
    with pytest.raises(ValueError, match="6 seeds is not one of the design's looks"):
        repeated_confidence(design, 1, 6)


def test_the_statistic_is_scipys_mann_whitney_z_and_ranks_a_failed_run_last():
    rng = np.random.default_rng(0)
    x, y = rng.normal(0.5, 1, 9).round(1), rng.normal(0, 1, 7).round(1)  # rounded: ties
    p = stats.mannwhitneyu(x, y, method="asymptotic", use_continuity=False).pvalue
    assert abs(mann_whitney_z(x, y)) == pytest.approx(stats.norm.isf(p / 2))
    assert np.sign(mann_whitney_z(x, y)) == np.sign(
        statistics.probability_of_improvement(x, y) - 0.5
    )
    failed = np.array([-np.inf, -np.inf, 1.0])
    worst = np.array([0.0, 0.5, 2.0])
    assert mann_whitney_z(failed, worst) == pytest.approx(mann_whitney_z([-9, -9, 1.0], worst))
    assert mann_whitney_z([3.0, 3.0], [3.0, 3.0]) == 0.0


def test_a_clear_difference_stops_at_its_first_look_and_a_null_one_runs_to_the_maximum():
    design = Design(group_size=8, max_seeds=16)
    rng = np.random.default_rng(1)
    baseline = rng.normal(0, 1, 16)
    far_below = baseline[:8] - 10  # every run below every baseline run: only 8 seeds recorded
    alike = rng.normal(0, 1, 16)
    worse, undecided = decide([(far_below, baseline), (alike, baseline)], design)
    assert (worse.decision, worse.seeds) == ("worse", 8)
    assert worse.z < -worse.boundary and "at look 1 (8 seeds, level 0.025)" in worse.reason
    assert (undecided.decision, undecided.seeds) == ("undecided", 16)
    assert "reached the maximum of 16 seeds" in undecided.reason
    waiting = decide([(alike[:8], baseline[:8])], design)[0]
    assert (waiting.decision, waiting.seeds) == (None, 8)
    assert "look 2 needs 16 seeds" in waiting.reason
    with pytest.raises(ValueError, match="comparison 0 has a score of NaN"):
        decide([(np.array([np.nan] * 8), baseline)], design)


@pytest.mark.parametrize(
    "group_size, max_seeds, message",
    [
        (1, 10**9, "max_seeds must be at most 100,000, got 1,000,000,000"),
        (1, 201, "max_seeds / group_size gives more than 200 looks: take larger groups"),
    ],
)
def test_a_design_too_large_to_compute_is_refused_at_once(group_size, max_seeds, message):
    with pytest.raises(ValueError, match=message):
        Design(group_size, max_seeds)


def test_a_design_takes_numpy_numbers():
    design = Design(np.int64(5), np.int64(20), np.float32(0.05))
    assert design.looks == (5, 10, 15, 20)


def test_the_looks_are_replayed_so_that_later_seeds_never_change_a_decision():
    design = Design(group_size=5, max_seeds=30, level=0.2)
    rng = np.random.default_rng(2)
    for _ in range(20):
        pairs = [(rng.normal(0.6, 1, 30), rng.normal(0, 1, 30)) for _ in range(3)]
        final = decide(pairs, design)
        for n in design.looks:
            sofar = decide([(c[:n], b[:n]) for c, b in pairs], design)
            for now, end in zip(sofar, final, strict=True):
                if now.decision is not None:  # decided after this look: the end agrees
                    assert (now.decision, now.seeds) == (end.decision, end.seeds)


def test_one_look_is_holms_procedure_on_the_normal_p_values():
    rng = np.random.default_rng(3)
    design = Design(group_size=12, max_seeds=12)
    for _ in range(50):
        pairs = [(rng.normal(shift, 1, 12), rng.normal(0, 1, 12)) for shift in (0.0, 0.8, 1.2)]
        p = [2 * stats.norm.sf(abs(mann_whitney_z(c, b))) for c, b in pairs]
        rejected = statistics.holm(p) < design.level
        decided = [d.decision != "undecided" for d in decide(pairs, design)]
        assert decided == rejected.tolist()


def test_the_improvement_estimate_is_u_over_nm_with_a_placement_error_floored_at_the_null_one():
    rng = np.random.default_rng(4)
    x, y = rng.normal(0.3, 1, 12).round(1), rng.normal(0, 2, 9).round(1)
    theta, error = improvement_estimate(x, y)
    assert theta == pytest.approx(statistics.probability_of_improvement(x, y))
    # DeLong's placements, written out: each run's share of wins over the other setting's.
    v = [np.mean([(a > b) + 0.5 * (a == b) for b in y]) for a in x]
    w = [np.mean([(a > b) + 0.5 * (a == b) for a in x]) for b in y]
    placement = np.var(v, ddof=1) / 12 + np.var(w, ddof=1) / 9
    null = (12 + 9 + 1) / (12 * 12 * 9)
    assert placement > null and error == pytest.approx(np.sqrt(placement))
    # Every score tied (every run failed): P = 1/2, its error the null one, not 0.
    failed = np.full(6, -np.inf)
    assert improvement_estimate(failed, failed) == pytest.approx((0.5, np.sqrt(13 / 432)))


def test_identical_arms_are_decided_equivalent_and_without_a_margin_undecided():
    rng = np.random.default_rng(5)
    baseline = rng.normal(0, 1, 40)
    design = Design(group_size=10, max_seeds=40, margin=0.2)
    (same,) = decide([(baseline.copy(), baseline)], design)
    assert (same.decision, same.seeds) == ("equivalent", 30)
    low, high = same.interval
    assert 0.3 <= low < 0.5 < high <= 0.7 and same.z >= same.boundary
    assert f"repeated CI [{low:.2f}, {high:.2f}]" in same.reason
    assert "within 1/2 ± 0.2 at look 3 (30 seeds, level 0.05 a side)" in same.reason
    # Its interval is θ̂ ± c'·se at the look's one-sided boundary.
    theta, error = improvement_estimate(baseline[:30], baseline[:30])
    critical = boundaries(0.05, (0.25, 0.5, 0.75, 1.0), sides=1)[2]
    np.testing.assert_allclose(same.interval, (theta - critical * error, theta + critical * error))
    # Today's rule without a margin: the same scores are undecided at the maximum.
    (plain,) = decide([(baseline.copy(), baseline)], Design(group_size=10, max_seeds=40))
    assert (plain.decision, plain.seeds, plain.interval) == ("undecided", 40, None)
    assert "P's repeated CI" not in plain.reason
    # A clear difference is still decided by its direction, and a null one whose interval
    # crosses the margin stays undecided, saying where its interval ended.
    far, other = decide([(baseline + 3, baseline), (baseline[::-1] + 0.3, baseline)], design)
    assert far.decision == "better"
    assert other.decision == "undecided" and "is not within 1/2 ± 0.2" in other.reason
    assert other.interval[1] > 0.7


def test_an_equivalent_comparison_passes_its_share_only_to_the_equivalence_tests():
    rng = np.random.default_rng(6)
    baseline = rng.normal(0, 1, 40)
    design = Design(group_size=10, max_seeds=40, margin=0.2)
    # Holm within the equivalence tests: the first decided at α/2 passes its share on, and the
    # second is tested again at α at the same look.
    first, second = decide([(baseline.copy(), baseline), (baseline[::-1] + 0.25, baseline)], design)
    assert first.decision == second.decision == "equivalent"
    assert "at look 3 (30 seeds, level 0.025 a side)" in first.reason
    assert "at look 3 (30 seeds, level 0.05 a side)" in second.reason
    # Not to better or worse: alone, this comparison is decided worse at look 2 (level α);
    # beside one decided equivalent its level for better or worse stays α/2, which it never
    # crosses, and it is decided equivalent at α instead, at the last look.
    wide = Design(group_size=10, max_seeds=40, margin=0.25)
    lower = baseline[::-1] - 0.4
    (alone,) = decide([(lower, baseline)], wide)
    assert alone.decision == "worse" and "at look 2 (20 seeds, level 0.05)" in alone.reason
    _, beside = decide([(baseline.copy(), baseline), (lower, baseline)], wide)
    assert (
        beside.decision == "equivalent" and "look 4 (40 seeds, level 0.05 a side)" in beside.reason
    )
    halved = boundaries(0.025, (0.25, 0.5, 0.75, 1.0))
    assert all(
        abs(mann_whitney_z(lower[:n], baseline[:n])) < halved[k] for k, n in enumerate(wide.looks)
    )


@pytest.mark.parametrize(
    "margin, level, message",
    [
        (0.5, 0.05, "margin \\(a distance from 1/2 .*\\) must be in \\(0, 0.5\\), got 0.5"),
        (0.0, 0.05, "in \\(0, 0.5\\), got 0.0"),
        (True, 0.05, "got True"),
        (0.2, 0.5, "an equivalence margin needs an error level below 0.5"),
    ],
)
def test_a_margin_outside_its_range_is_refused(margin, level, message):
    with pytest.raises(ValueError, match=message):
        Design(5, 30, level, margin)
