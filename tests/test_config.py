"""fppo_jax.core.config: the checks of a run's settings, their messages, presets and Table 2."""

import dataclasses
import math
import re

import jax.numpy as jnp
import numpy as np
import pytest

from fppo_jax.core.config import (
    HYPERPARAMETER_DEFAULTS,
    MAX_STEPS,
    PRESETS,
    TABLE2,
    TrainConfig,
    as_float,
    describe,
    describe_update,
    environment_name,
    hyperparameters,
    preset_config,
    resolve_config,
    resolve_hyperparameters,
    table2,
    task_preset,
)
from fppo_jax.envs import MUJOCO_TASKS, lookup

SMALL = {"num_envs": 4, "num_steps": 32, "num_minibatches": 4, "num_epochs": 2}


def test_table2_gives_the_papers_alpha_or_k_of_the_variants_that_take_them():
    assert table2("hopper", "fppo-qp") == {"k": 0.2}
    assert table2("walker2d", "fppo-qp") == {"k": 0.1}
    assert table2("swimmer", "fppo-lp") == {"alpha": 1.1}
    assert table2("reacher", "fppo-lp") == {"alpha": 1.1}
    assert table2("cartpole", "fppo-lp") == {"alpha": 1.3}
    for variant in ("ppo", "tr-ppo", "ppo-rb", "tr-ppo-rb"):  # their own: not in Table 2
        assert table2("hopper", variant) == {}
    assert table2(None, "fppo-qp") == {} and table2("gymnax/Pendulum-v1", "fppo-lp") == {}
    # Every task of the table is a registered one, and every MuJoCo task is in the table.
    assert all(lookup(task).name == task for task in TABLE2)
    assert set(MUJOCO_TASKS) <= set(TABLE2)


def test_num_updates_is_the_whole_updates_within_the_budget():
    for total, updates in [(128, 1), (255, 1), (256, 2), (1000, 7), (1024, 8)]:
        config = TrainConfig(total_steps=total, **SMALL)
        assert config.samples_per_update == 128 and config.minibatch_size == 32
        assert config.num_updates == updates == total // 128
        assert config.num_updates * config.samples_per_update <= total


def test_train_config_normalises_its_fields_and_is_frozen():
    config = TrainConfig(total_steps=np.int64(512), hidden_sizes=[16, np.int32(8)], **SMALL)
    assert config.hidden_sizes == (16, 8) and type(config.total_steps) is int
    assert all(type(h) is int for h in config.hidden_sizes)
    with pytest.raises(dataclasses.FrozenInstanceError):
        config.num_envs = 2  # type: ignore[misc]


@pytest.mark.parametrize(
    "settings, message",
    [
        ({"hidden_sizes": ()}, "hidden_sizes must be a sequence of positive layer widths such as "),
        ({"hidden_sizes": (64, 1.5)}, "each of hidden_sizes must be a positive integer, got 1.5"),
        ({"total_steps": MAX_STEPS + 1}, "total_steps must be at most 2,147,483,647 (the compiled"),
        ({"num_epochs": 0}, "num_epochs must be a positive integer, got 0"),
        ({"num_minibatches": 5}, "num_minibatches (5) must divide the samples per update "),
        ({"total_steps": 127}, "total_steps (127) is less than one update's samples (num_envs × "),
        ({"clip_value_loss": 1}, "clip_value_loss must be True or False, got 1"),
        ({"anneal_learning_rate": None}, "anneal_learning_rate must be True or False, got None"),
    ],
)
def test_train_config_refuses_bad_settings_saying_which_and_why(settings, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        TrainConfig(**{"total_steps": 1024, **SMALL, **settings})


def test_the_largest_budget_the_program_can_count_is_accepted():
    config = TrainConfig(total_steps=MAX_STEPS, **SMALL)
    assert config.num_updates == MAX_STEPS // 128
    assert TrainConfig(total_steps=1024, normalize_rewards=np.bool_(False), **SMALL)


def test_describe_says_the_shape_and_what_whole_updates_leave_of_the_budget():
    config = TrainConfig(total_steps=1000, **SMALL)
    shape = "128 samples (4 envs × 32 steps), 4 minibatches × 2 epochs"
    assert describe_update(config) == shape
    assert (
        describe(config)
        == f"7 updates × {shape} = 896 env steps (whole updates of the 1,000 asked)"
    )
    exact = TrainConfig(total_steps=1024, anneal_learning_rate=True, **SMALL)
    assert describe(exact, "massive") == (
        f"preset massive, 8 updates × {shape}, learning rate annealed linearly to 0"
    )


def test_presets_and_task_presets():
    assert preset_config("paper") == TrainConfig()  # the defaults are the paper's
    paper = preset_config("paper", total_steps=2048)
    assert (paper.samples_per_update, paper.num_minibatches, paper.num_epochs) == (2048, 32, 10)
    assert paper.minibatch_size == 64  # baselines' ppo2: 2048 samples in 32 minibatches
    assert preset_config("massive", total_steps=32768, num_epochs=1).num_epochs == 1
    assert set(PRESETS) == {"paper", "massive"}
    for task in MUJOCO_TASKS:
        assert task_preset("paper", task) == {"anneal_learning_rate": True}
        assert task_preset("massive", task) == {}
    assert task_preset("paper", "cartpole") == {} and task_preset("paper", None) == {}


def test_resolve_config_takes_the_tasks_budget_unless_told_and_lists_valid_settings():
    class Custom:  # an environment object: no registered budget
        pass

    assert resolve_config(Custom(), None, {}).total_steps == TrainConfig().total_steps
    assert resolve_config("cartpole", None, {}).total_steps == lookup("cartpole").total_steps
    assert resolve_config("hopper", None, {}).total_steps == 1_000_000
    assert resolve_config("hopper", 4096, {"total_steps": 8192}).total_steps == 4096
    assert resolve_config("hopper", None, {"total_steps": 8192}).total_steps == 8192
    with pytest.raises(ValueError, match=r"unknown setting lr, zz; valid: total_steps, .*, seed$"):
        resolve_config("cartpole", None, {"zz": 1, "lr": 1}, also_valid=("variant", "seed"))


def test_hyperparameters_take_defaults_and_check_each_range_at_its_bounds():
    hp = hyperparameters()
    for name, value in HYPERPARAMETER_DEFAULTS.items():
        assert getattr(hp, name).dtype == jnp.float32
        assert float(getattr(hp, name)) == pytest.approx(value)
    edges = hyperparameters(gamma=1.0, gae_lambda=0.0, entropy_coef=0.0, value_coef=0.0)
    assert (float(edges.gamma), float(edges.gae_lambda)) == (1.0, 0.0)
    assert float(hyperparameters(gamma=None).gamma) == pytest.approx(0.99)  # None: the default
    refused = {
        "gamma": (0.0, "gamma must be in (0, 1], got 0.0"),
        "gae_lambda": (1.01, "gae_lambda must be in [0, 1], got 1.01"),
        "entropy_coef": (-0.1, "entropy_coef must be >= 0, got -0.1"),
        "value_coef": (math.nan, "value_coef must be >= 0, got nan"),
        "max_grad_norm": (0.0, "max_grad_norm must be > 0, got 0.0"),
        "learning_rate": (math.inf, "learning_rate must be > 0, got inf"),
    }
    for name, (value, message) in refused.items():
        with pytest.raises(ValueError, match=re.escape(message)):
            hyperparameters(**{name: value})
    with pytest.raises(ValueError, match=r"unknown hyperparameter lr; valid: epsilon, alpha, k"):
        hyperparameters(lr=1e-3)


@pytest.mark.parametrize(
    "given, message",
    [
        (
            {"gamma": 1e-300},
            "gamma must be in (0, 1], got 1e-300, which training's float32 holds as 0",
        ),
        (
            {"learning_rate": 1e300},
            "learning_rate must be > 0, got 1e+300, which training's float32",
        ),
        ({"variant": "fppo-qp", "k": 1e300}, "k must be >= 0 for fppo-qp, got 1e+300, which train"),
        ({"variant": "tr-ppo", "delta": 1e-300}, "delta must be > 0 for tr-ppo, got 1e-300, which"),
        ({"epsilon": 1e-300}, "epsilon must be in (0, 1), got 1e-300, which training's float32 h"),
    ],
)
def test_a_value_in_range_that_float32_takes_out_of_it_is_refused(given, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        hyperparameters(**given)


def test_resolve_hyperparameters_reports_the_setting_as_plain_decimals():
    hp, settings = resolve_hyperparameters("fppo-qp", "cartpole", gamma=None, value_coef=0.7)
    assert settings == {
        "variant": "fppo-qp",
        "epsilon": 0.2,
        "k": 0.4,  # Table 2's, for CartPole
        "learning_rate": 0.0003,
        "gamma": 0.99,
        "gae_lambda": 0.95,
        "entropy_coef": 0.0,
        "value_coef": 0.7,
        "max_grad_norm": 0.5,
    }
    assert float(hp.value_coef) == np.float32(0.7)
    assert "alpha" not in resolve_hyperparameters("ppo", "hopper")[1]
    with pytest.raises(ValueError, match="unknown variant 'lp'"):
        resolve_hyperparameters("lp", "hopper")


def test_as_float_is_the_shortest_decimal_of_the_float32():
    assert float(np.float32(1.3)) != 1.3 and as_float(jnp.float32(1.3)) == 1.3
    assert as_float(np.float32(3e-4)) == 3e-4 and as_float(jnp.asarray(0.99)) == 0.99
    assert np.float32(as_float(np.float32(0.1) / 3)) == np.float32(0.1) / 3  # round-trips


def test_environment_name_is_the_tasks_the_environments_own_or_its_class():
    class Named:
        name = "MyEnv-v0"

    class Inner:
        pass

    class Wrapper:
        name = None  # not a string: the wrapped environment's class names it
        env = Inner()

    assert environment_name("hopper", object()) == "hopper"
    assert environment_name(Named(), Named()) == "MyEnv-v0"
    assert environment_name(Wrapper(), Wrapper()) == "Inner"
    assert environment_name(Inner(), Inner()) == "Inner"
