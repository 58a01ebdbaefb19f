"""fppo_jax.analysis.study_plan: a plan written once, then held to field by field (naming the
field, inside a section too), the fields recorded only left aside, and the rule named in words
that no move of a module changes; every recorded study's plan and decisions of the shapes the
module gives them."""

import json
from pathlib import Path

import pytest
from helpers import mismatches

from fppo_jax.analysis.study_plan import EQUIVALENCE_TEST, TEST, Decisions, StudyPlan, check_plan
from fppo_jax.errors import InvalidInput

PLAN = {"level": 0.05, "sampler": {"name": "qmc", "seed": 0}, "commit": "a" * 40}


def test_a_plan_is_written_once_then_held_to_naming_the_field(tmp_path):
    assert check_plan(tmp_path, PLAN) == PLAN
    assert json.loads((tmp_path / "plan.json").read_text()) == PLAN
    # Another commit goes on, under the plan as recorded.
    assert check_plan(tmp_path, {**PLAN, "commit": "b" * 40}) == PLAN
    with pytest.raises(InvalidInput, match=r"planned with level = 0\.05, not 0\.1"):
        check_plan(tmp_path, {**PLAN, "level": 0.1})
    with pytest.raises(InvalidInput, match=r"planned with sampler\.seed = 0, not 1"):
        check_plan(tmp_path, {**PLAN, "sampler": {"name": "qmc", "seed": 1}})
    with pytest.raises(InvalidInput, match=r"planned with margin = none, not 0\.2"):
        check_plan(tmp_path, {**PLAN, "margin": 0.2})


def test_fields_recorded_only_are_not_held_to(tmp_path):
    recorded = {**PLAN, "sampler": {**PLAN["sampler"], "package": "optuna 5.0.0"}}
    check_plan(tmp_path, recorded, "a tune", "tune.json")
    now = {**PLAN, "sampler": {**PLAN["sampler"], "package": "optuna 5.1.0"}}
    only = frozenset({"commit", "sampler.package"})
    assert check_plan(tmp_path, now, "a tune", "tune.json", only) == recorded
    with pytest.raises(InvalidInput, match=r"a tune planned with sampler\.package"):
        check_plan(tmp_path, now, "a tune", "tune.json")


def test_the_rule_is_named_in_words_without_a_module():
    assert "fppo_jax" not in TEST and "fppo_jax" not in EQUIVALENCE_TEST


RESULTS = Path(__file__).resolve().parent.parent / "experiments" / "results"
STUDIES = sorted(path.parent for path in RESULTS.rglob("plan.json"))


def test_there_are_recorded_studies_to_check():
    assert len(STUDIES) >= 9, STUDIES


@pytest.mark.parametrize("study", STUDIES, ids=lambda path: str(path.relative_to(RESULTS)))
def test_a_recorded_study_holds_the_shapes_of_its_plan_and_decisions(study):
    assert mismatches(json.loads((study / "plan.json").read_text()), StudyPlan) == []
    decisions = study / "decisions.json"
    if decisions.exists():
        assert mismatches(json.loads(decisions.read_text()), Decisions) == []
