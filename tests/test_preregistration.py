"""fppo_jax.analysis.preregistration: a plan written once, then held to field by field (naming
the field, inside a section too), the fields recorded only left aside; a plan's digest; the
folder locked from the plan's check to the call's end, an array task's let go at its share."""

import json

import pytest

from fppo_jax.analysis.preregistration import (
    Preregistered,
    check_plan,
    commit,
    plan_digest,
)
from fppo_jax.errors import InvalidInput, MissingFile
from fppo_jax.store.files import DirectoryBusy, DirectoryLock

PLAN = {"level": 0.05, "sampler": {"name": "qmc", "seed": 0}, "commit": "a" * 40}


def test_a_plan_is_written_once_then_held_to_naming_the_field(tmp_path):
    assert check_plan(tmp_path, PLAN, "a study", "plan.json") == PLAN
    assert json.loads((tmp_path / "plan.json").read_text()) == PLAN
    # Another commit goes on, under the plan as recorded.
    assert check_plan(tmp_path, {**PLAN, "commit": "b" * 40}, "a study", "plan.json") == PLAN
    with pytest.raises(InvalidInput, match=r"planned with level = 0\.05, not 0\.1"):
        check_plan(tmp_path, {**PLAN, "level": 0.1}, "a study", "plan.json")
    with pytest.raises(InvalidInput, match=r"planned with sampler\.seed = 0, not 1"):
        check_plan(
            tmp_path, {**PLAN, "sampler": {"name": "qmc", "seed": 1}}, "a study", "plan.json"
        )
    with pytest.raises(InvalidInput, match=r"planned with margin = none, not 0\.2"):
        check_plan(tmp_path, {**PLAN, "margin": 0.2}, "a study", "plan.json")


def test_fields_recorded_only_are_not_held_to(tmp_path):
    recorded = {**PLAN, "sampler": {**PLAN["sampler"], "package": "optuna 5.0.0"}}
    check_plan(tmp_path, recorded, "a tune", "tune.json")
    now = {**PLAN, "sampler": {**PLAN["sampler"], "package": "optuna 5.1.0"}}
    only = frozenset({"commit", "sampler.package"})
    assert check_plan(tmp_path, now, "a tune", "tune.json", only) == recorded
    with pytest.raises(InvalidInput, match=r"a tune planned with sampler\.package"):
        check_plan(tmp_path, now, "a tune", "tune.json")


def test_a_plan_that_is_not_an_object_is_named(tmp_path):
    (tmp_path / "plan.json").write_text("[1, 2]")
    with pytest.raises(InvalidInput, match=r"plan\.json: it holds no JSON object"):
        check_plan(tmp_path, PLAN, "a study", "plan.json")
    (tmp_path / "tune.json").write_text(json.dumps(PLAN)[:20])  # cut short
    with pytest.raises(
        InvalidInput, match=r"cannot read the plan .*tune\.json: Unterminated string"
    ):
        check_plan(tmp_path, PLAN, "a tune", "tune.json")


def test_a_plan_is_known_by_its_digest(tmp_path):
    with pytest.raises(MissingFile, match=r"holds no tune \(tune\.json is missing\)"):
        plan_digest(tmp_path / "tune.json", "tune")
    check_plan(tmp_path, PLAN, "a tune", "tune.json")
    first = plan_digest(tmp_path / "tune.json", "tune")
    assert len(first) == 64
    (tmp_path / "tune.json").write_text(json.dumps({**PLAN, "level": 0.1}))
    assert plan_digest(tmp_path / "tune.json", "tune") != first


def test_the_folder_is_locked_until_the_call_ends(tmp_path):
    with Preregistered(tmp_path, "a study") as folder:
        assert folder.check(PLAN, "plan.json", frozenset({"commit"})) == PLAN
        folder.share_out()  # not an array task's: the lock is kept
        with pytest.raises(DirectoryBusy, match="writing a study"):
            DirectoryLock(tmp_path, "a study")
    DirectoryLock(tmp_path, "a study").release()  # let go at the end


def test_an_array_task_lets_go_to_train_its_share(tmp_path):
    with Preregistered(tmp_path, "a tune", shared=True) as folder:
        with pytest.raises(DirectoryBusy):
            DirectoryLock(tmp_path, "a tune")
        folder.share_out()
        DirectoryLock(tmp_path, "a tune").release()


def test_the_commit_is_the_checkouts_or_unknown():
    found = commit()
    assert found == "unknown" or len(found) == 40


def test_a_folder_holding_another_kind_of_experiment_is_refused(tmp_path):
    (tmp_path / "plan.json").write_text("{}")
    with pytest.raises(InvalidInput, match=r"holds a study \(plan\.json\): a tune is written"):
        Preregistered(tmp_path, "a tune", apart_from={"plan.json": "a study"})
    assert not (tmp_path / ".lock").exists()  # refused before anything is written
