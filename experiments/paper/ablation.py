"""The paper's Fig. 6 ablation: FPPO-LP's α and FPPO-QP's k, × seeds, each part one program.

    python experiments/paper/ablation.py --backend native                     # Walker2d and Ant
    python experiments/paper/ablation.py --backend native --tasks ant --parts k   # one part
    python experiments/paper/ablation.py --tasks reacher --steps 4096 --seeds 1 --results /tmp/smoke

Each task has two parts, each one vmapped sweep (`fppo_jax.sweep`, `paper` preset) of 5
settings × 5 seeds × 1M steps, chunked automatically to fit device memory: `alpha`, FPPO-LP
with α ∈ {1.1, …, 1.5}, and `k`, FPPO-QP with k ∈ {0.1, …, 0.5} (the paper's Fig. 6). They run on
`--backend` (default auto: MJX on a GPU, native MuJoCo on a CPU). As each part ends, its curves
and run record go to <results>/ablation_<backend>/<task>/<part>/, the task's chart (max average
return against α and against k, the paper's Fig. 6) to <results>/ablation_<backend>/<task>.png,
and <results>/ablation_<backend>/ablation.md is written again from every part recorded so far,
saying which are still to run: a long ablation can go part by part, across sittings.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import matplotlib

from fppo_jax.core.resolution import table2
from fppo_jax.envs import TASKS
from fppo_jax.run.results import SweepResult

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: shared modules

from common import (
    ABLATION_PARTS,
    ablation_parts,
    add_record_flags,
    add_sweep_flags,
    argument_parser,
    draw_ablation,
    read_run_record,
    record_sweep,
    sweep_directory,
    write_result,
)

TASKS_IN_PAPER = ("walker2d", "ant")


def run_part(task: str, part: str, args: argparse.Namespace, directory: Path) -> None:
    """One part's sweep, written with its run record to `directory`/<task>/<part>/."""
    variant, name, values = ABLATION_PARTS[part]
    record_sweep(task, {"variant": variant, name: values}, args, directory / task / part)


def figure(directory: Path, task: str) -> Path:
    """`task`'s chart, written to `directory`/<task>.png."""
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    width = len(ablation_parts(directory, task))
    fig, axes = plt.subplots(1, width, figsize=(5 * width, 4), squeeze=False, layout="constrained")
    draw_ablation(directory, task, axes[0])
    path = directory / f"{task}.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def report(directory: Path, backend: str) -> Path:
    """ablation.md: every part recorded under `directory`, and those still to run."""
    others = sorted(p.name for p in directory.iterdir() if p.is_dir())
    shown = [*TASKS_IN_PAPER, *(t for t in others if t not in TASKS_IN_PAPER)]
    done = [f"{t} {p}" for t in shown for p in ablation_parts(directory, t)]
    pending = [f"{t} {p}" for t in TASKS_IN_PAPER for p in ABLATION_PARTS if f"{t} {p}" not in done]
    lines = [
        f"# Fig. 6 ablation on {backend}: FPPO-LP's α and FPPO-QP's k",
        "",
        "- Each part is one sweep (one compiled program) of the `paper` preset (learning rate "
        "annealed linearly to 0, as baselines' ppo2 MuJoCo defaults): `alpha`, FPPO-LP with "
        f"α ∈ {ABLATION_PARTS['alpha'][2]}; `k`, FPPO-QP with k ∈ {ABLATION_PARTS['k'][2]}.",
        "- Max average return: the maximum over updates of the seed-mean of the "
        "last-100-episode average return, ± the sample std across seeds there, over the seeds that "
        "did not diverge. The paper's Fig. 6 gives these as a chart only; its Table 2 picks "
        "the best α and k per task.",
        f"- Parts done: {', '.join(done) or 'none'}; still to run: {', '.join(pending) or 'none'}.",
        "",
    ]
    for task in shown:
        parts = ablation_parts(directory, task)
        if not parts:
            continue
        chosen = {**table2(task, "fppo-lp"), **table2(task, "fppo-qp")}
        lines += [f"## {task}", ""]
        if chosen:
            lines += ["Table 2's choice: " + ", ".join(f"{k} = {v}" for k, v in chosen.items())]
            lines += [""]
        for part in parts:
            result = SweepResult.read(directory / task / part)
            record = read_run_record(directory / task / part)
            lines += [
                f"### {part}",
                "",
                f"{len(result.runs)} runs ({result.config['total_steps']:,} env steps each) in "
                f"{record['wall_seconds']:,.0f} s ({result.compile_seconds:.0f} s compiling) "
                f"on {record['machine']}, {record['date']}: `{record['command']}`.",
                "",
                result.table(),
                "",
            ]
        lines += [f"![{task}: Fig. 6]({task}.png)", ""]
    path = directory / "ablation.md"
    write_result(path, lines)
    return path


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--tasks", nargs="+", default=list(TASKS_IN_PAPER), choices=list(TASKS))
    parser.add_argument(
        "--parts", nargs="+", default=list(ABLATION_PARTS), choices=list(ABLATION_PARTS)
    )
    add_sweep_flags(parser)
    add_record_flags(parser)
    args = parser.parse_args()

    parts = [Path(task, part) for task in args.tasks for part in args.parts]
    backend, directory = sweep_directory(args, "ablation", parts)
    for task in args.tasks:
        for part in args.parts:
            run_part(task, part, args, directory)
            figure(directory, task)
            print(f"wrote {report(directory, backend)}", flush=True)


if __name__ == "__main__":
    main()
