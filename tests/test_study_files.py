"""fppo_jax.analysis.study_files: every recorded study reads back through the public reader,
its runs those its decisions used (its own groups, joined shares and runs taken from recorded
sweeps alike); a file cut short or a group missing is one error naming it."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

import fppo_jax
from fppo_jax.analysis.study_files import group_folder, load_study
from fppo_jax.analysis.study_runs import run_scores
from fppo_jax.errors import MissingFile
from fppo_jax.stats.rules import SequentialMannWhitney
from fppo_jax.stats.sequential import Design
from fppo_jax.store.artifact import DamagedArtifact

RESULTS = Path(__file__).resolve().parent.parent / "experiments" / "results"
STUDIES = sorted(path.parent for path in RESULTS.rglob("plan.json"))


@pytest.mark.parametrize("directory", STUDIES, ids=lambda path: str(path.relative_to(RESULTS)))
def test_every_recorded_study_reads_back_and_its_runs_give_its_decisions(directory):
    """Each recorded study's runs, read back, decide again as its decisions.json says: the
    reader gives the runs the study decided on, seed for seed."""
    study = fppo_jax.load_study(directory)
    assert study.plan["tasks"] == list(study.results)
    plan = study.plan
    design = Design(plan["group_size"], plan["max_seeds"], plan["level"], plan.get("margin"))
    scores = [
        tuple(
            run_scores(study.results[row["task"]], v, plan["primary_endpoint"])
            for v in (row["candidate"], row["baseline"])
        )
        for row in study.decisions
    ]
    decided = SequentialMannWhitney(design).decide(scores)
    assert [(d.decision or "undecided", d.seeds) for d in decided] == [
        (row["decision"], row["seeds"]) for row in study.decisions
    ]


def _copy(tmp_path, name="tuned/classic/study"):
    copy = tmp_path / "study"
    shutil.copytree(RESULTS / name, copy, ignore=shutil.ignore_patterns("*.png"))
    return copy


def test_a_file_cut_short_edited_or_missing_is_named(tmp_path):
    copy = _copy(tmp_path)
    decisions = copy / "decisions.json"
    recorded = json.loads(decisions.read_text())
    decisions.write_text(json.dumps({**recorded, "finished": "yes"}))
    with pytest.raises(DamagedArtifact, match=r"decisions\.json is not the study's decisions"):
        load_study(copy)
    decisions.write_text(json.dumps(recorded))
    shutil.rmtree(group_folder(copy, "cartpole", 2))
    with pytest.raises(MissingFile, match=r"cartpole/group-2 is missing"):
        load_study(copy)
    (copy / "plan.json").write_text((copy / "plan.json").read_text()[:50])
    with pytest.raises(DamagedArtifact, match=r"plan\.json is not valid JSON"):
        load_study(copy)
    with pytest.raises(MissingFile, match=r"holds no study \(plan\.json is missing\)"):
        load_study(tmp_path)


def test_a_study_before_its_first_look_has_its_plan_alone(tmp_path):
    copy = _copy(tmp_path)
    (copy / "decisions.json").unlink()
    study = load_study(copy)
    assert not study.finished and study.decisions == [] and study.results == {}
    assert study.plan["rule"]["id"] == "sequential-mann-whitney-holm"


def test_runs_taken_from_recorded_sweeps_are_read_from_them(tmp_path):
    study = load_study(RESULTS / "redecided" / "fppo-paper-classic")
    for task, result in study.results.items():
        seeds = sorted({run["seed"] for run in result.runs})
        assert seeds == list(range(max(row["seeds"] for row in study.decisions))), task
        assert np.isfinite(run_scores(result, "ppo", "final")).any()
