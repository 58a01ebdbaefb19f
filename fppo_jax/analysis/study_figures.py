"""A study's figures beside its ``report.md``: each task's learning curves, each comparison's
probability of improvement and, across tasks, performance profiles of normalised scores."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from fppo_jax.analysis.study_plan import DecisionRow, StudyPlan
from fppo_jax.analysis.study_report import normalised_scores
from fppo_jax.analysis.study_sections import Scores
from fppo_jax.analysis.study_shapes import ShapedRuns, TaskRuns
from fppo_jax.run.results import SweepResult
from fppo_jax.stats import statistics


def profile_label(endpoint: str, baseline: str) -> str:
    """The x-axis label of ``profiles.png``: in words, with no symbol (τ) that a user's
    hyperparameter of that name (``tau``) could be taken for."""
    return f"threshold on the normalised {endpoint} (1 = {baseline}'s IQM on the task)"


def arm_names(result: SweepResult) -> list[str] | None:
    """Each setting of a study's task by its variant alone, where that tells them apart: a
    tuned arm's every hyperparameter would overflow the legend, and the report lists them."""
    variants = [str(setting["variant"]) for setting in result.settings]
    return variants if len(set(variants)) == len(variants) else None


def write_figures(
    output: Path,
    plan: StudyPlan,
    rows: Sequence[DecisionRow],
    results: dict[str, TaskRuns],
    scores: dict[str, Scores],
) -> list[Path]:
    """In `output`: ``curves.png``, each task's learning curves (IQM over each setting's runs
    with a 95% bootstrap band), and ``improvement.png``, each comparison's probability of
    improvement on the primary endpoint over the runs its decision used, with the report's
    unadjusted 95% interval. Returns the paths written."""
    import matplotlib.pyplot as plt  # on first use: a study that writes no figure never waits

    from fppo_jax.analysis.plots import plot_curves, plot_improvement, plot_profiles

    tasks = [task for task in plan["tasks"] if task in results]
    if not tasks:
        return []
    figure, axes = plt.subplots(
        1, len(tasks), figsize=(6 * len(tasks), 4), squeeze=False, layout="constrained"
    )
    for ax, task in zip(axes[0], tasks, strict=True):
        runs = results[task]
        for part in runs.parts if isinstance(runs, ShapedRuns) else (runs,):
            plot_curves(part, band="iqm", names=arm_names(part), ax=ax)
    endpoint = plan["primary_endpoint"]
    improvements: dict[str, tuple[float, float, float]] = {}
    for row in rows:
        if row["task"] in scores:
            seeds, of_task = row["seeds"], scores[row["task"]]
            candidate = of_task[row["candidate"]][endpoint]
            reference = of_task[row["baseline"]][endpoint]
            compared = statistics.compare(candidate[:seeds], reference[:seeds])
            name = f"{row['candidate']}, {row['task']} ({seeds} seeds)"
            improvements[name] = compared["probability_of_improvement"]
    charts = {
        "curves.png": figure,
        "improvement.png": plot_improvement(improvements, plan["baseline"]),
    }
    normalised = normalised_scores(plan, scores) if len(scores) > 1 else {}
    if normalised:
        charts["profiles.png"] = plot_profiles(
            {v: np.concatenate(x) for v, x in normalised.items()},
            xlabel=profile_label(endpoint, plan["baseline"]),
        )
    paths = []
    for name, chart in charts.items():
        paths.append(output / name)
        chart.savefig(paths[-1], dpi=90)
        plt.close(chart)
    return paths
