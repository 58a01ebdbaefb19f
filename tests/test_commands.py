"""What each command does (fppo_jax.cli.commands): train writes its logs and summary, sweep,
table, compare and plot on its files, outputs checked before training, and a finished run
resumed."""

import csv
import errno
import json
import os

import pytest
from conftest import TINY_FLAGS
from helpers import sweep_by_hand

import fppo_jax.cli.commands
import fppo_jax.run.driver
import fppo_jax.store.files
from fppo_jax.cli import main


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


@pytest.mark.parametrize("variant", [":x", ".x:y", "x:"])
def test_a_variant_path_without_a_module_or_an_attribute_is_one_line(variant, capsys):
    assert main(["train", "--variant", variant, "--quiet"]) == 2
    expected = f"variant {variant!r}: expected module:attribute, such as my_pkg.mod:ppo_x"
    assert capsys.readouterr().err == f"fppo-jax: error: {expected}\n"
