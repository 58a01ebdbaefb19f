"""Settings files (fppo_jax.cli.settings, --config FILE): a recorded run or sweep rerun from its
config.json with flags overriding it, its shape and preset kept, and a file read strictly."""

import json

import numpy as np
import pytest
from conftest import TINY_FLAGS

import fppo_jax.cli.commands
from fppo_jax import SweepResult
from fppo_jax.cli import main


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


def test_a_settings_file_that_is_a_directory_or_not_text_is_one_line(tmp_path, capsys):
    (tmp_path / "bytes.json").write_bytes(b"\xff\xfe")
    for path in (tmp_path, tmp_path / "bytes.json"):
        assert main(["train", "--config", str(path)]) == 2
        err = capsys.readouterr().err
        assert err.startswith(f"fppo-jax: error: {path} cannot be read as settings: ")
        assert len(err.splitlines()) == 1


def test_a_settings_file_that_is_not_there_is_named_in_one_line(tmp_path, capsys):
    assert main(["train", "--config", str(tmp_path / "nothere.yaml")]) == 2
    err = capsys.readouterr().err
    assert err == f"fppo-jax: error: settings file {tmp_path / 'nothere.yaml'} not found\n"
