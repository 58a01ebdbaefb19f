"""The README's headline figure, drawn from the recorded tuned verdict: does FPPO beat PPO when
every arm is tuned?

    python experiments/headline.py              # results/figures/headline.png
    python experiments/headline.py --out DIR    # DIR/headline.png

For each task of the tuned plan (experiments/plans/tuned.json), FPPO-LP's and FPPO-QP's
probability of improvement over tuned PPO, P(candidate > PPO), on the primary endpoint of the
study on test seeds (the deterministic policy's return), over the seeds the decision used, with
its 95% percentile bootstrap interval; each dot coloured by the decision of the plan's family
(better, worse, equivalent within the plan's margin, or undecided), and the margin shaded.
The studies are read once with ``fppo_jax.load_study`` (results/tuned/*/study*/), P is
``fppo_jax.stats.statistics.compare``'s, and the families are decided as one by the library's
sequential rule replayed on the recorded runs (studies/_tuned_families.py), as
results/tuned.md reports them. Nothing is trained; the figure is written again freely.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import sys
from collections.abc import Sequence
from pathlib import Path

import matplotlib.pyplot as plt
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from fppo_jax.analysis.study_runs import run_scores
from fppo_jax.stats import statistics

sys.path.insert(0, str(Path(__file__).resolve().parent))  # experiments/: shared modules
sys.path.insert(0, str(Path(__file__).resolve().parent / "studies"))

from _tuned_families import decide_family, planned_families, recorded_study
from common import RESULTS, argument_parser

PLAN = RESULTS.parent / "plans" / "tuned.json"
CANDIDATES = ("fppo-lp", "fppo-qp")
FIGURE = "headline.png"
DPI = 100
COLOURS = {
    "better": "#1a9850",
    "worse": "#d73027",
    "equivalent": "#4575b4",
    "undecided": "#7f7f7f",
}
NAMES = {
    "cartpole": "CartPole",
    "acrobot": "Acrobot",
    "mountaincar": "MountainCar",
    "hopper": "Hopper",
    "halfcheetah": "HalfCheetah",
    "swimmer": "Swimmer",
    "fppo-lp": "FPPO-LP",
    "fppo-qp": "FPPO-QP",
}


@dataclasses.dataclass(frozen=True)
class Comparison:
    """One candidate against tuned PPO on one task: the plan's family's `decision`, the `seeds`
    per arm it holds, and P(candidate > PPO) over those seeds as (point, low, high)."""

    task: str
    candidate: str
    decision: str
    seeds: int
    probability: tuple[float, float, float]


def comparisons(results: Path = RESULTS, plan: Path = PLAN) -> tuple[list[Comparison], float]:
    """FPPO's comparisons with tuned PPO in the recorded tuned verdict under `results`, in the
    plan's order of tasks, and the plan's equivalence margin."""
    planned = json.loads(plan.read_text())
    found, margins = [], set()
    for name, tasks in planned_families(planned).items():
        family = decide_family(results, name, tasks)
        for one in family.replayed:
            if one.candidate not in CANDIDATES:
                continue
            study = recorded_study(family.studies[one.task])  # fppo_jax.load_study's, read once
            margins.add(study.plan["margin"])
            runs, seeds = study.results[one.task], one.planned.seeds
            candidate = run_scores(runs, one.candidate, family.endpoint)[:seeds]
            baseline = run_scores(runs, study.plan["baseline"], family.endpoint)[:seeds]
            probability = statistics.compare(candidate, baseline)["probability_of_improvement"]
            decision = one.planned.decision or "undecided"
            found.append(Comparison(one.task, one.candidate, decision, seeds, probability))
    (margin,) = margins
    return found, margin


def draw(found: Sequence[Comparison], margin: float) -> Figure:
    """P(candidate > tuned PPO) per task and candidate, each a dot coloured by its decision on
    its 95% interval, top to bottom in the order given, with ½ and the equivalence margin."""
    figure, ax = plt.subplots(figsize=(7.5, 0.34 * len(found) + 1.6), layout="constrained")
    ax.axvspan(0.5 - margin, 0.5 + margin, color="#4575b4", alpha=0.08, lw=0)
    ax.axvline(0.5, color="grey", ls="--", lw=1)
    rows = list(range(len(found)))[::-1]
    for row, one in zip(rows, found, strict=True):
        point, low, high = one.probability
        colour = COLOURS[one.decision]
        ax.plot([low, high], [row, row], color=colour, lw=3, alpha=0.45, solid_capstyle="butt")
        ax.plot([point], [row], "o", color=colour, ms=7)
    for row, (before, after) in zip(rows[1:], itertools.pairwise(found), strict=True):
        if before.task != after.task:
            ax.axhline(row + 0.5, color="lightgrey", lw=0.8)
    labels = [f"{NAMES[o.task]}, {NAMES[o.candidate]} ({o.seeds} seeds)" for o in found]
    ax.set_yticks(rows, labels)
    ax.set_ylim(-0.6, len(found) - 0.4)
    ax.set_xlim(0, 1)
    ax.set_xlabel("P(candidate > tuned PPO), deterministic policy's return, 95% CI")
    ax.set_title("Tuned FPPO against tuned PPO, on seeds the tune never used", fontsize="medium")
    handles = [
        Line2D([], [], color=colour, marker="o", lw=3, alpha=0.8, label=decision)
        for decision, colour in COLOURS.items()
    ]
    handles.append(
        plt.Rectangle((0, 0), 1, 1, color="#4575b4", alpha=0.15, label=f"margin ½ ± {margin:g}")
    )
    figure.legend(handles=handles, loc="outside lower center", fontsize="small", ncols=5)
    ax.grid(alpha=0.3, axis="x")
    return figure


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--out", type=Path, default=RESULTS / "figures", help="where to draw it")
    args = parser.parse_args()
    found, margin = comparisons()
    figure = draw(found, margin)
    args.out.mkdir(parents=True, exist_ok=True)
    figure.savefig(args.out / FIGURE, dpi=DPI)
    plt.close(figure)
    for one in found:
        point, low, high = one.probability
        print(
            f"{one.task} {one.candidate}: {one.decision} at {one.seeds} seeds, "
            f"P = {point:.2f} [{low:.2f}, {high:.2f}]"
        )
    print(f"wrote {args.out / FIGURE}")


if __name__ == "__main__":
    main()
