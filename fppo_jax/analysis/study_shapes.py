"""A study whose arms train in run shapes of their own, as a tune chose them
(:mod:`fppo_jax.core.shape_space`): each task's arms are grouped by shape, and each shape's
group of seeds at a look is a sweep of its own, in ``<task>/<shape folder>/group-<k>/`` (the
task's own shape where its groups always were); a task's runs are merged per shape
(:class:`ShapedRuns`), and the rule reads each arm's runs in the sweep that holds them."""

from __future__ import annotations

import dataclasses
import hashlib
import json
from collections.abc import Mapping, Sequence
from typing import Any

from fppo_jax.core.config import Setting
from fppo_jax.core.shape_space import SHAPE_AXES, ChoiceValue, config_values, split_setting
from fppo_jax.errors import InvalidInput
from fppo_jax.run.merge import merge
from fppo_jax.run.results import SweepResult
from fppo_jax.store.record import RunRecord

# A run shape as a key: its values by name, sorted (empty: the task's own).
Shape = tuple[tuple[str, ChoiceValue], ...]


def shape_of(setting: Mapping[str, Any] | None) -> Shape:
    """The run-shape values of a setting (a tune's chosen one), as a key."""
    return tuple(sorted(split_setting(setting or {})[1].items()))


def shape_folder(shape: Shape) -> str:
    """The folder of a shape's groups within its task's: none for the task's own shape, else
    ``shape-`` and a digest of its values (the decisions name the values)."""
    if not shape:
        return ""
    text = json.dumps(dict(shape), sort_keys=True)
    return "shape-" + hashlib.sha256(text.encode()).hexdigest()[:10]


def shaped_protocol(protocol: RunRecord, shape: Shape) -> RunRecord:
    """The protocol of a task's runs in run shape `shape`."""
    if not shape:
        return protocol
    config = dataclasses.replace(protocol.config, **config_values(dict(shape)))
    return dataclasses.replace(protocol, config=config)


@dataclasses.dataclass(frozen=True)
class ShapedRuns:
    """A task's runs in several run shapes: one sweep per shape (merged over its groups)."""

    parts: tuple[SweepResult, ...]

    @property
    def settings(self) -> list[Setting]:
        return [setting for part in self.parts for setting in part.settings]

    def of(self, variant: str) -> SweepResult:
        """The sweep that holds `variant`'s runs."""
        for part in self.parts:
            if variant in [setting["variant"] for setting in part.settings]:
                return part
        raise InvalidInput(f"no run of {variant} is recorded here")


# A task's runs in a study: one sweep, or one per run shape where its arms train in several.
TaskRuns = SweepResult | ShapedRuns


def holding(runs: TaskRuns, variant: str) -> SweepResult:
    """The sweep of `runs` that holds `variant`'s runs."""
    return runs.of(variant) if isinstance(runs, ShapedRuns) else runs


def merged(parts: Sequence[SweepResult]) -> TaskRuns:
    """`parts` (a task's groups) merged per run shape: one sweep where they share one."""
    by_shape: dict[str, list[SweepResult]] = {}
    for part in parts:
        key = json.dumps([part.config.get(name) for name in SHAPE_AXES])
        by_shape.setdefault(key, []).append(part)
    if len(by_shape) == 1:
        return merge(parts)
    return ShapedRuns(tuple(merge(same) for same in by_shape.values()))


def shape_record(shape: Shape) -> dict[str, ChoiceValue]:
    """A shape as ``decisions.json`` names a group's."""
    return dict(shape)
