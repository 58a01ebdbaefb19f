import argparse
import csv
import errno
import json
import os
import re
import subprocess
import sys

import numpy as np
import pytest
from helpers import sweep_by_hand

import fppo_jax.cli.commands
import fppo_jax.run.driver
import fppo_jax.store.files
import fppo_jax.store.metric_log
from fppo_jax import SweepResult
from fppo_jax.cli import build_parser, main
from fppo_jax.errors import InvalidInput, MissingFile, MissingPackage, NotEnoughMemory

TINY_FLAGS = ["--num-envs", "4", "--num-steps", "32", "--minibatches", "4", "--epochs", "2"]


def test_train_writes_metrics_config_and_summary(tmp_path, capsys):
    code = main(
        [
            "train",
            "--env",
            "cartpole",
            "--variant",
            "fppo-qp",
            "--k",
            "0.3",
            "--steps",
            "512",
            "--seed",
            "1",
            "--output",
            str(tmp_path),
            *TINY_FLAGS,
        ]
    )
    assert code == 0
    out, err = capsys.readouterr()
    assert "fppo-qp on cartpole (k = 0.3, epsilon = 0.2), seed 1" in out
    assert "compiling" in err and "update     4/4" in err and "steps/s" in err
    rows = list(csv.DictReader(open(tmp_path / "metrics.csv")))
    assert [int(r["env_steps"]) for r in rows] == [128, 256, 384, 512]
    config = json.loads((tmp_path / "config.json").read_text())
    assert config["variant"] == "fppo-qp" and config["k"] == 0.3 and config["num_envs"] == 4
    assert (tmp_path / "summary.txt").read_text().startswith("fppo-qp on cartpole")


def test_a_recorded_run_reruns_from_its_config_and_flags_override_it(tmp_path, capsys):
    first = ["train", "--variant", "fppo-qp", "--k", "0.3", "--steps", "512", "--seed", "1"]
    assert main([*first, *TINY_FLAGS, "--output", str(tmp_path / "a"), "--quiet"]) == 0
    config = str(tmp_path / "a" / "config.json")
    assert main(["train", "--config", config, "--output", str(tmp_path / "b"), "--quiet"]) == 0
    metrics = [(tmp_path / run / "metrics.csv").read_text() for run in ("a", "b")]
    assert metrics[0] == metrics[1]  # the same run again, bit for bit
    again = ["train", "--config", config, "--seed", "2", "--output", str(tmp_path / "c")]
    assert main([*again, "--quiet"]) == 0
    rerun = json.loads((tmp_path / "c" / "config.json").read_text())
    assert (rerun["seed"], rerun["k"], rerun["num_envs"]) == (2, 0.3, 4)
    capsys.readouterr()
    (tmp_path / "bad.yaml").write_text("env: cartpole\ncolour: 3\n")
    assert main(["train", "--config", str(tmp_path / "bad.yaml")]) == 2
    assert "bad.yaml: unknown setting colour; valid: alpha, " in capsys.readouterr().err


def test_a_recorded_sweep_reruns_from_its_config(tmp_path):
    # 8 runs, as the sweep of test_sweep_then_table_then_plot: the same compiled program.
    flags = ["sweep", "--variant", "ppo,fppo-qp", "--k", "0.2,0.3,0.4", "--seeds", "2"]
    flags += ["--steps", "256", *TINY_FLAGS, "--quiet"]
    assert main([*flags, "--output", str(tmp_path / "a")]) == 0
    config = str(tmp_path / "a" / "config.json")
    assert main(["sweep", "--config", config, "--output", str(tmp_path / "b"), "--quiet"]) == 0
    curves = [SweepResult.read(tmp_path / run) for run in ("a", "b")]
    assert curves[0].runs == curves[1].runs and len(curves[0].runs) == 8
    for name, values in curves[0].metrics.items():
        np.testing.assert_array_equal(values, curves[1].metrics[name], err_msg=name)


def test_out_of_range_hyperparameter_is_an_error_not_a_traceback(capsys):
    assert main(["train", "--variant", "fppo-lp", "--alpha", "0.5"]) == 2
    assert "error: alpha must be >= 1 for fppo-lp" in capsys.readouterr().err


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


def test_render_needs_a_picture_format_and_a_mujoco_task_before_training(
    tmp_path, capsys, monkeypatch
):
    monkeypatch.setattr(fppo_jax.run.driver, "compile_program", lambda *_: pytest.fail("compiled"))
    args = ["train", "--env", "cartpole", "--steps", "2048", "--quiet"]
    assert main([*args, "--render", str(tmp_path / "x.webm")]) == 2
    assert "a .gif (animation) or an .mp4 (video)" in capsys.readouterr().err
    for env in ("cartpole", "gymnax/Pendulum-v1"):
        assert main([*args, "--env", env, "--render", str(tmp_path / "x.png")]) == 2
        err = capsys.readouterr().err
        assert f"error: {env} is a classic (gymnax) task, which MuJoCo cannot render" in err


def test_outputs_that_cannot_be_written_are_refused_before_training(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(fppo_jax.run.driver, "compile_program", lambda *_: pytest.fail("compiled"))
    (tmp_path / "file").write_text("")
    under_a_file = tmp_path / "file" / "sub"
    for flag, path in [
        ("--output", under_a_file),
        ("--save-policy", under_a_file),
        ("--render", under_a_file / "hopper.gif"),
    ]:
        assert main(["train", "--quiet", flag, str(path)]) == 2
        assert f"cannot write to {under_a_file}: Not a directory" in capsys.readouterr().err
    assert main(["train", "--quiet", "--checkpoint-dir", str(under_a_file)]) == 2
    assert capsys.readouterr().err == (
        f"fppo-jax: error: cannot write to {under_a_file}: Not a directory\n"
    )
    read_only = tmp_path / "read-only"

    def refused(*_, dir, **__):
        raise OSError(errno.EROFS, os.strerror(errno.EROFS), dir)

    with monkeypatch.context() as m:  # as root, a directory's permissions refuse nothing
        m.setattr(fppo_jax.store.files.tempfile, "TemporaryFile", refused)
        for flag in ("--checkpoint-dir", "--output"):
            assert main(["train", "--quiet", flag, str(read_only)]) == 2
            error = capsys.readouterr().err
            assert error == f"fppo-jax: error: cannot write to {read_only}: Read-only file system\n"


def test_a_disk_that_fills_while_writing_is_one_line_naming_the_file(tmp_path, capsys, monkeypatch):
    def full(path, value):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))

    monkeypatch.setattr(fppo_jax.store.metric_log, "write_json", full)
    assert main(["train", "--quiet", *TINY_FLAGS, "--output", str(tmp_path)]) == 2
    error = capsys.readouterr().err
    assert error == f"fppo-jax: error: {tmp_path / 'config.json'}: No space left on device\n"


def test_an_os_error_that_names_no_file_is_not_taken_for_a_user_s_error(monkeypatch):
    def broken(*_):
        raise OSError("a bug, not a path")

    monkeypatch.setattr(fppo_jax.cli.commands, "COMMANDS", {"list": broken})
    with pytest.raises(OSError, match="a bug"):
        main(["list"])


@pytest.mark.parametrize("error", [ValueError, ImportError, MemoryError, ZeroDivisionError])
def test_a_built_in_error_from_inside_keeps_its_traceback(error, monkeypatch):
    def broken(*_):
        raise error("a bug deep inside")

    monkeypatch.setattr(fppo_jax.cli.commands, "COMMANDS", {"list": broken})
    with pytest.raises(error, match="a bug deep inside"):
        main(["list"])


@pytest.mark.parametrize("error", [InvalidInput, MissingPackage, MissingFile, NotEnoughMemory])
def test_a_project_error_is_one_line(error, monkeypatch, capsys):
    def refused(*_):
        raise error("what to do instead")

    monkeypatch.setattr(fppo_jax.cli.commands, "COMMANDS", {"list": refused})
    assert main(["list"]) == 2
    assert capsys.readouterr().err == "fppo-jax: error: what to do instead\n"


def test_sweep_then_table_then_plot(tmp_path, capsys):
    code = main(
        [
            "sweep",
            "--env",
            "cartpole",
            "--variant",
            "ppo,fppo-lp",
            "--alpha",
            "1.1:1.5:0.2",
            "--seeds",
            "2",
            "--steps",
            "256",
            "--quiet",
            "--output",
            str(tmp_path),
            *TINY_FLAGS,
        ]
    )
    assert code == 0
    out = capsys.readouterr().out
    assert "8 runs on cartpole" in out and "| fppo-lp α=1.3 |" in out
    rows = list(csv.DictReader(open(tmp_path / "curves.csv")))
    assert len(rows) == 8 * 2 and {r["variant"] for r in rows} == {"ppo", "fppo-lp"}
    assert main(["table", str(tmp_path)]) == 0
    assert len(capsys.readouterr().out.strip().splitlines()) == 2 + 4  # header, rule, 4 settings
    assert main(["table", str(tmp_path), "--stat", "iqm", "--endpoint", "auc", "--ci", "0.9"]) == 0
    assert "IQM of the auc score [90% CI]" in capsys.readouterr().out
    for given in (["--ci", "0.9"], ["--endpoint", "auc"], ["--endpoint", "max", "--ci", "0.5"]):
        assert main(["table", str(tmp_path), *given]) == 2
        error = capsys.readouterr().err
        assert error.startswith(f"fppo-jax: error: {given[0]}") and "--stat paper" in error
        assert "for --stat iqm or mean or median" in error
    assert main(["plot", str(tmp_path)]) == 0
    for name in ("curves.png", "ablation.png"):
        assert (tmp_path / name).read_bytes()[:4] == b"\x89PNG"


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


def test_table_prints_diverged_runs_and_refuses_a_damaged_file(tmp_path, capsys):
    sweep_by_hand().write(tmp_path)
    assert main(["table", str(tmp_path)]) == 0
    row = "| fppo-lp α=1.3 | 0 of 3 (3 diverged) | diverged at update 2 | – | – | – |"
    assert row in capsys.readouterr().out.splitlines()
    curves = tmp_path / "curves.csv"
    curves.write_text("".join(curves.read_text().splitlines(keepends=True)[:-1]))
    assert main(["table", str(tmp_path)]) == 2
    out, err = capsys.readouterr()
    assert out == ""
    assert err.startswith(f"fppo-jax: error: {curves}: run 8 has no update 3")  # cut short


def test_namespaced_environments_train_and_sweep_from_the_command_line(tmp_path, capsys):
    args = ["--env", "gymnax/Pendulum-v1", "--steps", "256", "--quiet", *TINY_FLAGS]
    assert main(["train", "--variant", "ppo", *args]) == 0
    assert "ppo on gymnax/Pendulum-v1" in capsys.readouterr().out
    assert main(["sweep", "--variant", "ppo", "--seeds", "2", *args]) == 0
    assert "2 runs on gymnax/Pendulum-v1" in capsys.readouterr().out
    assert main(["train", "--env", "nope/CartPole-v1", "--quiet"]) == 2
    assert "unknown environment 'nope/CartPole-v1'" in capsys.readouterr().err


def test_a_finished_run_resumed_keeps_its_saved_policy(tmp_path, capsys):
    flags = ["train", "--env", "cartpole", "--variant", "ppo", "--steps", "256", *TINY_FLAGS]
    flags += ["--checkpoint-dir", str(tmp_path / "ckpt"), "--save-policy", str(tmp_path / "p")]
    assert main(flags) == 0
    files = {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in (tmp_path / "p").iterdir()}
    capsys.readouterr()
    assert main([*flags, "--resume"]) == 0
    assert "kept " in capsys.readouterr().out
    assert {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in (tmp_path / "p").iterdir()} == (
        files
    )
    # Another run's policy is refused before compiling, resumed or not.
    other = [*flags, "--seed", "1", "--checkpoint-dir", str(tmp_path / "other"), "--resume"]
    assert main(other) == 2
    err = capsys.readouterr().err
    assert "already holds a saved policy" in err and "compiling" not in err


@pytest.mark.parametrize(
    "name, text, problem",
    [
        ("a.json", '{"quiet": "no"}', "a.json: quiet must be true or false, got 'no'"),
        (
            "b.json",
            '{"anneal_learning_rate": 0}',
            "anneal_learning_rate must be true or false, got 0",
        ),
        ("c.json", '{"quiet": null}', "c.json: quiet must be true or false, got None"),
        ("d.json", '{"seed": 1, "seed": 2}', "d.json cannot be read as settings: seed given "),
        ("e.yaml", "seed: 1\nseed: 2\n", "e.yaml cannot be read as settings: seed given "),
    ],
)
def test_a_settings_file_s_switches_and_keys_are_read_strictly(
    tmp_path, capsys, name, text, problem
):
    (tmp_path / name).write_text(text)
    assert main(["train", "--config", str(tmp_path / name)]) == 2
    assert problem in capsys.readouterr().err


def test_a_recorded_run_s_shape_and_another_preset_are_refused_not_mislabelled(
    tmp_path, capsys, monkeypatch
):
    paper = {"env": "cartpole", "preset": "paper", "num_envs": 8, "num_steps": 256}
    (tmp_path / "paper.json").write_text(json.dumps(paper))
    (tmp_path / "shape.json").write_text(json.dumps({"num_envs": 16}))
    (tmp_path / "massive.json").write_text(json.dumps({"preset": "massive"}))
    presets = []
    monkeypatch.setattr(
        fppo_jax.cli.commands, "COMMANDS", {"train": lambda args: presets.append(args.preset)}
    )
    for command in ("train", "sweep"):
        assert main([command, "--config", str(tmp_path / "paper.json"), "--preset", "massive"]) == 2
        error = capsys.readouterr().err
        assert error.startswith(f"fppo-jax: error: {tmp_path / 'paper.json'} records a run of the")
        assert "paper preset, with its run shape (num_envs=8, num_steps=256)" in error
        assert "override --preset massive" in error and "drop --preset" in error
    for config, given, preset in [
        ("paper.json", [], "paper"),  # rerun as recorded
        ("paper.json", ["--preset", "paper"], "paper"),
        ("shape.json", ["--preset", "massive"], "massive"),  # a shape of one's own over it
        ("shape.json", [], "paper"),
        ("massive.json", [], "massive"),
    ]:
        assert main(["train", "--config", str(tmp_path / config), *given]) is None
        assert presets.pop() == preset, config


@pytest.mark.parametrize("variant", [":x", ".x:y", "x:"])
def test_a_variant_path_without_a_module_or_an_attribute_is_one_line(variant, capsys):
    assert main(["train", "--variant", variant, "--quiet"]) == 2
    expected = f"variant {variant!r}: expected module:attribute, such as my_pkg.mod:ppo_x"
    assert capsys.readouterr().err == f"fppo-jax: error: {expected}\n"


def test_a_settings_file_that_is_a_directory_or_not_text_is_one_line(tmp_path, capsys):
    (tmp_path / "bytes.json").write_bytes(b"\xff\xfe")
    for path in (tmp_path, tmp_path / "bytes.json"):
        assert main(["train", "--config", str(path)]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"fppo-jax: error: {path} cannot be read as settings: ")
        assert len(err.splitlines()) == 1
