"""PNG figures of a sweep: learning curves (the paper's Figs. 4–5) and the α/k chart (Fig. 6)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only: no display is needed or assumed

import matplotlib.pyplot as plt
import numpy as np

from fppo_jax.results import SweepResult, labels, max_average_return, nanmean

SWEPT = ("alpha", "k", "delta", "epsilon", "learning_rate")


def plot_sweep(result: SweepResult, directory: str | Path) -> list[Path]:
    """Write `curves.png`, and `ablation.png` if a numeric hyperparameter takes several values.
    Returns the paths written."""
    directory = Path(directory)
    written = [directory / "curves.png"]
    plot_curves(result, written[0])
    if ablation_keys(result):
        written.append(directory / "ablation.png")
        plot_ablation(result, written[-1])
    return written


def plot_curves(result: SweepResult, path: Path) -> None:
    """Average return against env steps: mean over seeds, ± one std as a band."""
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for index, name in enumerate(labels(result.settings)):
        m = result.setting_metrics(index)
        steps = m["env_steps"][0]
        mean = nanmean(m["average_return"], axis=0)
        std = np.nanstd(m["average_return"], axis=0) if m["average_return"].size else mean
        (line,) = ax.plot(steps, mean, label=name)
        ax.fill_between(steps, mean - std, mean + std, color=line.get_color(), alpha=0.2)
    ax.set_xlabel("env steps")
    ax.set_ylabel("average return (last 100 episodes)")
    ax.set_title(f"{result.config['env']}: mean ± std over {len(result.seeds)} seeds")
    ax.legend(fontsize="small")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def ablation_keys(result: SweepResult) -> list[str]:
    """The numeric hyperparameters that take more than one value in the sweep."""
    return [key for key in SWEPT if len({s[key] for s in result.settings if key in s}) > 1]


def plot_ablation(result: SweepResult, path: Path) -> None:
    """Max average return (SPEC §2) against each swept hyperparameter, one line per variant."""
    keys = ablation_keys(result)
    fig, axes = plt.subplots(1, len(keys), figsize=(5 * len(keys), 4), squeeze=False)
    for ax, key in zip(axes[0], keys, strict=True):
        for variant in dict.fromkeys(s["variant"] for s in result.settings):
            points = [
                (s[key], *max_average_return(result.setting_metrics(i)["average_return"])[:2])
                for i, s in enumerate(result.settings)
                if s["variant"] == variant and key in s
            ]
            if len(points) > 1:
                x, best, std = (np.asarray(v) for v in zip(*sorted(points), strict=True))
                ax.errorbar(x, best, yerr=std, marker="o", capsize=3, label=variant)
        ax.set_xlabel(key)
        ax.set_ylabel("max average return")
        ax.legend(fontsize="small")
        ax.grid(alpha=0.3)
    fig.suptitle(f"{result.config['env']}: max average return over {len(result.seeds)} seeds")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
