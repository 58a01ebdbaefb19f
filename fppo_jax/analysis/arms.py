"""What an experiment compares, named and checked once for every kind of experiment: its tasks
(each named once) and its arms (variants: a built-in's name, ``module:attribute`` or a
surrogate; each resolved, none twice, no two surrogates under one name)."""

from __future__ import annotations

from collections.abc import Sequence

from fppo_jax.core.objectives import union
from fppo_jax.core.resolution import resolve
from fppo_jax.core.surrogates import Surrogate
from fppo_jax.errors import InvalidInput

# An experiment's arms as given: one variant or several.
Variants = str | Surrogate | Sequence[str | Surrogate]


def names_of_tasks(tasks: str | Sequence[str], what: str) -> list[str]:
    """`tasks`, one name or several, checked: named, and each once (`what` is whose they are:
    "a study", "a tune")."""
    tasks = [tasks] if isinstance(tasks, str) else list(tasks)
    if not tasks or not all(isinstance(task, str) and task for task in tasks):
        raise InvalidInput(f"{what}'s tasks are named tasks (fppo-jax list), got {tasks!r}")
    if len(set(tasks)) < len(tasks):
        raise InvalidInput(f"a task is named twice among {', '.join(tasks)}")
    return tasks


def task_folder(task: str) -> str:
    """A task's folder in an experiment's: its name, a namespace's slash made a double
    underscore (``native/Hopper-v4`` in ``native__Hopper-v4/``)."""
    return task.replace("/", "__")


def resolve_arms(variants: Variants, what: str, role: str = "variant") -> list[Surrogate]:
    """`variants` resolved to their surrogates, in order: at least one, none named twice, and no
    two different surrogates under one name (`what` has them as its `role`s: "a tune"'s
    "variant"s, "a study"'s "candidate"s)."""
    listed = [variants] if isinstance(variants, str | Surrogate) else list(variants)
    arms = [resolve(v) for v in listed]
    if not arms:
        raise InvalidInput(f"{what} needs at least one {role}")
    union(arms)  # two different surrogates under one name are refused
    names = [arm.name for arm in arms]
    if len(set(names)) < len(names):
        raise InvalidInput(f"a {role} is named twice among {', '.join(names)}")
    return arms
