"""A sweep in two parts: one process after another, against two processes at once on one core
each, as a cluster's nodes would share it.

    python experiments/benchmarks/bench_parts.py \
        [--task hopper] [--seeds 2] [--steps 100000] [--repeats 2]

The sweep is PPO and FPPO-LP × `--seeds` on native MuJoCo, in two groups of `--seeds` runs
(``--chunk``: a part trains whole groups of the sweep). Each arm runs
``fppo-jax sweep --part K/2`` for K = 1 and 2 in fresh processes: (a) one after another, each
free to use every core; (b) both at once, each held to a core of its own. The arms alternate
`--repeats` times and the best wall time of each counts (start-up and compilation included);
both arms' parts are merged and must hold every run. From arm (a) it also projects the time
on N nodes: every part pays the start-up and compilation, and the training is shared, so
T(N) = overhead + training / N. Writes experiments/results/bench_parts.md.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from fppo_jax import SweepResult, merge

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: shared modules

from common import (
    RESULTS,
    RUN_RECORD,
    add_record_flags,
    argument_parser,
    header,
    read_run_record,
    refuse_to_replace,
    write_result,
)

PARTS = 2


def run_parts(flags: list[str], where: Path, at_once: bool) -> float:
    """Wall seconds to train both parts into `where`/part1 and part2."""
    cores = sorted(os.sched_getaffinity(0))
    start = time.perf_counter()
    processes = []
    for k in range(1, PARTS + 1):
        pinned = {cores[(k - 1) % len(cores)]} if at_once else None
        part = ["--part", f"{k}/{PARTS}", "--output", str(where / f"part{k}"), "--quiet"]
        process = subprocess.Popen(
            [sys.executable, "-m", "fppo_jax", "sweep", *flags, *part],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            preexec_fn=None if pinned is None else lambda c=pinned: os.sched_setaffinity(0, c),
        )
        if at_once:
            processes.append(process)
        else:
            finish(process)
    for process in processes:
        finish(process)
    return time.perf_counter() - start


def finish(process: subprocess.Popen) -> None:
    output, _ = process.communicate()
    if process.returncode != 0:
        sys.exit(f"a part failed:\n{output[-3000:]}")


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--task", default="hopper")
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--steps", type=int, default=100_000)
    parser.add_argument("--repeats", type=int, default=2)
    add_record_flags(parser)
    args = parser.parse_args()
    output = args.results / "bench_parts.md"
    refuse_to_replace([output], args.force)
    flags = ["--env", args.task, "--variant", "ppo,fppo-lp", "--seeds", str(args.seeds)]
    flags += ["--steps", str(args.steps), "--backend", "native", "--chunk", str(args.seeds)]

    walls: dict[str, list[float]] = {"a": [], "b": []}
    parts: dict[str, list[SweepResult]] = {}
    with tempfile.TemporaryDirectory() as scratch:
        for repeat in range(args.repeats):
            for arm, at_once in (("a", False), ("b", True)):
                where = Path(scratch) / f"{arm}{repeat}"
                walls[arm].append(run_parts(flags, where, at_once))
                parts[arm] = [SweepResult.read(where / f"part{k}") for k in (1, 2)]
                print(f"arm ({arm}), repeat {repeat + 1}: {walls[arm][-1]:.1f} s", flush=True)
    for arm in parts:
        merged = merge(parts[arm])
        expected = 2 * args.seeds
        if len(merged.runs) != expected:
            sys.exit(f"arm ({arm}) merged {len(merged.runs)} runs, not {expected}")
    a, b = min(walls["a"]), min(walls["b"])
    training = sum(p.train_seconds for p in parts["a"])
    overhead = (a - training) / PARTS  # start-up and compilation, per part
    steps = sum(int(p.metrics["env_steps"][:, -1].sum()) for p in parts["a"])
    lines = [
        *header("A sweep's two parts: one after another, or at once on a core each"),
        "",
        f"The sweep: PPO and FPPO-LP × {args.seeds} seeds on {args.task} (native MuJoCo), "
        f"{args.steps:,} env steps a run, {steps:,} in all, split with `--part K/2`. Wall time "
        f"from starting the processes to both ending (start-up and compilation included), "
        f"best of {args.repeats}, the arms alternating.",
        "",
        "| arm | wall (s) | every try (s) |",
        "|---|---|---|",
        f"| (a) one process after another, every core each | {a:.1f} | "
        + ", ".join(f"{w:.1f}" for w in walls["a"])
        + " |",
        f"| (b) two processes at once, one core each | {b:.1f} | "
        + ", ".join(f"{w:.1f}" for w in walls["b"])
        + " |",
        "",
        f"**(a) / (b) = {a / b:.2f}×.** Both arms' parts merged into the whole sweep "
        f"({2 * args.seeds} runs).",
        "",
        f"In arm (a) the parts trained for {training:.1f} s in all and spent {overhead:.1f} s "
        "each starting and compiling. On N nodes each part pays that overhead once and the "
        "training is shared, so T(N) ≈ overhead + training / N:",
        "",
        "| nodes | T(N) (s) | speed-up over one |",
        "|---|---|---|",
    ]
    for n in (1, 2, 4, 8, 16):
        t = overhead + training / n
        lines.append(f"| {n} | {t:.1f} | {(overhead + training) / t:.2f}× |")
    study = RESULTS / "study" / "hopper" / "paper" / "seeds-0-4_ppo+fppo-lp+fppo-qp"
    if (study / RUN_RECORD).exists():
        part = read_run_record(study)["wall_seconds"]
        lines += [
            "",
            f"A part of the seed study trains far longer (Hopper, 15 runs × 1M steps: {part:,.0f} "
            f"s), against which this overhead is {overhead / part:.1%}.",
        ]
    write_result(output, lines)
    print(f"wrote {output}")


if __name__ == "__main__":
    main()
