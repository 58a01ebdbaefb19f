"""The search space: the default intervals hold every arm's default, a space file replaces or
narrows them, and every interval is checked against the hyperparameter's valid range."""

import json

import pytest

from fppo_jax.core.search_space import (
    OWN,
    SHARED,
    Interval,
    default_setting,
    interval,
    read_space_file,
    search_spaces,
)
from fppo_jax.core.variants import BUILTINS
from fppo_jax.errors import InvalidInput


@pytest.mark.parametrize("variant", list(BUILTINS))
def test_every_builtins_default_lies_in_its_default_space(variant):
    surrogate = BUILTINS[variant]
    axes = search_spaces([surrogate])[variant].axes
    for task in ("cartpole", "hopper", "swimmer"):
        setting = default_setting(surrogate, task)
        assert set(setting) == set(axes)
        assert all(axes[name].contains(value) for name, value in setting.items()), setting
    assert set(OWN[variant]) == set(surrogate.defaults)


def test_a_discount_is_searched_on_one_minus_its_value():
    assert SHARED["gamma"] == Interval(0.9, 0.9999, "log1m")
    with pytest.raises(InvalidInput, match="log1m scale needs high < 1"):
        interval("gamma", (0.9, 1.0, "log1m"), "here")


def test_a_space_file_replaces_the_intervals_it_names(tmp_path):
    path = tmp_path / "space.json"
    path.write_text(
        json.dumps({"learning_rate": [1e-4, 1e-3, "log"], "fppo-lp": {"alpha": [1, 1.5]}})
    )
    spaces = search_spaces([BUILTINS["ppo"], BUILTINS["fppo-lp"]], read_space_file(path))
    assert spaces["ppo"].shared["learning_rate"] == Interval(1e-4, 1e-3, "log")
    assert spaces["fppo-lp"].shared == spaces["ppo"].shared
    assert spaces["fppo-lp"].own == {"alpha": Interval(1.0, 1.5)}
    yaml_path = tmp_path / "space.yaml"
    yaml_path.write_text("epsilon: {low: 0.1, high: 0.3}\n")
    assert read_space_file(yaml_path) == {"epsilon": {"low": 0.1, "high": 0.3}}


def test_a_yaml_space_file_reads_an_exponent_without_a_dot_as_a_number(tmp_path):
    # PyYAML alone reads 1e-4 as the text "1e-4", which the interval refused as not finite.
    path = tmp_path / "space.yaml"
    path.write_text("learning_rate: {low: 1e-4, high: 3E-3, scale: log}\nentropy_coef: [0, 1e-2]\n")
    given = read_space_file(path)
    assert given == {
        "learning_rate": {"low": 1e-4, "high": 3e-3, "scale": "log"},
        "entropy_coef": [0, 1e-2],
    }
    assert search_spaces([BUILTINS["ppo"]], given)["ppo"].shared["learning_rate"] == Interval(
        1e-4, 3e-3, "log"
    )
    path.write_text("learning_rate: {low: '1e-4', high: 1e-3, scale: log}\n")  # quoted: text
    with pytest.raises(InvalidInput, match="must be finite"):
        search_spaces([BUILTINS["ppo"]], read_space_file(path))


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ({"low": 1}, "must be {'low'"),
        ((2, 1), "low <= high"),
        ((0, float("inf")), "finite"),
        ((0.1, 1, "cubic"), "scale must be one of linear, log, log1m"),
        ("wide", "must be \\(low, high"),
    ],
)
def test_a_malformed_interval_is_refused_naming_it(value, message):
    with pytest.raises(InvalidInput, match=message):
        interval("epsilon", value, "the search space")


def test_an_unreadable_space_file_is_one_error(tmp_path):
    (tmp_path / "bad.json").write_text("{")
    with pytest.raises(InvalidInput, match="cannot read the space file"):
        read_space_file(tmp_path / "bad.json")
    (tmp_path / "list.json").write_text("[1]")
    with pytest.raises(InvalidInput, match="must map names to intervals"):
        read_space_file(tmp_path / "list.json")
    with pytest.raises(InvalidInput, match="cannot read the space file"):
        read_space_file(tmp_path / "missing.json")
