"""Every recorded tune's files hold the shapes ``tuning_records`` gives them: each key a type
requires is there, no key is one the type lacks, and each value is of its key's type, all the
way down. A shape that drifted from what the tune writes fails here."""

import json
from pathlib import Path

import pytest

from fppo_jax.analysis.tuning_records import ArmResults, RungScores, ShareScores, TunePlan
from fppo_jax.store.shapes import mismatches

TUNED = Path(__file__).resolve().parent.parent / "experiments" / "results" / "tuned"
TUNES = sorted(path.parent for path in TUNED.rglob("tune.json"))


def test_there_are_recorded_tunes_to_check():
    assert len(TUNES) >= 2, TUNES


@pytest.mark.parametrize("tune", TUNES, ids=lambda path: str(path.relative_to(TUNED)))
def test_a_recorded_tune_holds_its_files_shapes(tune):
    plan = json.loads((tune / "tune.json").read_text())
    assert mismatches(plan, TunePlan) == []
    results = json.loads((tune / "results.json").read_text())
    assert mismatches(results, dict[str, dict[str, ArmResults]]) == []
    rungs = sorted(tune.glob("*/rung-*/scores.json"))
    assert rungs
    for path in rungs:
        assert mismatches(json.loads(path.read_text()), RungScores) == [], path
    for path in tune.glob("*/rung-*/part-*/scores.json"):
        assert mismatches(json.loads(path.read_text()), ShareScores) == [], path


def test_a_key_missing_added_or_of_another_type_is_named():
    plan = json.loads((TUNES[0] / "tune.json").read_text())
    assert mismatches(plan, TunePlan) == []
    del plan["trials"]
    plan["extra"] = 1
    plan["budget"][plan["tasks"][0]]["rungs"][0]["trials"] = "nine"
    assert sorted(mismatches(plan, TunePlan)) == [
        f".budget.{plan['tasks'][0]}.rungs[0].trials: 'nine' is not int",
        ".extra: not in TunePlan",
        ".trials: missing",
    ]
