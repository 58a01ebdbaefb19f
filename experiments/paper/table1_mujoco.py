"""The paper's Table 1, MuJoCo rows, and its Figs. 4–5: variants × seeds × 1M steps, each task one
sweep, on the backend asked for.

    python experiments/paper/table1_mujoco.py --backend native --tasks reacher swimmer   # a CPU
    python experiments/paper/table1_mujoco.py --backend mjx --tasks hopper ant           # a GPU
    python experiments/paper/table1_mujoco.py --backend native --steps 8192 --seeds 1 \\
        --variants ppo --tasks reacher --results /tmp/smoke                        # a smoke run

Each task's runs (all five variants × seeds 0–4 by default, Table 2's α and k, the `paper` preset:
the paper's protocol) are one vmapped, compiled program (`fppo_jax.sweep`). As each task ends, its
curves (`SweepResult.write`, the metrics the table and figures read) and its run record go to
<results>/table1_mujoco_<backend>/<task>/, its learning curves (mean ± std over seeds, every
variant) to <results>/table1_mujoco_<backend>/<task>.png, and <results>/table1_mujoco_<backend>.md
is written again from every task recorded so far, saying which are still to run: a long reproduction
can go task by task, across sittings. Neither MJX nor envpool is the paper's MuJoCo 1.5 with gym v2,
so absolute returns differ; what should agree is how the variants compare.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import matplotlib

from fppo_jax.core.config import describe, preset_config, task_preset
from fppo_jax.envs import MUJOCO_TASKS
from fppo_jax.run.results import SweepResult

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: shared modules

from common import (
    PAPER_VARIANTS,
    RUN_RECORD,
    TABLE1,
    add_record_flags,
    add_sweep_flags,
    argument_parser,
    read_run_record,
    record_sweep,
    sweep_directory,
    write_result,
)


def run_task(task: str, args: argparse.Namespace, directory: Path) -> None:
    """One task's sweep, its curves and record, and its figure."""
    result = record_sweep(task, {"variant": list(args.variants)}, args, directory / task)
    figure(result, directory / f"{task}.png")


def figure(result: SweepResult, path: Path) -> None:
    matplotlib.use("Agg")
    from fppo_jax.analysis.plots import plot_curves

    fig = plot_curves(result)
    fig.savefig(path, dpi=110, bbox_inches="tight")
    matplotlib.pyplot.close(fig)


def report(args: argparse.Namespace, directory: Path, backend: str) -> Path:
    """The Markdown table of every task recorded under `directory`, beside the paper's."""
    config = preset_config("paper", total_steps=args.steps, **task_preset("paper", MUJOCO_TASKS[0]))
    done = [task for task in MUJOCO_TASKS if (directory / task / RUN_RECORD).exists()]
    pending = [task for task in MUJOCO_TASKS if task not in done]
    lines = [
        f"# Table 1, MuJoCo rows, on {backend}",
        "",
        f"- Protocol (the paper's): {describe(config, 'paper')} per run (baselines' ppo2 MuJoCo "
        "defaults, which the paper's baselines used); Table 2's α and k; each task's runs "
        "(variants × seeds) are one sweep, one compiled program.",
        "- Max average return: the maximum over updates of the seed-mean of the "
        "last-100-episode average return, ± the sample std across seeds there, over the seeds that "
        "did not diverge (`seeds` says how many, and how many diverged). Escape: the fraction "
        "of each update's batch left in R+ ∪ R- after its last epoch, averaged over the run.",
        f"- Tasks done: {', '.join(done) or 'none'}; still to run: {', '.join(pending) or 'none'}.",
        "",
    ]
    for task in done:
        result = SweepResult.read(directory / task)
        record = read_run_record(directory / task)
        hours = record["wall_seconds"] / 3600
        paper = ", ".join(
            f"{s['variant']} {TABLE1[task][PAPER_VARIANTS.index(s['variant'])]}"
            for s in result.settings
        )
        lines += [
            f"## {task}",
            "",
            f"{len(result.runs)} runs ({result.config['total_steps']:,} env steps each) in "
            f"{record['wall_seconds']:,.0f} s ({hours:.2f} h; {result.compile_seconds:.0f} s "
            f"compiling) on {record['machine']}, {record['date']}: `{record['command']}`.",
            "",
            result.table(),
            "",
            f"Paper (Table 1, max average return): {paper}.",
            "",
            f"![{task}: learning curves]({directory.name}/{task}.png)",
            "",
        ]
    path = directory.parent / f"{directory.name}.md"
    write_result(path, lines)
    return path


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--tasks", nargs="+", default=list(MUJOCO_TASKS), choices=MUJOCO_TASKS)
    parser.add_argument("--variants", nargs="+", default=PAPER_VARIANTS, choices=PAPER_VARIANTS)
    add_sweep_flags(parser)
    add_record_flags(parser)
    args = parser.parse_args()

    backend, directory = sweep_directory(args, "table1_mujoco", args.tasks)
    for task in args.tasks:
        run_task(task, args, directory)
        print(f"wrote {report(args, directory, backend)}", flush=True)


if __name__ == "__main__":
    main()
