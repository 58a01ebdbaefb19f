"""fppo_jax.analysis.halving: the rungs halve the trials and end at the full budget, in whole
calls of the first rung's length; a rung's trials ranked best first, a trial without a score
below every scored one, a diverged one out."""

import numpy as np
import pytest

from fppo_jax.analysis.halving import SuccessiveHalving, ranked, schedule
from fppo_jax.errors import InvalidInput


def row(trial, score, diverged=False):
    return {"trial": trial, "score": score, "seed_scores": [score], "diverged": diverged}


def test_schedule_halves_the_trials_and_ends_at_the_full_budget():
    rungs = schedule(27, 3, 81)
    assert rungs.trials == (27, 9, 3, 1)
    assert rungs.ends == (3, 9, 27, 81)
    assert schedule(10, 3, 100).trials == (10, 3, 1)
    assert schedule(10, 3, 100).ends == (11, 33, 100)
    # Every trial trains the first rung; the survivors each rung's further updates.
    assert rungs.updates_per_arm(seeds=2) == 2 * (27 * 3 + 9 * 6 + 3 * 18 + 1 * 54)
    assert schedule(1, 3, 5).ends == (5,)
    # Progress between calls: the first rung (3 updates here, 54 on MuJoCo) in whole calls.
    assert rungs.updates_per_call == 1
    assert schedule(9, 3, 488).updates_per_call == 3
    with pytest.raises(InvalidInput, match="too short for 4 rungs"):
        schedule(27, 3, 20)


def test_a_trial_without_an_episode_ranks_below_scored_ones_and_a_diverged_one_not_at_all():
    rows = [row(0, None), row(1, 5.0), row(2, 7.0, True), row(3, None), row(4, 5.0)]
    assert [r["trial"] for r in ranked(rows)] == [1, 4, 0, 3]


def test_a_tied_rung_cuts_none_and_every_rung_records_its_evidence():
    halving = SuccessiveHalving(["ppo"], 4, [7, 8], schedule(4, 2, 8))
    window = halving.next_window([])
    flat = halving.measured([], np.full(len(window.runs), -200.0), np.zeros(8, bool))["ppo"]
    assert flat["survivors"] == [0, 1, 2, 3] and flat["evidence"]["tied"]
    recorded = [{"arms": {"ppo": flat}}]
    assert len(halving.next_window(recorded).runs) == 8  # all four go on, not the first two
    apart = np.array([float(t) for _, t, _ in window.runs])
    cut = halving.measured([], apart, np.zeros(8, bool))["ppo"]
    assert cut["survivors"] == [2, 3] and not cut["evidence"]["tied"]
