"""Runs recorded elsewhere that a study takes instead of training them (fppo_jax.analysis.reuse):
taken whole, under the same protocol and setting only, said in the report, and a directory
that holds none refused before any plan."""

import dataclasses
import json

import numpy as np
import pytest
from own_surrogates import frozen

import fppo_jax
from fppo_jax.analysis.reuse import Pool
from fppo_jax.analysis.study_runs import run_scores
from fppo_jax.run.results import SweepResult
from fppo_jax.store.record import RunRecord

# As tests/test_studies.py's: PPO learns CartPole in this budget, eight runs per compiled call.
BUDGET = {"total_steps": 4096, "learning_rate": 0.003, "chunk": 8}


def test_a_study_takes_the_baseline_s_recorded_runs_instead_of_training_them(tmp_path, tiny):
    pool = tmp_path / "recorded" / "ppo-part"  # as a seed study records PPO's runs
    fppo_jax.sweep("cartpole", {"variant": ["ppo"]}, seeds=16, log_dir=pool, **tiny, **BUDGET)
    output = tmp_path / "study"
    settings = {**tiny, **BUDGET, "output": output, "max_seeds": 16, "group_size": 8}
    done = fppo_jax.study("cartpole", [frozen, "fppo-lp"], "ppo", reuse=pool.parent, **settings)

    assert done.finished and json.loads((output / "plan.json").read_text())["reuse"] == [
        str(pool.parent)
    ]
    group_1 = SweepResult.read(output / "cartpole" / "group-1")
    assert [s["variant"] for s in group_1.settings] == ["frozen", "fppo-lp"]  # no PPO trained
    groups = json.loads((output / "decisions.json").read_text())["groups"]
    assert [(g["group"], g["seeds"][0], g["reused"]) for g in groups] == [
        (1, 0, {"ppo": [str(pool)]}),
        (2, 8, {"ppo": [str(pool)]}),
    ]
    assert all(len(g["commit"]) == 40 for g in groups)  # and the candidates were trained
    recorded = SweepResult.read(pool)
    for endpoint in ("final", "auc"):  # the baseline's scores are the recorded runs'
        np.testing.assert_array_equal(
            run_scores(done.results["cartpole"], "ppo", endpoint),
            run_scores(recorded, "ppo", endpoint),
        )
    report = (output / "report.md").read_text()
    assert "were taken instead of trained" in report
    # Runs recorded before the plan: it says what it preregistered and what it did not.
    assert "Planned in plan.json before any run it trained (commit" in report
    assert "for them the plan is no preregistration" in report
    again = fppo_jax.study("cartpole", [frozen, "fppo-lp"], "ppo", reuse=pool.parent, **settings)
    assert again.decisions == done.decisions  # resumed: nothing trained, nothing taken anew
    with pytest.raises(ValueError, match="planned with reuse = "):
        fppo_jax.study("cartpole", [frozen, "fppo-lp"], "ppo", **settings)

    # Taken only whole, and only under the same protocol and setting.
    taken = Pool.read([pool.parent])
    protocol = RunRecord.from_json(recorded.config).protocol()
    ppo = recorded.settings[0]
    assert taken.take(protocol, ppo, None, list(range(8, 16))).sources == [pool]
    assert taken.take(protocol, ppo, None, list(range(10, 18))) is None  # seeds 16, 17 missing
    wider = dataclasses.replace(protocol.config, num_envs=8)
    assert taken.take(dataclasses.replace(protocol, config=wider), ppo, None, [0]) is None
    assert taken.take(protocol, {**ppo, "learning_rate": 0.001}, None, [0]) is None
    with pytest.raises(FileNotFoundError, match="no directory of recorded sweeps to reuse"):
        Pool.read([tmp_path / "nowhere"])
    elsewhere = tmp_path / "another-study"  # a mistyped directory is refused before any plan
    with pytest.raises(FileNotFoundError, match="no directory of recorded sweeps to reuse"):
        fppo_jax.study(
            "cartpole",
            frozen,
            "ppo",
            reuse=tmp_path / "nowhere",
            **{**settings, "output": elsewhere},
        )
    assert not elsewhere.exists()
