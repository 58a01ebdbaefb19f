"""The paper's Table 1, MuJoCo rows on MJX: variants × seeds × 1M steps, each task one sweep.

    python experiments/table1_mujoco.py                       # Hopper; PPO, FPPO-LP, FPPO-QP
    python experiments/table1_mujoco.py --tasks hopper walker2d ant \\
        --variants fppo-lp fppo-qp ppo tr-ppo ppo-rb
    python experiments/table1_mujoco.py --steps 8192 --seeds 1  # a smoke run on a CPU

Meant for a GPU: on a 2-core CPU one Hopper run of 1M steps takes hours. Each task's runs are
one vmapped, compiled program (`fppo_jax.sweep`) with the `paper` preset (SPEC §2). Writes
experiments/results/table1_mujoco_<platform>.md (returns beside the paper's, wall time,
escape speed) and each sweep's curves under experiments/results/table1_mujoco_<platform>/;
runs that diverged are left out, and counted beside their variant, as `fppo-jax table` does.
MJX is not the paper's MuJoCo 1.5 with gym v2, so absolute returns differ; what should agree
is the comparison between variants.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import jax
import numpy as np

from fppo_jax import sweep
from fppo_jax.config import describe, preset_config
from fppo_jax.envs import MUJOCO_TASKS
from fppo_jax.results import max_average_return

PAPER = {  # SPEC §2, Table 1: FPPO-LP, FPPO-QP, PPO, TR-PPO, PPO-RB
    "walker2d": (4030.4, 3893.4, 3368.5, 3279.8, 2858.4),
    "ant": (2778.8, 3323.6, 2024.3, 2013.0, 2640.1),
    "reacher": (-6.1, -6.5, -7.6, -6.0, -7.8),
    "hopper": (2726.1, 2908.8, 2364.2, 2341.8, 1997.7),
    "halfcheetah": (4107.0, 4478.3, 4141.7, 3455.8, 3420.1),
    "swimmer": (113.6, 115.5, 100.2, 108.9, 99.8),
}
PAPER_VARIANTS = ("fppo-lp", "fppo-qp", "ppo", "tr-ppo", "ppo-rb")
RESULTS = Path(__file__).resolve().parent / "results"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tasks", nargs="+", default=["hopper"], choices=list(MUJOCO_TASKS))
    parser.add_argument(
        "--variants", nargs="+", default=["ppo", "fppo-lp", "fppo-qp"], choices=PAPER_VARIANTS
    )
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--steps", type=int, default=1_000_000)
    parser.add_argument("--chunk", type=int, help="runs per compiled call (default: automatic)")
    args = parser.parse_args()

    platform = jax.devices()[0].platform
    device = f"{platform.upper()} ({jax.devices()[0].device_kind})"
    config = preset_config("paper", total_steps=args.steps)
    runs = len(args.variants) * args.seeds
    lines = [
        "# Learning on the MuJoCo tasks (MJX)",
        "",
        f"- Machine: {device}, jax {jax.__version__}",
        f"- Command: `python experiments/table1_mujoco.py {' '.join(sys.argv[1:])}`",
        f"- Protocol (SPEC §2): {describe(config, 'paper')}; α and k from Table 2; seeds "
        f"0–{args.seeds - 1}; each task's {runs} runs are one sweep (one compiled program).",
        "- Max average return: the maximum over updates of the seed-mean of the last-100-episode "
        "average return, ± the std across seeds there. Escape: the fraction of each update's "
        "batch left in R+ ∪ R- after its last epoch, averaged over the run and the seeds.",
        "",
    ]
    for task in args.tasks:
        start = time.perf_counter()
        result = sweep(
            task,
            {"variant": list(args.variants)},
            seeds=args.seeds,
            total_steps=args.steps,
            chunk=args.chunk,
            progress=True,
        )
        seconds = time.perf_counter() - start
        result.write(RESULTS / f"table1_mujoco_{platform}" / task)
        lines += [
            f"## {task}",
            "",
            f"{runs} runs in {seconds:.0f} s wall ({result.compile_seconds:.0f} s compiling), "
            f"{result.config['runs_per_call']} runs per compiled call.",
            "",
            "| variant | max average return | paper (Table 1) | final average return "
            "| escape: in R± after update |",
            "|---|---|---|---|---|",
        ]
        for index, variant in enumerate(args.variants):
            m = result.setting_metrics(index)  # its runs that did not diverge, as fppo-jax table
            name = variant
            if result.setting_runs(index)[1].size:
                name += f", seeds {result.setting_seeds(index)}"
            best, std, at = max_average_return(m["average_return"])
            paper = PAPER[task][PAPER_VARIANTS.index(variant)]
            if at < 0:  # every run diverged, or none finished an episode
                lines.append(f"| {name} | – | {paper} | – | – |")
                continue
            final = np.nanmean(m["average_return"][:, -1])
            lines.append(
                f"| {name} | {best:.1f} ± {std:.1f} | {paper} | {final:.1f} | "
                f"{np.mean(m['negative_fraction_after']):.2%} |"
            )
            print(f"{task:<12} {variant:<8} max {best:9.1f} ± {std:7.1f}  final {final:9.1f}")
        lines.append("")
    path = RESULTS / f"table1_mujoco_{platform}.md"
    path.write_text("\n".join(lines))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
