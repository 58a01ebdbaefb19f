"""fppo_jax.analysis.tuning_draws: trial 0 is each arm's default, every arm takes the same points
on the axes they share, the same storage and seed give the same population again, and a
storage that cannot be opened is one error."""

import warnings

import pytest
from helpers import TUNE_ARMS as ARMS
from helpers import TUNE_SMALL as SMALL

from fppo_jax.analysis.tune_storage import open_storage
from fppo_jax.analysis.tuning import tune
from fppo_jax.analysis.tuning_draws import (
    draw_population,
    import_optuna,
    setting_of,
)
from fppo_jax.core.resolution import resolve
from fppo_jax.core.search_space import search_spaces
from fppo_jax.errors import InvalidInput


def population(tmp_path, sampler="qmc", seed=0, trials=5, name="optuna.db"):
    optuna = import_optuna()
    arms = [resolve(arm) for arm in ("ppo", "fppo-lp", "spo")]
    storage = open_storage(optuna, f"sqlite:///{tmp_path / name}")
    drawn = draw_population(
        optuna, storage, "cartpole", arms, search_spaces(arms), trials, sampler, seed
    )
    return {arm: [setting_of(params) for params in trials] for arm, trials in drawn.items()}


def test_trial_0_is_each_arms_default_and_the_arms_share_their_points(tmp_path):
    drawn = population(tmp_path)
    ppo, lp, spo = drawn["ppo"], drawn["fppo-lp"], drawn["spo"]
    assert ppo[0]["learning_rate"] == 3e-4 and ppo[0]["gamma"] == pytest.approx(0.99)
    assert lp[0]["alpha"] == 1.3  # Table 2 on CartPole
    assert [len(arm) for arm in drawn.values()] == [5, 5, 5]
    for trial in range(5):
        shared = ppo[trial]
        assert {k: v for k, v in lp[trial].items() if k != "alpha"} == shared
        assert {k: v for k, v in spo[trial].items() if k in shared} == shared
    # Four draws, distinct, each inside the arms' own intervals.
    assert len({setting["learning_rate"] for setting in ppo}) == 5
    assert len({setting["alpha"] for setting in lp[1:]}) == 4


def test_the_same_storage_and_seed_give_the_same_population_again(tmp_path):
    first = population(tmp_path)
    assert population(tmp_path) == first  # read back from the storage, not drawn again
    assert population(tmp_path, name="other.db") == first  # drawn again from the seed
    assert population(tmp_path, seed=1, name="seed-1.db") != first


def test_a_storage_that_cannot_be_opened_is_one_error(tmp_path):
    with pytest.raises(InvalidInput, match="cannot open Optuna's storage nosuch://here: SQLAlc"):
        tune("cartpole", ARMS, output=tmp_path, storage="nosuch://here", **SMALL)


def test_a_space_that_leaves_the_default_out_keeps_it_as_trial_0_without_optunas_warning(
    tmp_path,
):
    optuna = import_optuna()
    arms = [resolve("ppo")]
    spaces = search_spaces(arms, {"learning_rate": {"low": 1e-3, "high": 1e-2, "scale": "log"}})
    storage = open_storage(optuna, f"sqlite:///{tmp_path / 'optuna.db'}")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # Optuna's "Fixed parameter ... is out of range" included
        warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)  # as tune() does
        drawn = draw_population(optuna, storage, "cartpole", arms, spaces, 4, "qmc", 0)
    rates = [setting_of(params)["learning_rate"] for params in drawn["ppo"]]
    assert rates[0] == 3e-4 and all(1e-3 <= rate <= 1e-2 for rate in rates[1:])
