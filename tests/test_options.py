"""fppo_jax.run.options: each option declared once (its default, its check, its flag), and what a
callback's answer means."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from fppo_jax.cli import build_parser
from fppo_jax.cli.flags import _type_of, options
from fppo_jax.run.options import Options, callback_stops


@pytest.mark.parametrize(
    "settings, message",
    [
        ({"keep": 0}, "keep must be a positive integer, got 0"),
        ({"eval_episodes": 2.0}, "eval_episodes must be a positive integer, got 2.0"),
        ({"devices": True}, "devices must be a positive integer, got True"),
        ({"resume": 1}, "resume must be True or False, got 1"),
        ({"progress": "yes"}, "progress must be True, False or a callable"),
        ({"log_dir": 3}, "log_dir must be a path, got 3"),
        ({"checkpoint_dir": ""}, "checkpoint_dir is an empty path"),
        ({"resume": True}, "resume needs a checkpoint directory"),
        ({"checkpoint_every": 5}, "checkpoint_every needs a checkpoint directory"),
        ({"wandb_project": 7}, "wandb_project must be a name, got 7"),
        ({"checkpoint_dir": "runs/a", "log_dir": "runs/./a"}, "name the same directory"),
    ],
)
def test_each_option_is_checked_when_made(settings, message):
    with pytest.raises(ValueError, match=message):
        Options(**settings)


def test_split_takes_the_options_and_leaves_the_rest():
    options_, rest = Options.split({"keep": 5, "num_envs": 4, "learning_rate": 1e-3})
    assert options_ == Options(keep=5)
    assert rest == {"num_envs": 4, "learning_rate": 1e-3}


def test_every_flagged_option_has_its_flag_and_reads_back_as_the_option():
    parser = build_parser()
    for command in ("train", "sweep"):
        defaults = options(parser.parse_args([command]))
        # The command line shows progress unless --quiet; every other default is the field's.
        assert defaults == {
            **{f.name: f.default for f in Options.flagged()},
            "progress": True,
        }
        Options(**defaults)  # and they make valid options
    given = parser.parse_args(
        "train --quiet --output out --checkpoint-dir ck --resume --checkpoint-every 4 --keep 2 "
        "--eval-every 3 --eval-episodes 5 --wandb-project p --devices 1".split()
    )
    assert options(given) == {
        "progress": False,
        "log_dir": Path("out"),
        "checkpoint_dir": Path("ck"),
        "resume": True,
        "checkpoint_every": 4,
        "keep": 2,
        "eval_every": 3,
        "eval_episodes": 5,
        "wandb_project": "p",
        "devices": 1,
    }
    # Options that only Python can give (a callable) have no flag.
    assert {f.name for f in dataclasses.fields(Options)} - {f.name for f in Options.flagged()} == {
        "progress",
        "callback",
    }


def test_a_bad_flag_value_is_one_line_naming_the_flag(capsys):
    with pytest.raises(SystemExit):
        build_parser().parse_args(["train", "--keep", "0"])
    err = capsys.readouterr().err
    assert "argument --keep: the value must be a positive integer, got 0" in err
    assert len(err.strip().splitlines()) == 1


def test_a_field_of_a_type_without_a_flag_type_is_named():
    @dataclasses.dataclass
    class Odd:
        ratio: "complex" = 1j

    with pytest.raises(TypeError, match=r"Odd.ratio is a complex, which has no command-line"):
        _type_of(Odd, dataclasses.fields(Odd)[0])


def test_a_callbacks_answer_stops_on_false_alone():
    assert callback_stops(False) and callback_stops(np.bool_(False))
    assert (
        not callback_stops(True) and not callback_stops(None) and not callback_stops(np.bool_(True))
    )
    for answer in (0, "stop", np.array([True])):
        with pytest.raises(TypeError, match="the callback returned"):
            callback_stops(answer)
