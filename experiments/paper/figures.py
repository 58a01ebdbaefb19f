"""The figures README.md shows, drawn from recorded results into results/figures/.

    python experiments/paper/figures.py [--records DIR] [--out DIR]

Each figure below but the surrogate chart is drawn when its records are found in `--records`
(default `results/`); `--records results/earlier-protocol --out DIR` draws the 5-seed Table 1
and Fig. 6 figures again from the earlier protocol's records.

- `objectives.png`: every variant's surrogate and slope against the ratio for A > 0 and A < 0,
  R+ and R- shaded (the paper's Figs. 1 and 3). Computed; it takes seconds.
- `table1_classic.png`: Table 1's classic-control learning curves (5 variants, mean ± sample
  std over 5 seeds), from `results/table1_classic/<task>/`, which `table1_classic.py` writes.
- `escape_speed.png`: per task, the share of one batch in R+ ∪ R- after each epoch under PPO,
  FPPO-LP and FPPO-QP from the same states and samples, mean ± sample std over seeds and update
  points, from `results/escape_speed/fractions.csv`, which `escape_speed.py` writes.
- `table1_mujoco.png`: Table 1's MuJoCo learning curves, from the tasks `table1_mujoco.py` has
  recorded (`results/table1_mujoco_<backend>/<task>/`).
- `ablation.png`: Fig. 6, max average return against FPPO-LP's α and FPPO-QP's k, one row
  per task `ablation.py` has recorded (`results/ablation_<backend>/<task>/<part>/`).

Nothing is trained.
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure

from fppo_jax.analysis.plots import plot_curves, plot_escape_speed, plot_objectives
from fppo_jax.run.results import SweepResult

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: shared modules

from common import (
    CLASSIC_TASKS,
    ESCAPE_FRACTIONS,
    ESCAPE_VARIANTS,
    RESULTS,
    RUN_RECORD,
    ablation_parts,
    argument_parser,
    draw_ablation,
    read_fractions,
)

DPI = 90


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--records", type=Path, default=RESULTS, help="where the records are")
    parser.add_argument("--out", type=Path, default=RESULTS / "figures")
    args = parser.parse_args()
    records: Path = args.records
    if not records.is_dir():  # else only the objectives would be drawn, silently
        parser.error(f"--records {records}: no such directory (relative to where this runs)")
    figures = {"objectives.png": plot_objectives()}
    classic = [records / "table1_classic" / task for task in CLASSIC_TASKS]
    if all((directory / "curves.csv").exists() for directory in classic):
        figures["table1_classic.png"] = plot_sweeps(classic)
    if (records / ESCAPE_FRACTIONS).exists():
        figures["escape_speed.png"] = plot_escape_speed_by_task(
            read_fractions(records / ESCAPE_FRACTIONS)
        )
    mujoco = sorted(path.parent for path in records.glob("table1_mujoco*/*/curves.csv"))
    if mujoco:
        figures["table1_mujoco.png"] = plot_sweeps(mujoco)
    ablations = sorted(
        {path.parent.parent for path in records.glob(f"ablation_*/*/*/{RUN_RECORD}")}
    )
    if ablations:
        figures["ablation.png"] = plot_ablations(ablations)
    args.out.mkdir(parents=True, exist_ok=True)
    for name, fig in figures.items():
        fig.savefig(args.out / name, dpi=DPI, pil_kwargs={"optimize": True})
        plt.close(fig)
        print(f"wrote {args.out / name}")


def plot_sweeps(directories: list[Path], columns: int = 3) -> Figure:
    """The learning curves of each recorded sweep, `columns` to a row."""
    rows = -(-len(directories) // columns)
    width = min(columns, len(directories))
    fig, axes = plt.subplots(
        rows, width, figsize=(3.5 * width, 2.7 * rows), layout="constrained", squeeze=False
    )
    for ax, directory in zip(axes.flat, directories, strict=False):
        result = SweepResult.read(directory)
        plot_curves(result, ax=ax)
        ax.set_title(f"{result.config['env']} ({len(result.seeds)} seeds, mean ± sample std)")
    for ax in axes.flat[len(directories) :]:
        ax.set_visible(False)
    return fig


def plot_ablations(tasks: list[Path]) -> Figure:
    """Each task's recorded ablation parts (`ablation.py`'s <task>/<part>/), one row per task."""
    width = max(len(ablation_parts(task.parent, task.name)) for task in tasks)
    fig, axes = plt.subplots(
        len(tasks), width, figsize=(4 * width, 3 * len(tasks)), layout="constrained", squeeze=False
    )
    for row, task in zip(axes, tasks, strict=True):
        draw_ablation(task.parent, task.name, row)
        for ax in row[len(ablation_parts(task.parent, task.name)) :]:
            ax.set_visible(False)
    return fig


def plot_escape_speed_by_task(fractions: dict[str, np.ndarray]) -> Figure:
    """One panel per task of :func:`common.read_fractions`' [seed, point, variant, epoch],
    each over its seeds and update points."""
    fig, axes = plt.subplots(
        1, len(fractions), figsize=(4 * len(fractions), 3.2), layout="constrained", sharey=True
    )
    for ax, (task, values) in zip(np.atleast_1d(axes), fractions.items(), strict=True):
        plot_escape_speed(values.reshape(-1, *values.shape[2:]), ESCAPE_VARIANTS, ax=ax)
        seeds, points = values.shape[:2]
        ax.set_title(f"{task}: {seeds} seeds × {points} updates", fontsize="medium")
    return fig


if __name__ == "__main__":
    main()
