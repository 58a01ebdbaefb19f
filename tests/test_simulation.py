"""The sequential rule's error rates by simulation on synthetic scores, no training
(fppo_jax.stats.simulation), and the experiments that tabulate them."""

import tempfile
from pathlib import Path

import numpy as np
import pytest
from helpers import run_script

from fppo_jax.stats.sequential import Design
from fppo_jax.stats.simulation import shift_for, simulate


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


def test_a_false_equivalent_at_the_margin_is_at_most_the_level():
    # P(candidate > baseline) exactly at 1/2 ± δ: any `equivalent` is false. Seeded.
    design = Design(group_size=10, max_seeds=50, level=0.05, margin=0.2)
    studies = 2000
    bound = design.level + 3 * np.sqrt(design.level * (1 - design.level) / studies)
    for shift, seed in ((shift_for(0.7), 1), (shift_for(0.3), 2)):
        found = simulate(design, [1], shift=shift, studies=studies, seed=seed)
        assert found["false_equivalence_rate"] <= bound
        assert found["false_equivalence_rate"] > design.level / 2  # near the level: a real test
    family = simulate(design, [2, 2], shift=shift_for(0.7), studies=1000, seed=3)
    assert family["false_equivalence_rate"] <= design.level + 3 * np.sqrt(0.05 * 0.95 / 1000)


def test_identical_settings_are_decided_equivalent_within_fifty_seeds_nine_times_in_ten():
    # m = 0.2, level 0.05, groups of 10 seeds up to 50 per setting, one comparison: with no
    # difference the study decides `equivalent` in 91% of 2,000 studies, with 40 seeds per
    # setting on average; better or worse stays at most the level.
    design = Design(group_size=10, max_seeds=50, level=0.05, margin=0.2)
    found = simulate(design, [1], shift=0.0, studies=2000, seed=3)
    assert found["equivalent"] == pytest.approx(0.9085, abs=1e-9)
    assert found["seeds"] == pytest.approx(40.0, abs=0.05)
    assert found["false_decision_rate"] <= 0.05 + 3 * np.sqrt(0.05 * 0.95 / 2000)
    assert found["false_equivalence_rate"] == 0  # P = 1/2 is within the margin


def test_the_equivalence_experiment_s_smoke_run_writes_its_table_into_a_temporary_directory(
    tmp_path, monkeypatch
):
    experiments = Path(__file__).resolve().parent.parent / "experiments"
    script = experiments / "studies" / "equivalence_rule.py"
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    done = run_script(script, "--smoke", cwd=experiments)
    assert done.returncode == 0, done.stdout + done.stderr
    written = Path(done.stdout.split("wrote ")[-1].strip())
    assert written.parent.name.startswith("fppo-equivalence-rule-smoke-")
    table = written.read_text()
    assert "- 200 simulated studies per row" in table
    rows = [line.split(" | ") for line in table.splitlines() if line.startswith("| 5 to 30")]
    # Equivalence reachable from 25 seeds for one comparison, from 30 at Holm's α/4 for four.
    assert [row[-1] for row in rows] == ["25 |"] * 3 + ["30 |"] * 3
