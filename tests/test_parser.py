"""The command line's parser (fppo_jax.cli.parser): its commands and flags, an unknown one
refused in one line, its version, and help for every flag."""

import argparse
import re
import subprocess
import sys

import pytest

from fppo_jax.cli import build_parser, main


def test_unknown_variant_is_rejected_by_the_parser(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["train", "--variant", "sppo"])
    assert exit_info.value.code == 2
    assert "unknown variant 'sppo'; valid variants: ppo," in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv, error",
    [
        (["train", "--bogus", "1"], "fppo-jax train: error: unrecognized arguments: --bogus 1"),
        (["--bogus", "list"], "fppo-jax list: error: unrecognized arguments: --bogus"),
    ],
)
def test_an_unknown_flag_is_the_command_s_one_line_error(argv, error, capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2
    command = error.split(":")[0]
    assert capsys.readouterr().err == f"{error} (see {command} --help)\n"


def test_version_is_the_installed_package_s(capsys):
    from importlib import metadata

    import fppo_jax

    assert fppo_jax.__version__ == metadata.version("fppo-jax")
    with pytest.raises(SystemExit) as exit:
        main(["--version"])
    assert exit.value.code == 0
    assert capsys.readouterr().out == f"fppo-jax {fppo_jax.__version__}\n"


def test_help_documents_every_flag():
    train = build_parser()._subparsers._group_actions[0].choices["train"]
    text = train.format_help()
    shown = set(re.findall(r"(?<![\w-])--[\w-]+", text))  # whole flags: --k is not --keep's
    for action in train._actions:
        if action.option_strings and action.dest != "help":
            assert action.help and action.help != argparse.SUPPRESS, action.option_strings
    for flag in [
        "--env",
        "--variant",
        "--alpha",
        "--k",
        "--delta",
        "--epsilon",
        "--steps",
        "--seed",
        "--num-envs",
        "--num-steps",
        "--minibatches",
        "--epochs",
        "--hidden",
        "--learning-rate",
        "--gamma",
        "--gae-lambda",
        "--entropy-coef",
        "--value-coef",
        "--max-grad-norm",
        "--no-obs-norm",
        "--no-reward-norm",
        "--no-value-clip",
        "--anneal-lr",
        "--output",
        "--quiet",
        "--eval-every",
        "--eval-episodes",
        "--wandb-project",
    ]:
        assert flag in shown


def test_console_entry_point_lists_tasks_and_variants():
    out = subprocess.run(
        [sys.executable, "-m", "fppo_jax", "list"], capture_output=True, text=True, check=True
    )
    assert "cartpole" in out.stdout and "tr-ppo-rb" in out.stdout and "alpha 1.3" in out.stdout
    assert "swimmer      Swimmer: 1000-step episodes" in out.stdout
    assert "fppo-qp k 0.1" in out.stdout and "backends: mjx, native (Hopper-v3)" in out.stdout
    assert "auto       MJX where" in out.stdout and "native/" in out.stdout
    assert "massive    32,768 samples (2048 envs × 16 steps)" in out.stdout
    assert "gymnax/" in out.stdout and "playground/" in out.stdout
    assert "Failed to import" not in out.stdout + out.stderr
