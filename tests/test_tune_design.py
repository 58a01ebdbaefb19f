"""fppo_jax.analysis.tune_design: a tune's design checked before any plan, each refusal naming
its value; the three streams of seeds apart; the budget per arm counts the validation race."""

import pytest
from conftest import TINY

from fppo_jax.analysis.tune_design import (
    TUNING_SEED_START,
    VALIDATION_SEED_START,
    design,
)
from fppo_jax.errors import InvalidInput
from fppo_jax.run.prepare import prepare

HALVING = dict(scheduler="halving", trials=4, seeds=2, eta=2, budget=None, score="eval")
HALVING |= dict(eval_episodes=10, finalists=3, validation_seeds=10, level=0.05)


def test_the_streams_of_seeds_never_meet():
    found = design(**HALVING)
    assert found.seeds == [TUNING_SEED_START, TUNING_SEED_START + 1]
    assert found.validation == list(range(VALIDATION_SEED_START, VALIDATION_SEED_START + 10))
    with pytest.raises(InvalidInput, match=r"validation seeds \[1000001\] are also tuning seeds"):
        design(**{**HALVING, "validation_seeds": [1_000_001, *range(5, 15)]})


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"finalists": 0}, "finalists"),
        ({"finalists": 4}, r"finalists \(4\) must be fewer than the trials \(4\)"),
        ({"validation_seeds": 5}, r"can never replace the default at level 0.05 .*2\^-5"),
        ({"scheduler": "bayes"}, "scheduler must be one of halving, racing"),
        ({"score": "auc"}, "score must be one of eval, train"),
        ({"eta": 1}, "eta .* at least 2"),
        ({"scheduler": "racing"}, "racing spends a budget"),
        ({"scheduler": "racing", "budget": 45}, r"cannot hold one round of 4 trials × 2 seeds"),
        ({"seeds": 1}, "at least 2 tuning seeds per trial, got 1"),
        ({"seeds": [0, 1]}, r"seeds \[0, 1\] are a study's test seeds"),
        ({"validation_seeds": list(range(3, 13))}, r"seeds \[3, 4, 5, 6, 7\] … are a study's"),
    ],
)
def test_a_design_that_cannot_work_is_refused_by_name(change, message):
    with pytest.raises(InvalidInput, match=message):
        design(**{**HALVING, **change})


def test_racing_spends_its_budget_in_rounds_and_the_race_is_counted_in_it():
    racing = design(**{**HALVING, "scheduler": "racing", "budget": 40 + 3 * 8})
    assert racing.seeds == list(range(TUNING_SEED_START, TUNING_SEED_START + 6))  # 3 rounds
    prepared = prepare("cartpole", TINY, (), total_steps=8 * 128, preset="paper", backend="auto")
    budget = racing.budget_of(prepared)
    assert budget["full_runs_per_arm"] == 4 * 6 + 4 * 10 and "rungs" not in budget
    halving = design(**HALVING).budget_of(prepared)
    # 4 → 2 → 1 trials × 2 seeds over rungs of 2, 4 and 8 updates, then the race's 40 runs.
    assert halving["full_runs_per_arm"] == (2 * (4 * 2 + 2 * 2 + 1 * 4) + 40 * 8) / 8
    assert [rung["trials"] for rung in halving["rungs"]] == [4, 2, 1]
