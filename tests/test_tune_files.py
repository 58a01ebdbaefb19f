"""fppo_jax.analysis.tune_files: every recorded tune reads back through the public reader, each
file held to its shape; a file cut short, edited or missing is one error naming it."""

import json
import shutil
from pathlib import Path

import pytest

import fppo_jax
from fppo_jax.analysis.tune_files import load_tune, recorded_rungs, tune_digest
from fppo_jax.errors import InvalidInput, MissingFile
from fppo_jax.store.artifact import DamagedArtifact

TUNED = Path(__file__).resolve().parent.parent / "experiments" / "results" / "tuned"
TUNES = sorted(path.parent for path in TUNED.rglob("tune.json"))


@pytest.mark.parametrize("directory", TUNES, ids=lambda path: str(path.relative_to(TUNED)))
def test_every_recorded_tune_reads_through_the_public_reader(directory):
    tune = fppo_jax.load_tune(directory)
    assert tune.finished and tune.plan["tasks"] == list(tune.results) == list(tune.rungs)
    for task, rungs in tune.rungs.items():
        assert len(rungs) == len(tune.plan["budget"][task]["rungs"])
        for arm in tune.plan["variants"]:
            chosen = tune.results[task][arm]["chosen"]
            assert chosen is not None
            assert tune.chosen(task, arm) == chosen["setting"]
            assert chosen["trial"] in rungs[-1]["arms"][arm]["survivors"]


def _copy(tmp_path):
    copy = tmp_path / "tune"
    shutil.copytree(TUNES[0], copy, ignore=shutil.ignore_patterns("*.npz", "*.db", "*.png"))
    return copy


def test_a_file_cut_short_or_edited_is_named(tmp_path):
    copy = _copy(tmp_path)
    task = load_tune(copy).plan["tasks"][0]
    scores = copy / task / "rung-0" / "scores.json"
    scores.write_text(scores.read_text()[:100])
    with pytest.raises(DamagedArtifact, match=r"rung-0/scores\.json is not valid JSON"):
        load_tune(copy)
    with pytest.raises(DamagedArtifact, match=r"rung-0/scores\.json is not valid JSON"):
        recorded_rungs(copy / task)
    plan = json.loads((copy / "tune.json").read_text())
    del plan["trials"]
    (copy / "tune.json").write_text(json.dumps(plan))
    with pytest.raises(
        DamagedArtifact, match=r"tune\.json is not the tune's plan .*: \.trials: missing"
    ):
        load_tune(copy)


def test_a_folder_without_a_tune_or_unfinished(tmp_path):
    with pytest.raises(MissingFile, match=r"the tune's plan in .* is missing"):
        load_tune(tmp_path)
    with pytest.raises(MissingFile, match=r"holds no tune \(tune\.json is missing\)"):
        tune_digest(tmp_path)
    copy = _copy(tmp_path)
    (copy / "results.json").unlink()
    unfinished = load_tune(copy)
    assert not unfinished.finished and unfinished.results == {}
    task, arm = unfinished.plan["tasks"][0], unfinished.plan["variants"][0]
    with pytest.raises(InvalidInput, match=f"did not tune {arm} on {task}"):
        unfinished.chosen(task, arm)


@pytest.mark.parametrize(
    ("written", "message"),
    [
        ([], r"results\.json holds a list, not an object"),
        ({}, r"results\.json is not the tune's results .*: it lacks cartpole, acrobot, "),
        ("first task emptied", r"results\.json is .*: it lacks ppo on cartpole, spo on cartpole,"),
        ("one arm removed", r"results\.json is .*: it lacks spo on cartpole, which the plan tunes"),
    ],
)
def test_results_emptied_or_cut_are_named_not_read_as_a_tune_that_left_a_task_out(
    tmp_path, written, message
):
    copy = _copy(tmp_path)
    results = json.loads((copy / "results.json").read_text())
    assert list(results)[:2] == ["cartpole", "acrobot"] and list(results["cartpole"])[:2] == [
        "ppo",
        "spo",
    ]
    if written == "first task emptied":
        written = {**results, "cartpole": {}}
    elif written == "one arm removed":
        del results["cartpole"]["spo"]
        written = results
    (copy / "results.json").write_text(json.dumps(written))
    with pytest.raises(DamagedArtifact, match=message):
        load_tune(copy)  # as the study on its settings reads it


def test_results_cut_short_and_a_rung_of_another_shape_are_named(tmp_path):
    copy = _copy(tmp_path)
    results = copy / "results.json"
    results.write_text(results.read_text()[:100])
    with pytest.raises(DamagedArtifact, match=r"results\.json is not valid JSON"):
        load_tune(copy)
    copy = _copy(tmp_path / "again")
    task = load_tune(copy).plan["tasks"][0]
    (copy / task / "rung-0" / "scores.json").write_text('{"seconds": 1}')
    with pytest.raises(
        DamagedArtifact,
        match=r"rung-0/scores\.json is not a rung's scores as fppo-jax writes it: "
        r"\.arms: missing \(and 1 more\); restore it or remove it",
    ):
        recorded_rungs(copy / task)
