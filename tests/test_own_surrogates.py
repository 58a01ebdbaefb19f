"""fppo_jax.core.own_surrogates: a surrogate of one's own may not take another setting's name (an
optimisation setting's, a run shape's or the command line's), but may share a built-in's
hyperparameter's name."""

import pytest

import fppo_jax
from fppo_jax import surrogate


@pytest.mark.parametrize(
    "hyperparameter, what",
    [
        ("learning_rate", "an optimisation setting"),
        ("gamma", "an optimisation setting"),
        ("num_envs", "a TrainConfig field"),
        ("steps", "a name of the command line"),
        ("output", "a name of the command line"),
        ("seed", "a name of the command line"),
        ("level", "a name of the command line"),
        ("variant", "a name of the command line"),
        ("command", "a name of the command line"),
    ],
)
def test_a_hyperparameter_cannot_take_a_settings_or_a_flags_name(hyperparameter, what):
    function = eval(f"lambda ratio, advantage, {hyperparameter}: ratio * advantage")
    with pytest.raises(
        ValueError,
        match=f"surrogate 'mine': a hyperparameter of its own cannot take another setting's "
        f"name \\({hyperparameter} is {what}\\), whose value it would take or shadow: rename it",
    ):
        surrogate("mine", function, **{hyperparameter: 0.001})


def test_a_hyperparameter_may_share_a_builtins_name_as_a_grid_axis_does():
    mine = surrogate("mine", lambda ratio, advantage, alpha: alpha * ratio * advantage, alpha=1.0)
    assert fppo_jax.expand_grid({"variant": ["fppo-lp", mine], "alpha": [1.1]}) == [
        {"variant": "fppo-lp", "alpha": 1.1},
        {"variant": "mine", "alpha": 1.1},
    ]
