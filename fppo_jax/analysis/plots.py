"""Figures: every variant's surrogate and slope against the ratio (the paper's Figs. 1 and 3), a
sweep's learning curves (Figs. 4–5) and α/k chart (Fig. 6), the escape-speed chart, a tune's
tuning curves, and the comparisons of :mod:`fppo_jax.stats.statistics` (performance profiles,
probabilities of improvement).

Each function draws on the Axes it is given, or on a new figure, and returns the figure. Saving
is the caller's (``fig.savefig``); :func:`plot_sweep` does it for a sweep's directory. No
backend is chosen here: a notebook shows the figures inline, and a process without a display
falls back to Agg.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, cast

import jax
import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.ticker import EngFormatter, MaxNLocator, PercentFormatter

from fppo_jax.analysis.tuning_records import ArmResults, RaceRecord
from fppo_jax.core.resolution import VARIANT_SPECIFIC, objective
from fppo_jax.core.variants import EPSILON, VARIANTS
from fppo_jax.errors import InvalidInput
from fppo_jax.run.results import SweepResult, labels, max_average_return, nanmean
from fppo_jax.stats import statistics

# The settings a sweep's charts are drawn against, where they vary, in this order.
SWEPT = (*VARIANT_SPECIFIC, "epsilon", "learning_rate")
IN_NEGATIVE_REGIONS = "share of the batch in R+ ∪ R-"
YLABELS = {
    "average_return": "average return (last 100 episodes)",
    "negative_fraction_before": f"{IN_NEGATIVE_REGIONS}, first epoch",
    "negative_fraction_after": f"{IN_NEGATIVE_REGIONS}, after the update",
    "clip_fraction": "clip fraction",
}
FRACTIONS = ("clip_fraction", "negative_fraction_before", "negative_fraction_after")


def plot_objective(
    advantage: float = 1.0,
    *,
    slope: bool = False,
    variants: Sequence[str] = VARIANTS,
    epsilon: float = EPSILON,
    ax: Axes | None = None,
) -> Figure:
    """Each variant's surrogate L(r, A), or its slope ∂L/∂r (by `jax.grad`), against the ratio r
    for one advantage, from :func:`fppo_jax.objective` with the paper's hyperparameters; R+
    (A > 0) or R- (A < 0) shaded."""
    ax = _axes(ax, (5.5, 3.5))
    ratio = jnp.linspace(1 - 2.5 * epsilon, 1 + 2.5 * epsilon, 401)
    for i, variant in enumerate(variants):
        curve = _curve(ratio, jnp.float32(advantage), variant, epsilon, slope)
        # Where variants coincide, the first (PPO, the reference) stays in sight.
        ax.plot(ratio, curve, label=variant, zorder=2 + len(variants) - i)
    if advantage > 0:
        ax.axvspan(ratio[0], 1 - epsilon, color="grey", alpha=0.15, lw=0)  # type: ignore[arg-type]  # matplotlib takes array scalars
        where = "A > 0 (R+ shaded)"
    else:
        ax.axvspan(1 + epsilon, ratio[-1], color="grey", alpha=0.15, lw=0)  # type: ignore[arg-type]  # as above
        where = "A < 0 (R- shaded)"
    ax.set(xlabel="ratio r", ylabel="∂L/∂r" if slope else f"L(r, A = {advantage:+g})")
    ax.set_title(f"{'slope' if slope else 'surrogate'}, {where}")
    ax.legend(fontsize="small")
    ax.grid(alpha=0.3)
    return cast(Figure, ax.figure)


@functools.partial(jax.jit, static_argnums=(2, 3, 4))
def _curve(
    ratio: jax.Array, advantage: jax.Array, variant: str, epsilon: float, slope: bool
) -> jax.Array:
    """L(r, A) for one variant at each ratio, or its slope ∂L/∂r: one compiled program per
    variant and kind (drawn op by op, each of its dozens of operations compiled on its own)."""
    f = objective(variant, epsilon=epsilon)

    def value(r: jax.Array) -> jax.Array:
        # The trust-region variants gate on KL(π_old ‖ π_θ); drawn against the ratio alone, the
        # per-sample estimate (r − 1) − log r stands in for it.
        return f(r, advantage, kl=(r - 1) - jnp.log(r))

    return jax.vmap(jax.grad(value) if slope else value)(ratio)


def plot_objectives(
    variants: Sequence[str] = VARIANTS, *, epsilon: float = EPSILON, axes: np.ndarray | None = None
) -> Figure:
    """The paper's Figs. 1 and 3 together: surrogates (left) and slopes (right) for A = +1 (top)
    and A = −1 (bottom), on `axes` (2 × 2) if given; one legend."""
    if axes is None:
        _, axes = plt.subplots(2, 2, figsize=(10, 6.5), sharex=True, layout="constrained")
    for row, advantage in enumerate((1.0, -1.0)):
        for col, slope in enumerate((False, True)):
            ax = axes[row][col]
            plot_objective(advantage, slope=slope, variants=variants, epsilon=epsilon, ax=ax)
            if (row, col) != (0, 1):
                ax.get_legend().remove()
            if row == 0:
                ax.set_xlabel("")
    return cast(Figure, axes[0][0].figure)


def plot_curves(
    result: SweepResult,
    metric: str = "average_return",
    *,
    band: str = "std",
    confidence: float = statistics.CONFIDENCE,
    names: Sequence[str] | None = None,
    ax: Axes | None = None,
) -> Figure:
    """`metric` (the average return unless told) against env steps, one line per setting,
    named in the legend by `names` (by :func:`~fppo_jax.run.results.labels` unless told).
    ``band="std"``: the mean over seeds ± one sample std; ``"iqm"``, ``"mean"`` or ``"median"``:
    that statistic over seeds with its percentile bootstrap band at level `confidence`
    (:func:`fppo_jax.stats.statistics.curve_interval`). Runs that diverged are left out, as the
    table leaves them out, and the legend says how many seeds a setting's line is over when some
    did or when settings ran different numbers of seeds."""
    if band != "std":
        statistics.estimator(band)
    ax = _axes(ax, (7, 4.5))
    run_counts = {result.setting_run_count(i) for i in range(len(result.settings))}
    for index, name in enumerate(labels(result.settings) if names is None else names):
        if len(run_counts) > 1 or result.setting_runs(index)[1].size:
            name += f", seeds {result.setting_seeds(index)}"
        m = result.setting_metrics(index)
        if not len(m[metric]):  # every run diverged: in the legend, with no line
            ax.plot([], [], label=name)
            continue
        if band == "std":
            line_values = nanmean(m[metric], axis=0)
            spread = _sample_std(m[metric])
            low, high = line_values - spread, line_values + spread
        else:
            line_values, low, high = statistics.curve_interval(
                m[metric], band, confidence=confidence
            )
        (line,) = ax.plot(m["env_steps"][0], line_values, label=name)
        ax.fill_between(m["env_steps"][0], low, high, color=line.get_color(), alpha=0.2, lw=0)
    ax.set(xlabel="env steps", ylabel=YLABELS.get(metric, metric))
    shown = (
        "mean ± sample std"
        if band == "std"
        else f"{statistics.STATISTICS[band]}, {confidence:.0%} bootstrap CI"
    )
    over = f"{len(result.seeds)} seeds" if len(run_counts) == 1 else "each setting's seeds"
    ax.set_title(f"{result.config['env']}: {shown} over {over}")
    if metric in FRACTIONS:
        ax.yaxis.set_major_formatter(PercentFormatter(1.0))
    ax.legend(fontsize="small")
    ax.grid(alpha=0.3)
    return cast(Figure, ax.figure)


def _sample_std(values: np.ndarray) -> np.ndarray:
    """The sample std over seeds at each update, NaN-ignoring and without all-NaN warnings."""
    finite = np.isfinite(values)
    count = finite.sum(axis=0)
    mean = nanmean(values, axis=0)
    squares = np.where(finite, (values - mean) ** 2, 0.0).sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 1, np.sqrt(squares / (count - 1)), np.nan)


def plot_profiles(
    scores: Mapping[str, np.ndarray],
    *,
    thresholds: np.ndarray | None = None,
    xlabel: str = "threshold on the normalised score",
    ax: Axes | None = None,
) -> Figure:
    """Performance profiles (Agarwal et al. 2021): for each setting, the fraction of its runs
    (pooled over tasks, on a normalised scale) whose score exceeds a threshold, against the
    threshold. The labels name no symbol (such as τ) that could be read as one of a user's
    hyperparameters."""
    ax = _axes(ax, (5.5, 3.8))
    pooled = {name: np.asarray(x, float).ravel() for name, x in scores.items()}
    if thresholds is None:
        every = np.concatenate(list(pooled.values()))
        every = every[np.isfinite(every)]
        thresholds = np.linspace(every.min(), every.max(), 201)
    for name, x in pooled.items():
        ax.plot(thresholds, statistics.performance_profile(x, thresholds), label=name)
    ax.set(xlabel=xlabel, ylabel="fraction of runs above the threshold", ylim=(-0.02, 1.02))
    ax.legend(fontsize="small")
    ax.grid(alpha=0.3)
    return cast(Figure, ax.figure)


def plot_improvement(
    improvements: Mapping[str, tuple[float, float, float]],
    baseline: str,
    *,
    confidence: float = statistics.CONFIDENCE,
    ax: Axes | None = None,
) -> Figure:
    """Probabilities of improvement over `baseline`, one row per name of `improvements` (e.g.
    ``"fppo-lp, hopper"``), each its ``(point, low, high)``: a dot and its interval, with the
    line of no difference (0.5)."""
    ax = _axes(ax, (5.5, 0.45 * len(improvements) + 1.2))
    names = list(improvements)
    rows = np.arange(len(names))[::-1]
    for row, name in zip(rows, names, strict=True):
        point, low, high = improvements[name]
        ax.plot([low, high], [row, row], color="C0", lw=3, alpha=0.5, solid_capstyle="butt")
        ax.plot(point, row, "o", color="C0")
    ax.axvline(0.5, color="grey", ls="--", lw=1)
    ax.set_yticks(rows, names)
    ax.set(xlim=(0, 1), xlabel=f"P(setting > {baseline}), {confidence:.0%} bootstrap CI")
    ax.grid(alpha=0.3, axis="x")
    return cast(Figure, ax.figure)


def ablation_keys(result: SweepResult) -> list[str]:
    """The numeric hyperparameters that take more than one value in the sweep."""
    return [key for key in SWEPT if len({s[key] for s in result.settings if key in s}) > 1]


def plot_ablation(
    result: SweepResult, *, axes: Sequence[Axes] | np.ndarray | None = None
) -> Figure:
    """Max average return (the paper's statistic) against each swept hyperparameter
    (:func:`ablation_keys`), one panel per hyperparameter (on `axes` if given) and one line per
    variant. Runs that diverged are left out, as the table leaves them out, and the legend says how
    many did."""
    keys = ablation_keys(result)
    if not keys:
        raise InvalidInput("no numeric hyperparameter takes several values in this sweep")
    if axes is None:
        _, axes = plt.subplots(
            1, len(keys), figsize=(5 * len(keys), 4), squeeze=False, layout="constrained"
        )
        axes = axes[0]
    for ax, key in zip(axes, keys, strict=True):
        for variant in dict.fromkeys(str(s["variant"]) for s in result.settings):
            chosen = sorted(
                (i for i, s in enumerate(result.settings) if s["variant"] == variant and key in s),
                key=lambda i: result.settings[i][key],
            )
            if len(chosen) < 2:
                continue
            x = [result.settings[i][key] for i in chosen]
            returns = [result.setting_metrics(i)["average_return"] for i in chosen]
            best, std, _ = np.array([max_average_return(r) for r in returns]).T
            label = variant + _lost(result, chosen)
            ax.errorbar(x, best, yerr=std, marker="o", capsize=3, label=label)
        ax.set(xlabel=key, ylabel="max average return")
        ax.set_title(f"{result.config['env']}: mean ± sample std over {len(result.seeds)} seeds")
        ax.legend(fontsize="small")
        ax.grid(alpha=0.3)
    return cast(Figure, axes[0].figure)


def _lost(result: SweepResult, settings: list[int]) -> str:
    """How many of the runs of `settings` diverged, for a legend ("" if none)."""
    runs = [result.setting_runs(i) for i in settings]
    lost = sum(diverged.size for _, diverged in runs)
    total = lost + sum(kept.size for kept, _ in runs)
    return f", {lost} of {total} runs diverged" if lost else ""


def plot_escape_speed(
    fractions: np.ndarray, variants: Sequence[str], *, ax: Axes | None = None
) -> Figure:
    """The paper's mechanism: the share of one batch in R+ ∪ R- after each epoch of an update,
    one line per variant, all from the same states. `fractions` is [state, variant, epoch], as
    :meth:`fppo_jax.Trainer.escape_by_epoch` vmapped over states and variants gives it; the line
    is the mean over states, the band ± one sample std."""
    ax = _axes(ax, (6, 4))
    fractions = np.asarray(fractions)
    epochs = np.arange(1, fractions.shape[-1] + 1)
    for i, variant in enumerate(variants):
        mean, std = fractions[:, i].mean(0), fractions[:, i].std(0, ddof=1)
        (line,) = ax.plot(epochs, mean, marker="o", ms=3, label=variant)
        ax.fill_between(epochs, mean - std, mean + std, color=line.get_color(), alpha=0.15, lw=0)
    ax.set(xlabel="epoch", ylabel=IN_NEGATIVE_REGIONS)
    ax.set_title(f"one batch, epoch by epoch: mean ± sample std over {len(fractions)} states")
    ax.yaxis.set_major_formatter(PercentFormatter(1.0))
    ax.legend(fontsize="small")
    ax.grid(alpha=0.3)
    return cast(Figure, ax.figure)


def plot_sweep(result: SweepResult, directory: str | Path) -> list[Path]:
    """Write `curves.png`, and `ablation.png` if a numeric hyperparameter takes several values,
    to `directory`. Returns the paths written."""
    figures = {"curves.png": plot_curves(result)}
    if ablation_keys(result):
        figures["ablation.png"] = plot_ablation(result)
    paths = []
    for name, fig in figures.items():
        paths.append(Path(directory) / name)
        fig.savefig(paths[-1], dpi=120)
        plt.close(fig)
    return paths


def plot_tuning_curves(results: Mapping[str, Mapping[str, ArmResults]]) -> Figure:
    """A tune's tuning curves (``tuning_curves.png``), a panel per task of `results` (as
    ``results.json`` holds them): per arm the best trial's score at each rung against the env
    steps the arm spent (solid), and the expected best of n first-rung settings (dashed) with
    its bootstrap band (shaded). A task where no trial scored says so in its panel."""
    figure, axes = plt.subplots(
        1, len(results), figsize=(5 * len(results), 3.5), squeeze=False, layout="constrained"
    )
    for ax, (task, arms) in zip(axes[0], results.items(), strict=True):
        for arm, found in arms.items():
            points = [(c["env_steps"], c["best"]) for c in found["curve"] if c["best"] is not None]
            if not points:  # no trial scored at any rung: then none on the first, no band
                continue
            (line,) = ax.plot(*zip(*points, strict=True), marker="o", label=arm)
            if found["expected_best"] is not None:
                steps, best, low, high = (
                    [point[key] for point in found["expected_best"]["points"]]
                    for key in ("env_steps", "expected_best", "low", "high")
                )
                ax.plot(steps, best, linestyle="--", color=line.get_color())
                ax.fill_between(steps, low, high, color=line.get_color(), alpha=0.2, linewidth=0)
            if "race" in found:
                _validation_points(ax, found["race"], found["env_steps"], line.get_color())
        ax.set(title=task, xlabel="env steps spent by the arm", ylabel="best score")
        steps_axis(ax)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
        else:  # a legend of nothing is matplotlib's warning, and an empty panel says nothing
            ax.set(xticks=[], yticks=[])
            ax.text(
                0.5,
                0.5,
                "no trial scored: each diverged\nor finished no episode",
                ha="center",
                va="center",
                transform=ax.transAxes,
            )
    figure.suptitle(
        "solid: the best trial at each rung; dashed: the expected best of n first-rung "
        "settings,\nshaded: its 95% bootstrap band over the trials; at the budget's end, the "
        "validation race: x each finalist's validation score, * the chosen setting's",
        fontsize=8,
    )
    return figure


def _validation_points(ax: Axes, race: RaceRecord, spent: int, color: Any) -> None:
    """The validation race at the arm's whole spend `spent`: each finalist's mean validation
    score (x) and the chosen setting's (*, the default's where it stayed), on seeds that chose
    nothing, beside the search's curve, whose best is biased upward by the choosing."""
    scores = [score for score in race["validation_scores"] if score is not None]
    ax.scatter([spent] * len(scores), scores, marker="x", color=color)
    chosen = race["chosen"]
    score = (
        race["default_score"]
        if chosen == 0
        else race["validation_scores"][race["finalists"].index(chosen)]
    )
    if score is not None:
        ax.scatter([spent], [score], marker="*", s=120, color=color, edgecolors="black")


def steps_axis(ax: Axes) -> None:
    """Env steps on `ax`'s x axis as 250k or 1.5M, at most six ticks: written out in full
    (250000, 1500000) they run together in a narrow panel."""
    ax.xaxis.set_major_formatter(EngFormatter(sep=""))
    ax.xaxis.set_major_locator(MaxNLocator(nbins=5))


def _axes(ax: Axes | None, figsize: tuple[float, float]) -> Axes:
    """`ax`, or the Axes of a new figure."""
    if ax is None:
        _, ax = plt.subplots(figsize=figsize, layout="constrained")
    return ax
