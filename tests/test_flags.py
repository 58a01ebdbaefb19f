"""The command line's flags (fppo_jax.cli.flags): one for each field of TrainConfig, and the
values and ranges a sweep's flags take, bad ones refused saying why."""

import pytest

from fppo_jax.cli import build_parser, main


def test_every_config_field_has_a_flag_named_after_it():
    import dataclasses

    from fppo_jax import TrainConfig
    from fppo_jax.cli.flags import config_overrides

    parser = build_parser()
    for command in ("train", "sweep"):
        fields = {f.name for f in dataclasses.fields(TrainConfig)}
        args = parser.parse_args([command])
        assert fields <= set(vars(args))  # one destination per field, None unless given
        assert config_overrides(args) == {"preset": "paper"}
    named = parser.parse_args(
        ["train", "--num-minibatches", "8", "--hidden-sizes", "32,16", "--no-normalize-rewards"]
    )
    aliased = parser.parse_args(["train", "--minibatches", "8", "--hidden", "32,16"])
    assert config_overrides(named) == {
        "preset": "paper",
        "num_minibatches": 8,
        "hidden_sizes": (32, 16),
        "normalize_rewards": False,
    }
    assert config_overrides(aliased) == {
        "preset": "paper",
        "num_minibatches": 8,
        "hidden_sizes": (32, 16),
    }
    assert config_overrides(parser.parse_args(["train", "--no-obs-norm", "--anneal-lr"])) == {
        "preset": "paper",
        "normalize_observations": False,
        "anneal_learning_rate": True,
    }


def test_sweep_value_ranges_and_errors(tmp_path, capsys):
    from fppo_jax.cli.flags import values as parse_values

    assert parse_values("1.1:1.5:0.1") == [1.1, 1.2, 1.3, 1.4, 1.5]
    assert parse_values("0.1,0.4") == [0.1, 0.4]
    with pytest.raises(SystemExit):
        main(["sweep", "--alpha", "1.5:1.1:0.1"])
    assert "expected start:stop:step" in capsys.readouterr().err
    assert main(["table", str(tmp_path / "nothing")]) == 2
    assert "not a sweep's output" in capsys.readouterr().err


@pytest.mark.parametrize(
    "text, values",
    [
        ("0:1:0.6", [0.0, 0.6]),  # not past its stop
        ("0:1:0.3", [0.0, 0.3, 0.6, 0.9]),
        ("0:1:0.1", [0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0]),  # nor short of it
        ("1e-4:5e-4:1e-4", [1e-4, 2e-4, 3e-4, 4e-4, 5e-4]),
        ("0.3:0.3:0.1", [0.3]),
        ("0:999:1", [float(i) for i in range(1000)]),
    ],
)
def test_value_ranges_end_on_or_before_their_stop_without_float_error(text, values):
    from fppo_jax.cli.flags import values as parse_values

    assert parse_values(text) == values


@pytest.mark.parametrize(
    "text, message",
    [
        ("0:1000:1", "0:1000:1 gives more than 1000 values"),
        ("0:1:1e-9", "0:1:1e-9 gives more than 1000 values"),
        ("0:inf:1", "values must be finite numbers, got '0:inf:1'"),
        ("nan:1:0.1", "values must be finite numbers"),
        ("0:1:nan", "values must be finite numbers"),
        ("0.1,inf", "values must be finite numbers"),
        ("1e400,1", "values must be finite numbers"),
        ("0:1:0", "expected start:stop:step with stop >= start and step > 0, got '0:1:0'"),
        ("0:1", "expected start:stop:step with stop >= start and step > 0"),
        ("0.1,,0.2", "expected start:stop:step or a comma list of numbers, got '0.1,,0.2'"),
    ],
)
def test_bad_values_are_refused_saying_why(text, message, capsys):
    with pytest.raises(SystemExit):
        main(["sweep", "--alpha", text])
    assert message in capsys.readouterr().err


@pytest.mark.parametrize("command", ["tune", "sweep", "study"])
@pytest.mark.parametrize("given", [["--part", "-1/2"], ["--part=-1/2"]])
def test_a_part_that_starts_with_a_dash_is_refused_by_its_own_check(command, given, capsys):
    # argparse took -1/2 for a flag and said only "expected one argument".
    with pytest.raises(SystemExit) as refused:
        main([command, *given, "--output", "x"])
    assert refused.value.code == 2
    assert capsys.readouterr().err == (
        f"fppo-jax {command}: error: argument --part: part must be the K-th of N parts, "
        f"1 <= K <= N, got '-1/2' (see fppo-jax {command} --help)\n"
    )


def test_a_flag_without_its_value_before_another_flag_is_still_missing_one(capsys):
    with pytest.raises(SystemExit):
        main(["tune", "--part", "--output", "x"])
    assert "argument --part: expected one argument" in capsys.readouterr().err
