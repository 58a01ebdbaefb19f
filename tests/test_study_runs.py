"""fppo_jax.analysis.study_runs: a look's group taken from its record only when whole, a run
that failed ranked below every other, and a group of another protocol refused before anything
trains."""

import json

import numpy as np
import pytest

import fppo_jax
from fppo_jax.analysis.study_runs import recorded_group, run_scores
from fppo_jax.run.results import SweepResult


def test_a_group_cut_short_is_not_taken_for_a_recorded_one(tmp_path, tiny):
    where = tmp_path / "group"
    fppo_jax.sweep("cartpole", {"variant": ["ppo"]}, [0, 1], total_steps=512, log_dir=where, **tiny)
    whole = SweepResult.read(where)
    ppo = fppo_jax.core.resolution.resolve("ppo")
    assert recorded_group(where, [ppo], [0, 1]) is not None
    cut = SweepResult(**{**whole.__dict__, "runs": whole.runs[:1], "diverged": whole.diverged[:1]})
    cut.metrics = {name: values[:1] for name, values in whole.metrics.items()}
    cut.write(tmp_path / "cut")
    assert recorded_group(tmp_path / "cut", [ppo], [0, 1]) is None
    with pytest.raises(ValueError, match="holds a group of ppo on seeds \\[0, 1\\], where"):
        recorded_group(where, [ppo], [0, 1, 2])
    # A run that failed ranks below every other.
    whole.diverged = np.array([3, 0])
    assert run_scores(whole, "ppo", "final")[0] == -np.inf


def test_a_group_of_another_protocol_is_refused_before_anything_trains(tmp_path, tiny):
    # As where a study planned with backend auto goes on on a machine that chooses another.
    output = tmp_path / "study"
    settings = {**tiny, "output": output, "total_steps": 512, "max_seeds": 2, "group_size": 1}
    fppo_jax.study("cartpole", "fppo-lp", "ppo", groups=1, **settings)
    record = output / "cartpole" / "group-1" / "sweep.json"
    written = json.loads(record.read_text())
    record.write_text(json.dumps({**written, "config": {**written["config"], "backend": "mjx"}}))
    with pytest.raises(
        ValueError, match=r'another protocol .*\(backend: "mjx" there, "gymnax" in this call\)'
    ):
        fppo_jax.study("cartpole", "fppo-lp", "ppo", **settings)
    assert not (output / "cartpole" / "group-2").exists()
