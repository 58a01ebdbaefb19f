"""fppo_jax.analysis.study_plan: the rule named by id and version, never by words or a module;
a plan that named it in words read as the same plan; every recorded study's plan and decisions
of the shapes the module gives them, its rule one this code decides by."""

import json
from pathlib import Path

import pytest

from fppo_jax.analysis.preregistration import check_plan
from fppo_jax.analysis.study_plan import (
    LEGACY_WORDS,
    Decisions,
    StudyPlan,
    rule_of_plan,
    upgraded,
)
from fppo_jax.errors import InvalidInput
from fppo_jax.store.shapes import mismatches

LEGACY = {"tasks": ["cartpole"], "test": LEGACY_WORDS["test"], "level": 0.05, "margin": 0.2}
LEGACY |= {"equivalence_test": LEGACY_WORDS["equivalence_test"], "group_size": 5}
LEGACY |= {"max_seeds": 10, "commit": "a" * 40}
RULE = {"id": "sequential-mann-whitney-holm", "version": 1}


def test_a_plan_that_named_its_rule_in_words_goes_on_under_its_id(tmp_path):
    now = upgraded(LEGACY)
    assert list(now) == ["tasks", "rule", "level", "margin", "group_size", "max_seeds", "commit"]
    assert now["rule"] == RULE and upgraded(now) == now
    (tmp_path / "plan.json").write_text(json.dumps(LEGACY))
    assert check_plan(tmp_path, now, "a study", "plan.json", upgrade=upgraded) == now
    with pytest.raises(InvalidInput, match=r"planned with test = \"two-sided"):
        check_plan(tmp_path, now, "a study", "plan.json")  # read without the upgrade
    with pytest.raises(InvalidInput, match="names its rule \\(test\\) in words this fppo-jax"):
        upgraded({**LEGACY, "test": "a t-test"})


def test_the_plans_rule_is_one_this_code_decides_by():
    rule = rule_of_plan(upgraded(LEGACY))
    assert (rule.design.group_size, rule.design.max_seeds, rule.design.margin) == (5, 10, 0.2)
    assert "fppo_jax" not in rule.words and "fppo_jax" not in (rule.equivalence_words or "")
    with pytest.raises(InvalidInput, match="the rule 'permutation', which this fppo-jax does"):
        rule_of_plan({**upgraded(LEGACY), "rule": {"id": "permutation", "version": 1}})


RESULTS = Path(__file__).resolve().parent.parent / "experiments" / "results"
STUDIES = sorted(path.parent for path in RESULTS.rglob("plan.json"))


def test_there_are_recorded_studies_to_check():
    assert len(STUDIES) >= 9, STUDIES


@pytest.mark.parametrize("study", STUDIES, ids=lambda path: str(path.relative_to(RESULTS)))
def test_a_recorded_study_holds_the_shapes_of_its_plan_and_decisions(study):
    plan = json.loads((study / "plan.json").read_text())
    assert mismatches(plan, StudyPlan) == []
    assert rule_of_plan(plan).id == plan["rule"]["id"]
    decisions = study / "decisions.json"
    if decisions.exists():
        assert mismatches(json.loads(decisions.read_text()), Decisions) == []
