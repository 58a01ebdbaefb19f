"""The statistics against cases with known answers and against direct implementations."""

import itertools

import numpy as np
import pytest
from scipy import stats

from fppo_jax.stats import statistics


def test_endpoints_of_a_curve_with_updates_before_any_episode():
    curves = np.array([[np.nan, 1.0, 3.0, 2.0], [np.nan, np.nan, np.nan, np.nan], [4, 0, 0, 0]])
    final = statistics.endpoint(curves, "final")
    np.testing.assert_array_equal(final[[0, 2]], [2.0, 0.0])
    assert np.isnan(final[1])
    best = statistics.endpoint(curves, "max")
    np.testing.assert_array_equal(best[[0, 2]], [3.0, 4.0])
    area = statistics.endpoint(curves, "auc")
    np.testing.assert_allclose(area[[0, 2]], [2.0, 1.0])
    assert np.isnan(best[1]) and np.isnan(area[1])
    with pytest.raises(ValueError, match="unknown endpoint 'best'"):
        statistics.endpoint(curves, "best")
    with pytest.raises(ValueError, match=r"\[run, update\]"):
        statistics.endpoint(curves[0], "final")


def test_steps_to_threshold_is_the_first_update_that_reaches_it():
    curves = np.array([[np.nan, 1.0, 3.0, 2.0], [np.nan, np.nan, np.nan, np.nan], [4, 0, 0, 0]])
    steps = np.array([100, 200, 300, 400])
    reached = statistics.steps_to_threshold(curves, steps, 3.0)
    np.testing.assert_array_equal(reached, [300, np.inf, 100])
    per_run = np.array([[1, 2, 3, 4], [10, 20, 30, 40], [5, 6, 7, 8]])
    np.testing.assert_array_equal(
        statistics.steps_to_threshold(curves, per_run, 1.0), [2, np.inf, 5]
    )


def test_the_iqm_is_the_mean_of_the_middle_half():
    assert statistics.iqm(np.arange(1.0, 9.0)) == pytest.approx(4.5)  # mean of 3, 4, 5, 6
    x = np.random.default_rng(0).normal(size=40)
    middle = np.sort(x)[10:30]
    assert statistics.iqm(x) == pytest.approx(middle.mean())


def test_the_std_is_the_sample_std():
    x = np.array([1.0, 2.0, 4.0, np.nan])
    assert statistics.sample_std(x) == pytest.approx(np.std([1, 2, 4], ddof=1))
    assert np.isnan(statistics.sample_std(np.array([3.0])))


def test_the_probability_of_improvement_counts_pairs_and_half_ties():
    x, y = np.array([2.0, 3.0]), np.array([1.0, 2.0])
    # (2>1) + ½(2=2) + (3>1) + (3>2) over 4 pairs
    assert statistics.probability_of_improvement(x, y) == pytest.approx(3.5 / 4)
    rng = np.random.default_rng(1)
    a, b = rng.integers(0, 5, 17).astype(float), rng.integers(0, 5, 11).astype(float)
    u = stats.mannwhitneyu(a, b).statistic
    assert statistics.probability_of_improvement(a, b) == pytest.approx(u / (17 * 11))
    assert statistics.probability_of_improvement(b, a) == pytest.approx(1 - u / (17 * 11))


def test_the_improvement_test_is_the_mann_whitney_test_of_one_half():
    # Five runs each, every x above every y: 2 of the C(10, 5) = 252 labellings are as extreme.
    x, y = np.arange(5.0, 10.0), np.arange(5.0)
    assert statistics.improvement_test(x, y) == pytest.approx(2 / 252)
    assert statistics.improvement_test(y, x) == pytest.approx(2 / 252)
    # Against a direct permutation test of |U - nm/2| on tied, overlapping scores.
    rng = np.random.default_rng(4)
    a, b = rng.integers(0, 9, 23).astype(float), rng.integers(2, 11, 19).astype(float)
    pooled = np.concatenate([a, b])

    def distance(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return np.abs(statistics.probability_of_improvement(x, y) - 0.5)

    shuffled = np.array([rng.permutation(pooled) for _ in range(20_000)])
    null = distance(shuffled[:, :23], shuffled[:, 23:])
    direct = np.mean(null >= distance(a, b) - 1e-12)
    assert statistics.improvement_test(a, b) == pytest.approx(direct, abs=0.01)
    assert statistics.improvement_test(np.ones(4), np.ones(3)) == 1.0
    assert np.isnan(statistics.improvement_test(np.array([np.nan]), y))


def test_holm_adjusts_a_family_step_down():
    adjusted = statistics.holm([0.01, 0.04, 0.03, 0.005])
    # Sorted 0.005, 0.01, 0.03, 0.04 times 4, 3, 2, 1, then made non-decreasing.
    np.testing.assert_allclose(adjusted, [0.03, 0.06, 0.06, 0.02])
    np.testing.assert_allclose(statistics.holm([0.5, 0.9]), [1.0, 1.0])
    np.testing.assert_allclose(statistics.holm([0.2]), [0.2])
    # A comparison not made yet, entered as 1, can only raise the others' adjusted p.
    assert statistics.holm([0.01, 0.02, 1.0])[0] == pytest.approx(0.03)
    for bad in ([0.1, np.nan], [1.5], [[0.1]]):
        with pytest.raises(ValueError, match="finite p-values in"):
            statistics.holm(bad)


def test_an_interval_matches_a_direct_percentile_bootstrap():
    x = np.random.default_rng(2).normal(10.0, 3.0, size=20)
    point, low, high = statistics.interval(x, "iqm", resamples=20_000)
    rng = np.random.default_rng(3)
    draws = stats.trim_mean(rng.choice(x, (20_000, x.size)), 0.25, axis=1)
    direct = np.percentile(draws, [2.5, 97.5])
    assert point == pytest.approx(stats.trim_mean(x, 0.25))
    assert low == pytest.approx(direct[0], abs=0.1)
    assert high == pytest.approx(direct[1], abs=0.1)
    assert low < point < high


def test_intervals_are_seeded_and_cover_as_stated():
    rng = np.random.default_rng(4)
    x = rng.normal(size=15)
    assert statistics.interval(x, "mean", seed=7) == statistics.interval(x, "mean", seed=7)
    assert statistics.interval(x, "mean", seed=7) != statistics.interval(x, "mean", seed=8)
    covered = 0
    for _ in range(200):
        _, low, high = statistics.interval(rng.normal(size=30), "mean", resamples=1000)
        covered += low <= 0.0 <= high
    assert 0.88 <= covered / 200 <= 0.99  # a percentile bootstrap's 95%, a little under


def test_constant_and_empty_scores():
    assert statistics.interval(np.full(5, 200.0), "iqm") == (200.0, 200.0, 200.0)
    assert all(np.isnan(statistics.interval(np.array([np.nan]), "iqm")))
    with pytest.raises(ValueError, match="unknown statistic 'mode'"):
        statistics.interval(np.ones(3), "mode")
    with pytest.raises(ValueError, match=r"confidence level must be in \(0, 1\)"):
        statistics.interval(np.arange(3.0), "mean", confidence=95)


def test_a_comparison_of_well_separated_settings_is_sure():
    x, y = np.arange(10.0) + 100, np.arange(10.0)
    result = statistics.compare(x, y)
    assert result["probability_of_improvement"] == (1.0, 1.0, 1.0)
    point, low, high = result["iqm_difference"]
    assert point == pytest.approx(100.0) and low < 100 < high
    same = statistics.compare(y, y)["probability_of_improvement"]
    assert same[0] == 0.5 and same[1] < 0.5 < same[2]


def test_an_aggregate_over_one_task_is_that_task_s_interval():
    x = np.random.default_rng(5).normal(size=12)
    assert statistics.aggregate([x], "iqm", seed=3) == statistics.interval(x, "iqm", seed=3)
    y = x[::-1] + 0.5
    one = statistics.aggregate_improvement([(x, y)], seed=3)
    assert one == statistics.compare(x, y, seed=3)["probability_of_improvement"]


def test_a_stratified_aggregate_pools_tasks_without_mixing_them():
    rng = np.random.default_rng(6)
    tasks = [rng.normal(0.0, 0.1, 8), rng.normal(1.0, 0.1, 8)]
    point, low, high = statistics.aggregate(tasks, "mean")
    assert point == pytest.approx(np.concatenate(tasks).mean())
    # Each resample keeps 8 runs of each task, so the pooled mean stays near 0.5; a bootstrap
    # that mixed the tasks' runs would swing far wider.
    assert high - low < 0.2  # about 0.1 stratified, about 0.5 mixed
    pairs = [(t + 0.01, t) for t in tasks]
    assert statistics.aggregate_improvement(pairs)[0] == pytest.approx(
        np.mean([statistics.probability_of_improvement(a, b) for a, b in pairs])
    )


def test_optimality_gap_normalisation_and_profiles():
    assert statistics.optimality_gap(np.array([0.5, 1.5])) == pytest.approx(0.25)
    np.testing.assert_allclose(statistics.normalise(np.array([0.0, 5.0, 10.0]), 0, 10), [0, 0.5, 1])
    with pytest.raises(ValueError, match="two different finite scores"):
        statistics.normalise(np.ones(2), 1.0, 1.0)
    profile = statistics.performance_profile(np.array([0.1, 0.5, 0.9, 1.2]), [0.0, 0.5, 1.0])
    np.testing.assert_allclose(profile, [1.0, 0.5, 0.25])


def test_a_curve_band_is_the_interval_at_every_update_from_one_draw_of_runs():
    rng = np.random.default_rng(7)
    curves = rng.normal(size=(12, 6))
    curves[:4, 0] = np.nan  # four runs had finished no episode at the first update
    point, low, high = statistics.curve_interval(curves, "iqm", seed=1)
    np.testing.assert_allclose(point[1:], [stats.trim_mean(c, 0.25) for c in curves[:, 1:].T])
    assert point[0] == pytest.approx(stats.trim_mean(curves[4:, 0], 0.25))
    assert np.all(low <= point) and np.all(point <= high) and np.all(low < high)
    same = statistics.curve_interval(curves, "iqm", seed=1)
    for a, b in zip(same, (point, low, high), strict=True):
        np.testing.assert_array_equal(a, b)
    identical = np.tile(curves[:, 1:2], (1, 3))  # the same column thrice: the same band
    _, low3, high3 = statistics.curve_interval(identical, "mean")
    assert np.ptp(low3) == 0 and np.ptp(high3) == 0


def test_the_iqm_leaves_nans_out():
    x = np.array([np.nan, 1.0, 2.0, 3.0, 4.0, 100.0, np.nan])
    assert statistics.iqm(x) == pytest.approx(stats.trim_mean(x[1:6], 0.25))
    assert np.isnan(statistics.iqm(np.full(3, np.nan)))


def test_the_paper_statistic_s_difference_and_its_interval():
    rng = np.random.default_rng(8)
    x = rng.normal(size=(10, 5)) + np.arange(5)  # best at the last update, about 4
    y = rng.normal(size=(12, 5))
    point, low, high = statistics.max_average_difference(x, y, seed=2)
    assert point == pytest.approx(x.mean(0).max() - y.mean(0).max())
    assert low < point < high
    assert statistics.max_average_difference(x, y, seed=2) == (point, low, high)
    assert statistics.max_average_difference(x, x[::-1])[0] == 0.0


def test_the_eval_endpoint_is_each_run_s_last_evaluation():
    nan = np.nan
    curves = np.array([[nan, 3.0, nan, 5.0], [nan, 2.0, nan, nan], [nan, nan, nan, nan]])
    np.testing.assert_array_equal(statistics.endpoint(curves, "eval"), [5.0, 2.0, nan])


def test_spearman_is_scipy_s_rank_correlation_with_ties_and_along_an_axis():
    rng = np.random.default_rng(11)
    doses = np.repeat([1.0, 1.1, 1.3, 2.0], 5)  # tied doses, as every dose has several runs
    scores = rng.normal(size=(3, 20)).round(1)  # and some tied scores
    for row in scores:
        expected = stats.spearmanr(doses, row).statistic
        assert statistics.spearman(doses, row) == pytest.approx(expected, abs=1e-12)
    np.testing.assert_allclose(
        statistics.spearman(doses, scores.T, axis=0), statistics.spearman(doses, scores)
    )
    assert np.isnan(statistics.spearman(doses, np.ones(20)))


def test_a_dose_trend_and_its_permutation_test():
    rng = np.random.default_rng(12)
    doses = [1.0, 1.5, 2.0, 3.0]
    rising = [rng.normal(dose, 0.3, 10) for dose in doses]
    flat = [rng.normal(0.0, 1.0, 10) for _ in doses]

    rho, low, high = statistics.dose_trend(doses, rising)
    assert rho == pytest.approx(stats.spearmanr(np.repeat(doses, 10), np.concatenate(rising))[0])
    assert 0 < low < rho < high <= 1
    assert statistics.trend_test(doses, rising) == 1 / 10_001  # no relabelling is as extreme
    falling = statistics.dose_trend(doses[::-1], rising)
    assert falling[0] == pytest.approx(-rho)

    p_flat = statistics.trend_test(doses, flat)
    assert p_flat > 0.05 and statistics.dose_trend(doses, flat)[1] < 0
    assert statistics.trend_test(doses, flat) == p_flat  # seeded
    # Near the exact p: every one of the 8! relabellings of 8 runs counted.
    scores = rng.normal(size=8) + np.arange(8) * 0.2
    every = np.array(list(itertools.permutations(scores)))
    observed = abs(statistics.spearman(np.arange(8), scores))
    exact = np.mean(np.abs(statistics.spearman(np.arange(8), every)) >= observed - 1e-12)
    permuted = statistics.trend_test(list(range(8)), [np.array([s]) for s in scores])
    assert 0.01 < exact < 0.99 and permuted == pytest.approx(exact, abs=0.015)


def test_a_dose_trend_leaves_nans_out_and_refuses_a_single_dose():
    doses = [0.0, 1.0]
    groups = [np.array([1.0, 2.0, np.nan]), np.array([3.0, 4.0])]
    assert statistics.dose_trend(doses, groups)[0] == pytest.approx(
        stats.spearmanr([0, 0, 1, 1], [1, 2, 3, 4])[0]
    )
    assert statistics.trend_test(doses, [np.ones(3), np.ones(2)]) == 1.0
    with pytest.raises(statistics.InvalidInput, match="two doses or more"):
        statistics.dose_trend([1.0, 1.0], groups)


def test_no_resample_or_permutation_is_refused_not_answered():
    x, curves = np.arange(8.0), np.ones((4, 3))
    calls = {
        "resamples": [
            lambda n: statistics.interval(x, "iqm", resamples=n),
            lambda n: statistics.curve_interval(curves, resamples=n),
            lambda n: statistics.max_average_difference(curves, curves, resamples=n),
        ],
        "permutations": [
            lambda n: statistics.trend_test([1.0, 2.0], [x, x + 1], permutations=n),
        ],
    }
    for name, functions in calls.items():
        for call in functions:
            for bad in (0, -1, 2.5, True):
                with pytest.raises(ValueError, match=f"{name} must be a positive integer"):
                    call(bad)
    statistics.trend_test([1.0, 2.0], [x, x + 1], permutations=np.int64(10))  # numpy counts
