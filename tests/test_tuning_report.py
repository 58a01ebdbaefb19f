"""The tune's results and report, from rung scores made by hand."""

import json

import numpy as np
import pytest

from fppo_jax.analysis.halving import Rungs, SuccessiveHalving
from fppo_jax.analysis.tuning_report import arm_results, expected_best, write_report


def row(trial, score, diverged=False):
    return {"trial": trial, "score": score, "seed_scores": [score], "diverged": diverged}


RUNGS = Rungs(trials=(4, 2, 1), ends=(2, 4, 8))
ARMS = [
    {
        "ppo": {
            "trials": [row(0, 10.0), row(1, 12.0), row(2, 8.0), row(3, 11.0)],
            "survivors": [1, 3],
        },
        "spo": {
            "trials": [row(0, 9.0), row(1, None, True), row(2, 15.0), row(3, 10.5)],
            "survivors": [2, 3],
        },
    },
    {
        "ppo": {"trials": [row(1, 20.0), row(3, 21.0)], "survivors": [3]},
        "spo": {"trials": [row(2, 25.0), row(3, 19.0)], "survivors": [2]},
    },
    {
        "ppo": {"trials": [row(3, 30.0)], "survivors": [3]},
        "spo": {"trials": [row(2, 35.0)], "survivors": [2]},
    },
]
SCORES = [{"arms": arms} for arms in ARMS]


def windows(scores):
    """What each rung of `scores` trained: its arms' trials × 2 seeds over the rung's updates."""
    arms = list(scores[0]["arms"])
    halving = SuccessiveHalving(arms, 4, [1000000, 1000001], RUNGS)
    return [halving.next_window(scores[:rung]) for rung in range(len(scores))]


SETTINGS = {
    arm: [{"learning_rate": lr} for lr in (1e-4, 2e-4, 3e-4, 4e-4)] for arm in ("ppo", "spo")
}


PLAN = {
    "variants": ["ppo", "spo"],
    "tasks": ["cartpole"],
    "trials": 4,
    "seeds": [1000000, 1000001],
    "eta": 2,
    "baseline": "ppo",
    "score": "s",
    "selection": "best",
    "commit": "abc",
    "budget": {
        "cartpole": {
            "env_steps_per_arm": 3200,
            "rungs": [
                {"trials": 4, "env_steps_per_run": 200},
                {"trials": 2, "env_steps_per_run": 400},
                {"trials": 1, "env_steps_per_run": 800},
            ],
        }
    },
    "space": {
        "ppo": {"learning_rate": {"low": 1e-5, "high": 1e-3, "scale": "log"}},
        "spo": {"learning_rate": {"low": 1e-5, "high": 1e-3, "scale": "log"}},
    },
    "sampler": {"name": "qmc", "seed": 0, "package": "optuna 5.0.0"},
}


def test_an_arms_results_say_what_the_rungs_measured():
    found = arm_results("spo", "ppo", SCORES, SETTINGS, windows(SCORES), 100)
    assert found["chosen"] == {"trial": 2, "score": 35.0, "setting": {"learning_rate": 3e-4}}
    assert found["default"]["first_rung_score"] == 9.0
    assert found["default"]["last_rung_reached"] == 0
    # Above PPO's default (10.0): trials 2 and 3 of the three sampled; trial 1 diverged.
    assert found["beat_baseline_default"] == {
        "baseline": "ppo",
        "baseline_default_score": 10.0,
        "sampled": 3,
        "beat": 2,
    }
    assert found["diverged_trials"] == [1]
    steps = [(4 * 2 * 2) * 100, (4 * 2 * 2 + 2 * 2 * 2) * 100, (16 + 8 + 1 * 2 * 4) * 100]
    assert [point["env_steps"] for point in found["curve"]] == steps
    assert [point["best"] for point in found["curve"]] == [15.0, 25.0, 35.0]
    assert found["first_rung_spread"]["median"] == 10.5
    assert found["first_rung_spread"]["sample_std"] == pytest.approx(np.std([9, 15, 10.5], ddof=1))
    # The band's curve: 1 … 4 settings drawn from the 3 scored trials, costing a quarter of the
    # first rung each, so that its last point meets the rung's point on the tuning curve.
    band = found["expected_best"]
    assert band["scored_trials"] == 3
    assert [p["settings"] for p in band["points"]] == [1, 2, 3, 4]
    assert [p["env_steps"] for p in band["points"]] == [400, 800, 1200, 1600]
    assert band["points"][0]["expected_best"] == pytest.approx(11.5)  # the mean


def test_the_expected_best_of_n_settings_is_dodge_et_als_estimator():
    # Two settings drawn from {0, 1}: their best is 1 unless both are 0, with probability 1/4.
    point, _, _ = expected_best(np.array([1.0, 0.0]), 3)
    assert point == pytest.approx([0.5, 0.75, 0.875])
    scores = np.array([3.0, 1.0, 4.0, 1.0, 5.0, 9.0, 2.0, 6.0, 5.0])
    point, low, high = expected_best(scores, 9)
    assert point[0] == pytest.approx(scores.mean())
    assert np.all(np.diff(point) > 0) and point[-1] < scores.max()
    assert np.all(low <= point) and np.all(point <= high)
    assert np.all(high <= scores.max())  # a bootstrap never reaches above the best seen


def test_the_band_repeats_with_its_seed_and_narrows_with_more_trials():
    scores = np.array([3.0, 1.0, 4.0, 1.0, 5.0, 9.0, 2.0, 6.0, 5.0])
    first, again = expected_best(scores, 9, seed=3), expected_best(scores, 9, seed=3)
    assert all(np.array_equal(a, b) for a, b in zip(first, again, strict=True))
    assert not np.array_equal(first[1], expected_best(scores, 9, seed=4)[1])
    # The same spread of scores from 9 and from 90 trials: at every n the band of 90 is narrower.
    # (Not a law at large n: 9 trials from a long tail hold their band under the best seen.)
    _, low_9, high_9 = expected_best(np.linspace(0, 1, 9), 9, resamples=500)
    _, low_90, high_90 = expected_best(np.linspace(0, 1, 90), 9, resamples=500)
    assert np.all(high_90 - low_90 < high_9 - low_9)


def test_one_trial_gives_a_band_of_zero_width():
    point, low, high = expected_best(np.array([7.0]), 5)
    assert np.array_equal(point, np.full(5, 7.0))
    assert np.array_equal(low, point) and np.array_equal(high, point)


def test_a_rung_that_scored_every_trial_alike_is_reported_as_tied(tmp_path):
    flat = [
        {"arms": {"ppo": {"trials": [row(t, -200.0) for t in range(4)], "survivors": [0, 1]}}},
        {"arms": {"ppo": {"trials": [row(0, -150.0), row(1, -120.0)], "survivors": [1]}}},
        {"arms": {"ppo": {"trials": [row(1, -110.0)], "survivors": [1]}}},
    ]
    found = arm_results("ppo", "ppo", flat, SETTINGS, windows(flat), 100)
    assert found["tied_rungs"] == [0]
    assert arm_results("spo", "ppo", SCORES, SETTINGS, windows(SCORES), 100)["tied_rungs"] == []


def test_the_report_gives_each_arm_its_row_its_sensitivity_its_band_and_the_checklist(tmp_path):
    results = {
        "cartpole": {
            arm: arm_results(arm, "ppo", SCORES, SETTINGS, windows(SCORES), 100)
            for arm in ("ppo", "spo")
        }
    }
    write_report(tmp_path, PLAN, results)
    report = (tmp_path / "report.md").read_text()
    assert "| spo | 9.0 | 15.0 | 2 | 35.0 | 2 of 3 | 1 | 3,200 |" in report
    assert "| ppo | 10.0 | 12.0 |" in report
    # Sensitivity (quartiles, sample std, range) and the expected best of 4 settings, whose
    # band from 3 scored trials is [9, 15]: wider than the 2.6 the curve rose from 1 setting.
    assert "| arm | scored trials | quartiles | sample std | range | " in report
    assert "expected best of 4 settings [95% band] |" in report
    assert "| spo | 3 | 9.8 / 10.5 / 12.8 | 3.1 | 6.0 | 14.1 [9.0, 15.0] |" in report
    assert "| ppo | 4 | 9.5 / 10.5 / 11.2 | 1.7 | 4.0 | 11.6 [" in report
    assert "Wide bands (ppo, spo): wider than the whole rise" in report
    assert "- spo: learning_rate = 0.0003" in report
    assert "Search space: learning_rate [1e-05, 0.001] log." in report
    assert "Tuning seeds: 1000000 … 1000001." in report
    assert (tmp_path / "tuning_curves.png").stat().st_size > 0
    json.dumps(results, allow_nan=False)  # results.json takes it as it is


def test_a_band_of_zero_width_is_not_called_wide(tmp_path):
    flat = [
        {"arms": {"ppo": {"trials": [row(t, -200.0) for t in range(4)], "survivors": [0, 1]}}},
        {"arms": {"ppo": {"trials": [row(0, -150.0), row(1, -120.0)], "survivors": [1]}}},
        {"arms": {"ppo": {"trials": [row(1, -110.0)], "survivors": [1]}}},
    ]
    results = {"cartpole": {"ppo": arm_results("ppo", "ppo", flat, SETTINGS, windows(flat), 100)}}
    write_report(tmp_path, {**PLAN, "variants": ["ppo"]}, results)
    report = (tmp_path / "report.md").read_text()
    assert "| ppo | 4 | -200.0 / -200.0 / -200.0 | 0.0 | 0.0 | -200.0 [-200.0, -200.0] |" in report
    assert "Wide bands" not in report
