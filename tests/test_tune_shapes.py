"""fppo_jax.analysis.tune_shapes: racing searches the run's shape (each shape its own program,
whole runs), the plan records the axes per task, the chosen setting carries its shape; successive
halving, whose rungs stop runs part-way, refuses a searched shape by name before any compile."""

import json
import shutil

import numpy as np
import pytest
from conftest import TINY
from helpers import TUNE_RACE

from fppo_jax import load_study, study, tune
from fppo_jax.analysis.study_runs import run_scores
from fppo_jax.analysis.study_shapes import ShapedRuns
from fppo_jax.analysis.tune_shapes import plan_record, task_axes
from fppo_jax.errors import InvalidInput
from fppo_jax.run.prepare import prepare

# The tiny shape, less its epochs: the axis searched is the epochs, 10 (the paper's) or 1.
SHAPE = {k: v for k, v in TINY.items() if k != "num_epochs"}
FIXED = dict(SHAPE, hidden_sizes=(64, 64), normalize_observations=True)


def _prepared(**settings):
    return prepare("cartpole", settings, (), total_steps=1024, preset="paper", backend="auto")


def test_racing_searches_the_default_axes_that_the_settings_leave_free_and_halving_none():
    racing = task_axes(_prepared(**TINY), TINY, {}, "racing")
    assert set(racing) == {"hidden_sizes", "normalize_observations"}  # cartpole: discrete
    assert task_axes(_prepared(**TINY), TINY, {}, "halving") == {}
    with pytest.raises(InvalidInput, match=r"space's num_epochs needs scheduler racing"):
        task_axes(_prepared(**SHAPE), SHAPE, {"num_epochs": [10, 2]}, "halving")
    assert plan_record({"cartpole": racing, "acrobot": {}}) == {
        "cartpole": {
            "hidden_sizes": {"choices": ["64,64", "256,256"]},
            "normalize_observations": {"choices": [True, False]},
        }
    }


@pytest.fixture(scope="module")
def shaped_tune(tmp_path_factory):
    """A racing tune of PPO and FPPO-LP whose space searches the epochs, 10 or 1."""
    output = tmp_path_factory.mktemp("shaped") / "tune"
    found = tune(
        "cartpole",
        ["ppo", "fppo-lp"],
        output=output,
        trials=3,
        seeds=2,
        scheduler="racing",
        budget=2 * 3 * 2 + 2 * 4,
        total_steps=8 * 128,
        space={"num_epochs": [10, 1]},
        **TUNE_RACE,
        **FIXED,
    )
    return output, found


def test_a_racing_tune_trains_each_shape_whole_and_records_the_shape_it_chose(shaped_tune):
    output, found = shaped_tune
    assert found.plan["run_shape"] == {"cartpole": {"num_epochs": {"choices": [10, 1]}}}
    assert json.loads((output / "tune.json").read_text())["run_shape"] == found.plan["run_shape"]
    for arm in ("ppo", "fppo-lp"):
        results = found.results["cartpole"][arm]
        assert results["default"]["setting"]["num_epochs"] == 10  # trial 0: the configured
        assert {trial["num_epochs"] for trial in results["trials"]} <= {1, 10}
        assert "num_epochs" in results["chosen"]["setting"]
    # Every run of every round scored, whichever shape it trained.
    for rung in found.rungs["cartpole"]:
        for row in rung["arms"]["ppo"]["trials"]:
            assert all(score is not None for score in row["seed_scores"])
    assert "the run shape on cartpole: num_epochs {10, 1}" in (output / "report.md").read_text()


def test_a_study_trains_each_arm_in_the_shape_its_tune_chose(shaped_tune, tmp_path):
    output, _ = shaped_tune
    tuned = tmp_path / "tune"
    shutil.copytree(output, tuned)
    # Whatever the race chose, FPPO-LP here takes a setting of 1 epoch: its own run shape.
    results = json.loads((tuned / "results.json").read_text())
    results["cartpole"]["fppo-lp"]["chosen"]["setting"]["num_epochs"] = 1
    (tuned / "results.json").write_text(json.dumps(results))
    arguments = dict(max_seeds=4, group_size=2, progress=False, **FIXED)
    done = study("cartpole", "fppo-lp", "ppo", output=tmp_path / "s", tuned=tuned, **arguments)
    runs = done.results["cartpole"]
    assert isinstance(runs, ShapedRuns)
    assert (
        runs.of("fppo-lp").config["num_epochs"] == 1 and runs.of("ppo").config["num_epochs"] == 10
    )
    groups = json.loads((tmp_path / "s/decisions.json").read_text())["groups"]
    named = sorted((g["group"], json.dumps(g.get("shape"))) for g in groups)
    shaped = '{"num_epochs": 1}'
    assert named == [(1, "null"), (1, shaped), (2, "null"), (2, shaped)][: len(named)]
    loaded = load_study(tmp_path / "s")
    for arm in ("fppo-lp", "ppo"):
        assert np.array_equal(
            run_scores(loaded.results["cartpole"], arm, "final"), run_scores(runs, arm, "final")
        )


def test_a_halving_tune_refuses_a_searched_shape_before_any_plan(tmp_path):
    with pytest.raises(InvalidInput, match="successive halving ranks runs part-way"):
        tune(
            "cartpole",
            ["ppo"],
            output=tmp_path,
            trials=4,
            eta=2,
            seeds=2,
            total_steps=8 * 128,
            space={"num_epochs": [2, 1]},
            **TUNE_RACE,
            **SHAPE,
        )
    assert not (tmp_path / "tune.json").exists()
