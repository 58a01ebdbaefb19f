"""fppo_jax.cli.tune_parser: the tune command's flags, the search's and the race's among them,
reach tune as its arguments; a value out of its choices is one line naming it."""

import pytest

from fppo_jax.cli.parser import build_parser


def test_the_race_and_the_search_are_flags_of_the_tune_command():
    args = build_parser().parse_args(
        "tune --variants ppo --tasks cartpole --output out --scheduler racing --budget 60 "
        "--finalists 2 --validation-seeds 8 --race-level 0.1 --score train".split()
    )
    assert (args.scheduler, args.budget, args.finalists) == ("racing", 60, 2)
    assert (args.validation_seeds, args.race_level, args.score) == (8, 0.1, "train")
    defaults = build_parser().parse_args("tune --variants ppo --tasks cartpole --output o".split())
    assert (defaults.scheduler, defaults.score, defaults.finalists) == ("halving", "eval", 3)
    assert (defaults.validation_seeds, defaults.budget) == (10, None)


def test_a_scheduler_out_of_its_choices_is_refused(capsys):
    with pytest.raises(SystemExit):
        build_parser().parse_args("tune --variants ppo --tasks c --output o --scheduler x".split())
    assert "invalid choice: 'x'" in capsys.readouterr().err
