"""A tune's run-shape axes, task by task (:mod:`fppo_jax.core.shape_space`): which it searches
under its scheduler, each arm's space with them, the plan's record of them, and the task
prepared for a trial's shape."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import Any

from fppo_jax.analysis.population import Shape
from fppo_jax.core.search_space import SearchSpace
from fppo_jax.core.shape_space import (
    SHAPE_AXES,
    Choice,
    ChoiceAxis,
    config_values,
    configured,
    shape_space,
)
from fppo_jax.envs import Box
from fppo_jax.errors import InvalidInput
from fppo_jax.run.prepare import Prepared, prepare


def task_axes(
    prepared: Prepared, fixed: Mapping[str, object], given: Mapping[str, Any], scheduler: str
) -> dict[str, Choice]:
    """The run-shape axes searched on `prepared`'s task: racing's runs are whole, so it searches
    the default axes (less those the run's settings `fixed`, with a space file's `given` in
    their place); successive halving compares runs part-way, in updates of one shape, so it
    searches none and refuses those given."""
    shape_given = {name: value for name, value in given.items() if name in SHAPE_AXES}
    if scheduler == "halving" and shape_given:
        raise InvalidInput(
            f"successive halving ranks runs part-way, in updates of one run shape: the space's "
            f"{', '.join(shape_given)} needs scheduler racing (--scheduler racing), whose runs "
            "are whole, or one value given as a setting"
        )
    continuous = isinstance(prepared.trainer.env.action_space, Box)
    return shape_space(
        prepared.config, continuous, set(fixed), shape_given, searched=scheduler != "halving"
    )


def with_axes(
    spaces: Mapping[str, SearchSpace], axes: Mapping[str, Choice], prepared: Prepared
) -> dict[str, SearchSpace]:
    """Each arm's space on the task, with its run-shape `axes` and their values at trial 0 (the
    task's configured shape)."""
    default = {name: configured(prepared.config, name) for name in axes}
    return {
        arm: dataclasses.replace(space, shape=dict(axes), shape_default=default)
        for arm, space in spaces.items()
    }


def plan_record(axes: Mapping[str, Mapping[str, Choice]]) -> dict[str, dict[str, ChoiceAxis]]:
    """What ``tune.json`` records of the run-shape axes, per task (nothing where none is
    searched)."""
    return {
        task: {name: axis.to_json() for name, axis in searched.items()}
        for task, searched in axes.items()
        if searched
    }


def preparer(
    task: str,
    settings: Mapping[str, Any],
    total_steps: int | None,
    preset: str,
    backend: str,
) -> Callable[[Shape], Prepared]:
    """The task prepared for a trial's run shape: the tune's settings with its values."""

    def prepared(shape: Shape) -> Prepared:
        overrides = {**settings, **config_values(dict(shape))}
        return prepare(task, overrides, (), total_steps=total_steps, preset=preset, backend=backend)

    return prepared
