"""fppo_jax.core.shape_space: the run-shape axes around the configured shape, fixed where the
run's settings give them, narrowed by a space file, every combination checked before any
compile, the configured value (trial 0's) always among an axis's values."""

import pytest

from fppo_jax.core.config import TrainConfig
from fppo_jax.core.shape_space import (
    Choice,
    config_values,
    configured,
    shape_space,
    split_setting,
)
from fppo_jax.errors import InvalidInput

PAPER = TrainConfig(total_steps=1_000_000)


def test_the_default_axes_surround_the_configured_shape():
    axes = shape_space(PAPER, True, (), {}, searched=True)
    assert axes["num_steps"] == Choice((256, 128, 64))
    assert axes["num_minibatches"] == Choice((32, 16, 8))
    assert axes["num_epochs"] == Choice((5, 10, 20))
    assert axes["hidden_sizes"] == Choice(("64,64", "256,256"))
    assert axes["normalize_observations"] == Choice((True, False))
    assert axes["initial_log_std"] == Choice((0.0, -0.5, -1.0, -2.0))
    # Discrete actions have no log-std; an axis the settings fix is not searched.
    discrete = shape_space(PAPER, False, {"num_epochs"}, {}, searched=True)
    assert "initial_log_std" not in discrete and "num_epochs" not in discrete
    # Every default value is trial 0's or another, each combination a valid run.
    for name, axis in axes.items():
        assert configured(PAPER, name) in axis.values


def test_a_space_file_narrows_an_axis_and_halving_searches_only_what_it_gives():
    given = {"num_epochs": [10, 20], "hidden_sizes": [[64, 64], [128, 128]]}
    axes = shape_space(PAPER, False, (), given, searched=False)
    assert axes == {"num_epochs": Choice((10, 20)), "hidden_sizes": Choice(("64,64", "128,128"))}
    assert config_values({"hidden_sizes": "128,128"}) == {"hidden_sizes": (128, 128)}
    assert shape_space(PAPER, False, (), {"num_epochs": {"choices": [10]}}, False) == {
        "num_epochs": Choice((10,))
    }


@pytest.mark.parametrize(
    ("given", "fixed", "message"),
    [
        ({"num_minibatches": [32, 3]}, (), r"num_minibatches 3 makes no valid run: .* divide"),
        ({"num_steps": [256, 4096]}, (), r"num_steps 4096 makes no valid run: total_steps"),
        ({"num_epochs": [5, 20]}, (), r"leave out the task's own 10, trial 0's"),
        ({"num_epochs": [10, 10]}, (), "lists a value twice"),
        ({"num_epochs": 10}, (), "given as a list of values"),
        ({"num_epochs": [10, 20]}, ("num_epochs",), "fixed by the run's settings"),
        ({"initial_log_std": [0.0, -1.0]}, (), "only where the actions are continuous"),
        ({"hidden_sizes": ["64,64", "wide"]}, (), "hidden_sizes must be layer widths"),
    ],
)
def test_a_value_that_makes_no_valid_run_is_refused_by_name(given, fixed, message):
    # A budget of one update at the paper's shape: 4,096 steps per rollout do not fit.
    config = TrainConfig(total_steps=2048) if "4096" in message else PAPER
    with pytest.raises(InvalidInput, match=message):
        shape_space(config, False, fixed, given, searched=False)


def test_a_setting_splits_into_its_hyperparameters_and_its_run_shape():
    setting = {"learning_rate": 1e-3, "num_epochs": 20, "hidden_sizes": "256,256"}
    assert split_setting(setting) == (
        {"learning_rate": 1e-3},
        {"num_epochs": 20, "hidden_sizes": "256,256"},
    )


def test_the_initial_log_std_is_a_finite_number_and_records_leave_its_default_out():
    from fppo_jax.store.record import RunRecord

    with pytest.raises(InvalidInput, match="initial_log_std must be a finite number"):
        TrainConfig(initial_log_std=float("nan"))
    plain = RunRecord("cartpole", "gymnax", "paper", TrainConfig())
    assert "initial_log_std" not in plain.to_json()
    assert RunRecord.from_json(plain.to_json()) == plain  # as records written before it read
    wider = RunRecord("hopper", "native", "paper", TrainConfig(initial_log_std=-1.0))
    assert RunRecord.from_json(wider.to_json()).config.initial_log_std == -1.0
