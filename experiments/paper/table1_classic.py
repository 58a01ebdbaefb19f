"""The paper's Table 1, classic-control rows: 5 variants × 5 seeds × 100k steps per task.

    python experiments/paper/table1_classic.py [--tasks cartpole acrobot mountaincar] [--seeds 5]

Each task's 25 runs (variants × seeds) are one sweep: one vmapped, compiled program. "Max average
return" is the paper's: per seed, the mean return of the last 100 finished episodes after every
update; averaged over seeds; the maximum of that curve, ± the standard deviation across seeds at
that update; runs that diverged are left out, and counted beside their variant, as `fppo-jax table`
does. Writes experiments/results/table1_classic.md, with the escape-speed comparison (the paper's
mechanism) beside it, and each task's curves (`SweepResult.write`, with the metrics the table and
the figures use) to experiments/results/table1_classic/<task>/, which `fppo-jax plot` and
experiments/paper/figures.py read."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from fppo_jax import TrainConfig, sweep
from fppo_jax.run.results import max_average_return

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: shared modules

from common import (
    CLASSIC_TASKS,
    PAPER_VARIANTS,
    RECORDED_METRICS,
    RESULTS,
    TABLE1,
    add_output_flags,
    argument_parser,
    header,
    refuse_to_replace,
    write_result,
)


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--tasks", nargs="+", default=list(CLASSIC_TASKS), choices=CLASSIC_TASKS)
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--steps", type=int, default=100_000)
    parser.add_argument("--curves", type=Path, default=RESULTS / "table1_classic")
    add_output_flags(parser, RESULTS / "table1_classic.md")
    args = parser.parse_args()
    recorded = [args.output, *(args.curves / task for task in args.tasks)]
    refuse_to_replace(recorded, args.force, elsewhere="--output FILE and --curves DIR")

    config = TrainConfig(total_steps=args.steps)
    runs = len(PAPER_VARIANTS) * args.seeds
    lines = [
        *header("Learning on the classic-control tasks"),
        "",
        f"Protocol (the paper's): {config.num_updates} updates × "
        f"{config.samples_per_update} samples "
        f"({config.num_envs} envs × {config.num_steps} steps) = "
        f"{config.num_updates * config.samples_per_update:,} env steps per run, "
        f"{config.num_minibatches} minibatches, {config.num_epochs} epochs, Adam 3e-4, γ 0.99, "
        "λ 0.95, entropy 0, observation and reward normalisation; α and k from Table 2; "
        f"seeds 0–{args.seeds - 1}. Each task's {runs} runs are one sweep (one compiled program).",
        "",
        "Max average return: the maximum over updates of the seed-mean of the last-100-episode "
        "average return, ± the sample std across seeds at that update (the update's env steps in "
        "brackets). Escape: `negative_fraction_after`, the fraction of each update's batch left "
        "in R+ ∪ R- after its last epoch, averaged over the run and the seeds (first-epoch value "
        "in brackets).",
        "",
    ]
    for task in args.tasks:
        start = time.perf_counter()
        grid = {"variant": list(PAPER_VARIANTS)}
        result = sweep(task, grid, seeds=args.seeds, total_steps=args.steps)
        seconds = time.perf_counter() - start
        result.write(args.curves / task, metrics=RECORDED_METRICS)
        lines += [
            f"## {task}",
            "",
            f"{runs} runs in {seconds:.0f} s (compilation included).",
            "",
            "| variant | max average return | paper (Table 1) | final average return "
            "| escape: in R± after update |",
            "|---|---|---|---|---|",
        ]
        for index, (variant, paper) in enumerate(zip(PAPER_VARIANTS, TABLE1[task], strict=True)):
            m = result.setting_metrics(index)  # its runs that did not diverge, as fppo-jax table
            name = variant
            if result.setting_runs(index)[1].size:
                name += f", seeds {result.setting_seeds(index)}"
            best, std, at = max_average_return(m["average_return"])
            if at < 0:  # every run diverged, or none finished an episode
                lines.append(f"| {name} | – | {paper} | – | – |")
                continue
            steps = int(m["env_steps"][0, at])
            final = np.nanmean(m["average_return"][:, -1])
            after, before = (
                np.mean(m["negative_fraction_after"]),
                np.mean(m["negative_fraction_before"]),
            )
            lines.append(
                f"| {name} | {best:.1f} ± {std:.1f} ({steps:,}) | {paper} | {final:.1f} | "
                f"{after:.2%} ({before:.2%}) |"
            )
            print(f"{task:<12} {variant:<8} max {best:8.1f} ± {std:5.1f}  final {final:8.1f}")
        lines.append("")
    write_result(args.output, lines)
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
