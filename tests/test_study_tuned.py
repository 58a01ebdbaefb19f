"""fppo_jax.analysis.study_tuned: a study takes a tune's settings only from a finished tune."""

import pytest
from helpers import TUNE_ARMS as ARMS
from helpers import TUNE_SMALL as SMALL

from fppo_jax.analysis.studies import study
from fppo_jax.analysis.study_files import load_study
from fppo_jax.analysis.tune_files import load_tune, tune_digest
from fppo_jax.analysis.tuning import tune
from fppo_jax.errors import InvalidInput


def test_a_tune_not_finished_is_no_source_of_settings(tmp_path):
    tune("cartpole", ARMS, output=tmp_path / "tune", rungs=0, **SMALL)
    with pytest.raises(InvalidInput, match="not finished"):
        study("cartpole", "fppo-lp", "ppo", output=tmp_path / "s", tuned=tmp_path / "tune")
    # Its plan's path names the tune too; its folder is no study's.
    with pytest.raises(InvalidInput, match="not finished"):
        study("cartpole", "fppo-lp", output=tmp_path / "s", tuned=tmp_path / "tune/tune.json")
    with pytest.raises(InvalidInput, match=r"holds a tune \(tune\.json\): a study is written"):
        study("cartpole", "fppo-lp", output=tmp_path / "tune")


def test_a_surrogate_edited_since_its_tune_is_refused_before_any_run(tmp_path):
    from own_surrogates import clipped, my_ppo

    import fppo_jax

    tune("cartpole", ["ppo", my_ppo], output=tmp_path / "tune", rungs=0, **SMALL)

    def edited(ratio, advantage, epsilon):
        return 2 * clipped(ratio, advantage, epsilon)

    changed = fppo_jax.surrogate("my-ppo", edited)
    with pytest.raises(InvalidInput, match=r"tuned another my-ppo than this code's \(digest '"):
        study("cartpole", changed, "ppo", output=tmp_path / "s", tuned=tmp_path / "tune")
    assert not (tmp_path / "s").exists()
    # The same surrogate passes this check, and stops at the tune not finished.
    with pytest.raises(InvalidInput, match="not finished"):
        study("cartpole", my_ppo, "ppo", output=tmp_path / "s", tuned=tmp_path / "tune")


def test_study_tune_tunes_races_and_decides_in_one_command_and_one_folder(tmp_path, capsys):
    from conftest import TINY_FLAGS

    from fppo_jax.cli import main

    flags = ["study", "--tune", "--tasks", "cartpole", "--candidates", "fppo-lp"]
    flags += ["--trials", "4", "--eta", "2", "--finalists", "1", "--validation-seeds", "4"]
    flags += ["--race-level", "0.1", "--max-seeds", "4"]
    flags += ["--group-size", "4", "--endpoint", "eval", "--eval-every", "8"]
    flags += ["--eval-episodes", "5", "--steps", "1024", *TINY_FLAGS, "--quiet"]
    assert main([*flags, "--output", str(tmp_path)]) == 0
    assert "cartpole: fppo-lp against ppo:" in capsys.readouterr().out
    tuned = load_tune(tmp_path / "tune")
    assert tuned.finished and "5 evaluation episodes" in tuned.plan["score"]
    assert tuned.rungs["cartpole"][-1]["arms"]["ppo"]["trials"][0]["trial"] == 0  # the race
    plan = load_study(tmp_path).plan
    assert plan["tuned"]["plan_digest"] == tune_digest(tmp_path / "tune")
    chosen = {arm: tuned.chosen("cartpole", arm) for arm in ARMS}
    assert plan["tuned"]["settings"]["cartpole"] == chosen
    # The tune's validation seeds, like its tuning seeds, are kept out of the test's.
    assert min(tuned.plan["validation"]["seeds"]) >= 2_000_000


def test_study_tune_refuses_what_it_sets_itself(tmp_path):
    with pytest.raises(InvalidInput, match="not beside tuned"):
        study("cartpole", "fppo-lp", output=tmp_path, tune={}, tuned=tmp_path / "t")
    with pytest.raises(InvalidInput, match="decides on eval or final, where the tune scores"):
        study("cartpole", "fppo-lp", output=tmp_path, tune={}, endpoint="auc")
    with pytest.raises(InvalidInput, match="sets the tune's score itself"):
        study("cartpole", "fppo-lp", output=tmp_path, tune={"score": "train"})
