"""fppo_jax.analysis.study_shapes: a task's groups merged per run shape, each arm's runs found in
the sweep that holds them, a shape's folder and protocol (the task's own shape where it was)."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from fppo_jax.analysis.study_runs import run_scores
from fppo_jax.analysis.study_shapes import (
    ShapedRuns,
    holding,
    merged,
    shape_folder,
    shape_of,
    shaped_protocol,
)
from fppo_jax.errors import InvalidInput
from fppo_jax.run.results import SweepResult
from fppo_jax.store.record import RunRecord

GROUPS = Path(__file__).parents[1] / "experiments/results/tuned/classic/study/cartpole"


def _in_epochs(result: SweepResult, epochs: int, variant: str) -> SweepResult:
    """`result`'s runs of `variant` alone, as if trained in `epochs` epochs."""
    index = [s["variant"] for s in result.settings].index(variant)
    runs = [i for i, run in enumerate(result.runs) if run["setting"] == index]
    return dataclasses.replace(
        result,
        config={**result.config, "num_epochs": epochs},
        settings=[result.settings[index]],
        runs=[{**result.runs[i], "setting": 0} for i in runs],
        metrics={name: values[runs] for name, values in result.metrics.items()},
        diverged=np.asarray(result.diverged)[runs],
    )


def test_groups_of_one_shape_merge_into_one_sweep_and_of_several_into_one_per_shape():
    first, second = (SweepResult.read(GROUPS / f"group-{k}") for k in (1, 2))
    assert isinstance(merged([first, second]), SweepResult)
    arms = [str(s["variant"]) for s in first.settings]
    candidate, baseline = arms[0], arms[-1]
    runs = merged([_in_epochs(first, 1, candidate), _in_epochs(first, 10, baseline)])
    assert isinstance(runs, ShapedRuns) and len(runs.parts) == 2
    assert holding(runs, candidate).config["num_epochs"] == 1
    for arm in (candidate, baseline):
        assert np.array_equal(run_scores(runs, arm, "final"), run_scores(first, arm, "final"))
    with pytest.raises(InvalidInput, match="no run of dpo is recorded here"):
        runs.of("dpo")


def test_a_shape_has_a_folder_and_a_protocol_of_its_own_and_the_tasks_own_has_neither():
    protocol = RunRecord.from_json(SweepResult.read(GROUPS / "group-1").config)
    assert shape_folder(()) == "" and shaped_protocol(protocol, ()) is protocol
    shape = shape_of({"learning_rate": 1e-3, "num_epochs": 1, "hidden_sizes": "16,16"})
    assert shape == (("hidden_sizes", "16,16"), ("num_epochs", 1))
    assert shape_folder(shape).startswith("shape-") and shape_folder(shape) == shape_folder(shape)
    assert shape_folder(shape) != shape_folder((("num_epochs", 1),))
    config = shaped_protocol(protocol, shape).config
    assert config.num_epochs == 1 and config.hidden_sizes == (16, 16)
