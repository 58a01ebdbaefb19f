"""fppo_jax.core.resolution: a variant's name resolved to its surrogate (a built-in, or one of
one's own imported by module:attribute), its hyperparameters' defaults (Table 2's α and k on a
task), ranges and checks, and the checked objective and hyperparameters, with their messages."""

import math
import os
import re
import sys

import jax.numpy as jnp
import numpy as np
import pytest
from own_surrogates import half_finite

import fppo_jax
from fppo_jax import VARIANTS, objective
from fppo_jax.cli import main
from fppo_jax.core.resolution import (
    HYPERPARAMETER_DEFAULTS,
    TABLE2,
    as_float,
    hyperparameters,
    resolve,
    resolve_hyperparameters,
    table2,
)
from fppo_jax.envs import MUJOCO_TASKS, lookup
from fppo_jax.errors import InvalidInput


@pytest.mark.parametrize(
    "variant, params, match",
    [
        ("sppo", {}, "unknown variant 'sppo'; valid variants: ppo, fppo-lp"),
        ("dpo", {"beta": 0.0}, "beta must be > 0 for dpo, got 0.0"),
        ("clip-higher", {"eps_low": 1.0}, "eps_low must be in \\(0, 1\\) for clip-higher"),
        ("clip-higher", {"eps_high": float("inf")}, "eps_high must be finite for clip-higher"),
        ("fppo-lp", {"alpha": 0.9}, "alpha must be >= 1 for fppo-lp"),
        ("fppo-lp", {"alpha": float("nan")}, "alpha must be >= 1"),
        ("fppo-qp", {"k": -0.1}, "k must be >= 0"),
        ("tr-ppo", {"delta": 0.0}, "delta must be > 0"),
        ("tr-ppo-rb", {"delta": -1.0}, "delta must be > 0"),
        ("ppo-rb", {"alpha": -0.1}, "alpha must be >= 0 for ppo-rb, got -0.1 \\(the rollback"),
        ("ppo", {"epsilon": 1.0}, "epsilon must be in \\(0, 1\\)"),
        ("ppo", {"epsilon": 0.0}, "epsilon must be in \\(0, 1\\)"),
        ("ppo", {"alpha": 1.3}, "ppo has no hyperparameter alpha"),
        (
            "fppo-qp",
            {"alpha": 1.3},
            "fppo-qp has no hyperparameter alpha \\(it takes: epsilon, k\\)",
        ),
    ],
)
def test_bad_hyperparameters_are_named(variant, params, match):
    with pytest.raises(ValueError, match=match):
        objective(variant, **params)


@pytest.mark.parametrize("value", ["1.3", True, np.ones(2), [1.3]])
def test_a_hyperparameter_that_is_not_a_number_is_refused(value):
    with pytest.raises(ValueError, match=r"alpha must be a (single )?number"):
        objective("fppo-lp", alpha=value)
    assert objective("fppo-lp", alpha=np.float32(1.25)).values["alpha"] == np.float32(1.25)


def test_an_optimisation_setting_that_is_not_a_number_is_refused():
    from fppo_jax import hyperparameters, sweep

    with pytest.raises(ValueError, match=r"learning_rate must be a number, got '0\.001'"):
        hyperparameters("ppo", learning_rate="0.001")
    with pytest.raises(ValueError, match=r"k must be a number, got '0\.4'"):
        sweep("cartpole", {"variant": "fppo-qp", "k": ["0.4"]}, seeds=1)


def test_resolve_takes_each_variant_and_lists_them_when_refusing():
    assert [resolve(v).name for v in VARIANTS] == list(VARIANTS)
    listed = "ppo, fppo-lp, fppo-qp, tr-ppo, ppo-rb, tr-ppo-rb, spo, clip-higher, dpo"
    for wrong in ("PPO", "fppo", None):
        with pytest.raises(
            ValueError, match=re.escape(f"unknown variant {wrong!r}; valid variants: {listed}")
        ):
            resolve(wrong)
    with pytest.raises(ValueError, match="unknown variant 'fppo'"):
        objective("fppo")


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
        "learning_rate": (math.inf, "learning_rate must be finite, got inf"),
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


def test_a_surrogate_not_finite_at_given_values_says_what_to_narrow():
    objective(half_finite, beta=0.5)  # finite up to 1/2
    with pytest.raises(
        InvalidInput,
        match=r"^surrogate 'half-finite' has a value that is not finite \(nan\) at ratio .* "
        r"beta = 0.75: give it beta or epsilon where it is finite \(a tune draws them from its "
        r"search space and stops at such a point: narrow the interval of beta or epsilon to "
        r"where it is finite, in a space file, --space, and tune into a new output\)$",
    ):
        objective(half_finite, beta=0.75)


def test_as_float_is_the_shortest_decimal_of_the_float32():
    assert float(np.float32(1.3)) != 1.3 and as_float(jnp.float32(1.3)) == 1.3
    assert as_float(np.float32(3e-4)) == 3e-4 and as_float(jnp.asarray(0.99)) == 0.99
    assert np.float32(as_float(np.float32(0.1) / 3)) == np.float32(0.1) / 3  # round-trips


def test_a_surrogate_module_is_imported_from_the_current_directory(module_here):
    module_here(
        "here_mine",
        "import fppo_jax\n"
        "mine = fppo_jax.surrogate('here-mine', lambda ratio, advantage: ratio * advantage)\n",
    )
    assert fppo_jax.core.resolution.resolve("here_mine:mine").name == "here-mine"
    assert os.getcwd() not in sys.path  # the directory is on the path only while importing
    with pytest.raises(
        ValueError,
        match=re.escape(
            f"no module 'here_absent' in the current directory or on Python's path (looked in "
            f"{os.getcwd()}, "
        ),
    ):
        fppo_jax.core.resolution.resolve("here_absent:mine")


@pytest.mark.parametrize(
    "text, match",
    [
        ("import sys\nsys.exit(0)\n", r"importing here_bad called sys.exit\(0\); a module"),
        (
            "raise RuntimeError('no GPU here')\n",
            "importing here_bad raised RuntimeError: no GPU here",
        ),
        ("x = 1\ndef f(:\n", r"here_bad does not parse: .*here_bad.py:2: SyntaxError: "),
    ],
)
def test_a_surrogate_module_that_fails_to_import_is_one_line_naming_it(
    module_here, capsys, text, match
):
    module_here("here_bad", text)
    assert main(["train", "--variant", "here_bad:mine"]) == 2
    err = capsys.readouterr().err
    assert re.fullmatch(f"fppo-jax: error: variant 'here_bad:mine': {match}.*\n", err), err
