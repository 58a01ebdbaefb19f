"""fppo_jax.analysis.arms: tasks named once each, and arms resolved in order, none twice, the
refusal naming whose they are."""

import pytest

from fppo_jax.analysis.arms import names_of_tasks, resolve_arms, task_folder
from fppo_jax.errors import InvalidInput


def test_one_task_or_several_each_named_once():
    assert names_of_tasks("cartpole", "a tune") == ["cartpole"]
    assert names_of_tasks(("cartpole", "acrobot"), "a tune") == ["cartpole", "acrobot"]
    with pytest.raises(InvalidInput, match="a tune's tasks are named tasks"):
        names_of_tasks([], "a tune")
    with pytest.raises(InvalidInput, match="a study's tasks are named tasks"):
        names_of_tasks(["cartpole", ""], "a study")
    with pytest.raises(InvalidInput, match="a task is named twice among cartpole, cartpole"):
        names_of_tasks(["cartpole", "cartpole"], "a study")


def test_arms_resolved_in_order_none_twice():
    assert [arm.name for arm in resolve_arms("ppo", "a tune")] == ["ppo"]
    assert [arm.name for arm in resolve_arms(["fppo-lp", "ppo"], "a tune")] == ["fppo-lp", "ppo"]
    with pytest.raises(InvalidInput, match="a study needs at least one candidate"):
        resolve_arms([], "a study", "candidate")
    with pytest.raises(InvalidInput, match="a variant is named twice among ppo, ppo"):
        resolve_arms(["ppo", "ppo"], "a tune")
    with pytest.raises(InvalidInput, match="unknown variant"):
        resolve_arms(["ppo", "no-such-variant"], "a tune")


def test_a_namespaced_task_has_a_folder_of_one_level():
    assert task_folder("native/Hopper-v4") == "native__Hopper-v4"
    assert task_folder("cartpole") == "cartpole"
