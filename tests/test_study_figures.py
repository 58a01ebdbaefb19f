"""A study's figures (fppo_jax.analysis.study_figures): each task's learning curves and each
comparison's probability of improvement, and across tasks the performance profiles, drawn
only where every task's scores can be normalised."""

import dataclasses

import numpy as np
from helpers import two_settings
from PIL import Image

from fppo_jax.analysis.study_figures import arm_names, profile_label, write_figures

PLAN = {"tasks": ["a", "b", "c"], "candidates": ["fppo-lp"], "baseline": "ppo"}
PLAN["primary_endpoint"] = "final"


def task_scores(result) -> dict:
    """A task's scores as a study holds them, from a sweep of PPO and FPPO-LP over 8 seeds."""
    final = result.metrics["average_return"][:, -1]
    return {
        v: {"final": final[i * 8 : (i + 1) * 8], "start": np.zeros(8)}
        for i, v in enumerate(["ppo", "fppo-lp"])
    }


def test_curves_improvements_and_profiles_are_written_for_the_tasks_with_runs(tmp_path):
    results = {"a": two_settings(), "b": two_settings(shift=-3.0)}  # c: nothing recorded yet
    scores = {task: task_scores(result) for task, result in results.items()}
    rows = [{"task": t, "candidate": "fppo-lp", "baseline": "ppo", "seeds": 8} for t in "abc"]
    paths = write_figures(tmp_path, PLAN, rows, results, scores)
    assert [p.name for p in paths] == ["curves.png", "improvement.png", "profiles.png"]
    width, _ = Image.open(tmp_path / "curves.png").size
    assert width == 2 * 6 * 90  # a panel of 6 inches per task with runs, at 90 dpi
    assert all(p.read_bytes().startswith(b"\x89PNG") for p in paths)

    # One task: nothing across tasks to profile. None: no figure at all.
    one = write_figures(tmp_path, PLAN, rows, {"a": results["a"]}, {"a": scores["a"]})
    assert [p.name for p in one] == ["curves.png", "improvement.png"]
    assert write_figures(tmp_path, PLAN, rows, {}, {}) == []
    # Where a task's baseline ends at its start, the scale is undefined: no profiles.
    flat = {v: {**x, "start": np.full(8, 1e6)} for v, x in scores["b"].items()}
    both = write_figures(tmp_path, PLAN, rows, results, {"a": scores["a"], "b": flat})
    assert [p.name for p in both] == ["curves.png", "improvement.png"]


def test_a_tasks_curves_are_named_by_their_arms_where_the_variants_tell_them_apart():
    tuned = two_settings()
    tuned.settings = [
        {"variant": "ppo", "learning_rate": 3.4e-4, "gamma": 0.9948, "gae_lambda": 0.9927},
        {"variant": "fppo-lp", "alpha": 1.3, "learning_rate": 1.0e-4, "gamma": 0.9971},
    ]
    assert arm_names(tuned) == ["ppo", "fppo-lp"]
    # Two settings of one variant: its hyperparameters are what tells them apart.
    alphas = [{"variant": "fppo-lp", "alpha": a} for a in (1.3, 2.0)]
    same = dataclasses.replace(tuned, settings=alphas)
    assert arm_names(same) is None


def test_the_profiles_axis_is_named_in_words():
    label = profile_label("final", "ppo")
    assert label == "threshold on the normalised final (1 = ppo's IQM on the task)"
