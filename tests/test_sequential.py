"""The decision rule of a study that adds seeds (fppo_jax.sequential): its boundaries against
published ones, its statistic against SciPy's, its replay of the looks, Holm's recycling, and
its error rates by simulation on synthetic scores (no training)."""

import tempfile
from pathlib import Path

import numpy as np
import pytest
from helpers import run_script
from scipy import stats

from fppo_jax import statistics
from fppo_jax.sequential import (
    Design,
    boundaries,
    decide,
    mann_whitney_z,
    repeated_confidence,
    simulate,
)


def test_boundaries_are_the_published_obrien_fleming_type_ones():
    # Lan–DeMets O'Brien–Fleming-type spending, five equally spaced looks, two-sided 0.05
    # (Jennison and Turnbull 2000, Table 7.5; gsDesign's sfLDOF at 0.025 a side).
    five = boundaries(0.05, (0.2, 0.4, 0.6, 0.8, 1.0))
    np.testing.assert_allclose(five, [4.8769, 3.3570, 2.6803, 2.2898, 2.0310], atol=2e-4)
    np.testing.assert_allclose(boundaries(0.05, (0.5, 1.0)), [2.9626, 1.9686], atol=2e-4)
    assert boundaries(0.05, (1.0,)) == pytest.approx((stats.norm.isf(0.025),), abs=1e-6)
    with pytest.raises(ValueError, match="must increase from above 0"):
        boundaries(0.05, (0.5, 0.5))


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


def test_the_family_wise_error_is_at_most_alpha_and_a_real_difference_takes_fewer_seeds():
    design = Design(group_size=5, max_seeds=30, level=0.05)
    family = [2, 2]  # two tasks, two candidates each against the task's baseline
    studies = 2000
    null = simulate(design, family, shift=0.0, studies=studies, seed=0)
    standard_error = np.sqrt(design.level * (1 - design.level) / studies)
    assert null["false_decision_rate"] <= design.level + 3 * standard_error

    shifted = simulate(design, family, shift=1.0, studies=1000, seed=1)
    assert shifted["false_decision_rate"] == 0 and shifted["power"] > 0.9
    # The fixed design (one look, Holm across the same family) that matches this power needs
    # more seeds than the sequential one used on average.
    needed = next(
        n
        for n in range(10, 61, 2)
        if simulate(Design(n, n), family, shift=1.0, studies=1000, seed=1)["power"]
        >= shifted["power"]
    )
    assert shifted["seeds"] < needed - 3


def test_the_experiments_smoke_run_writes_its_table_into_a_temporary_directory(
    tmp_path, monkeypatch
):
    experiments = Path(__file__).resolve().parent.parent / "experiments"
    script = experiments / "studies" / "sequential_rule.py"
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))  # where its temporary directory goes
    done = run_script(script, "--smoke", cwd=experiments)
    assert done.returncode == 0, done.stdout + done.stderr
    written = Path(done.stdout.split("wrote ")[-1].strip())
    assert written.parent.parent == tmp_path
    assert written.parent.name.startswith("fppo-sequential-rule-smoke-")
    table = written.read_text()
    assert "- 200 simulated studies per row" in table
    assert "| 2 tasks × 2 candidates | 1 | 0.000 | 0.9" in table
    results = str(experiments / "results")
    refused = run_script(script, "--smoke", "--results", results, cwd=experiments)
    assert refused.returncode != 0 and "never writes into the recorded results" in refused.stderr
