"""fppo_jax.core.config: the run's shape, its checks and their messages, and the presets."""

import dataclasses
import re

import numpy as np
import pytest

from fppo_jax.core.config import (
    MAX_STEPS,
    PRESETS,
    TrainConfig,
    describe,
    describe_update,
    environment_name,
    preset_config,
    resolve_config,
    task_preset,
)
from fppo_jax.envs import MUJOCO_TASKS, lookup

SMALL = {"num_envs": 4, "num_steps": 32, "num_minibatches": 4, "num_epochs": 2}


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
