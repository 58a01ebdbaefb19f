"""fppo_jax.stats.race: a finalist replaces the default only when the paired test, Holm over the
finalists, shows it better; a failed run loses its pair; identical scores never win."""

import numpy as np
import pytest

from fppo_jax.errors import InvalidInput
from fppo_jax.stats.race import paired_differences, race, signed_rank_p, smallest_p


def test_a_finalist_better_on_every_seed_wins_and_one_alike_does_not():
    rng = np.random.default_rng(0)
    default = rng.normal(0, 1, 10)
    finalists = np.stack([default + 0.0, default + rng.uniform(0.5, 1.5, 10), default - 1])
    outcome = race(default, finalists, 0.05)
    assert outcome.p[0] == 1.0 and outcome.p[1] == pytest.approx(smallest_p(10))
    assert outcome.beat == (1,) and outcome.winner == 1
    assert outcome.adjusted[1] == pytest.approx(3 * smallest_p(10))


def test_the_default_stays_when_no_finalist_is_shown_better():
    default = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    # Better on every seed, but 5 pairs cannot show it to 3 finalists at 0.05: 2^-5 > 0.05/3.
    outcome = race(default, np.stack([default + 1] * 3), 0.05)
    assert outcome.winner is None and outcome.beat == ()
    assert smallest_p(5) > 0.05 / 3


def test_the_best_mean_among_those_that_beat_the_default_wins():
    default = np.zeros(8)
    outcome = race(default, np.stack([np.full(8, 1.0), np.full(8, 2.0) + np.arange(8)]), 0.05)
    assert outcome.beat == (0, 1) and outcome.winner == 1


def test_a_run_without_a_score_loses_its_pair():
    d = paired_differences(
        np.array([1.0, np.nan, 3.0, np.nan]), np.array([0.0, 1.0, np.inf, np.nan])
    )
    assert d.tolist() == [1.0, -2.0, 2.0, 0.0]  # beyond the largest finite difference, 1
    assert signed_rank_p(np.array([2.0, 2.0]), np.array([2.0, 2.0])) == 1.0
    with pytest.raises(InvalidInput, match="one per seed each"):
        paired_differences(np.zeros(3), np.zeros(4))
    with pytest.raises(InvalidInput, match="at least one finalist"):
        race(np.zeros(3), np.zeros((0, 3)), 0.05)
