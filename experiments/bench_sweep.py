"""The same runs as one sweep vs one after another with train: wall time, compilation included.

    python experiments/bench_sweep.py [--seeds 5] [--steps 100000]

25 runs by default: the 5 compared variants × 5 seeds on CartPole with the paper's protocol.
Both sides produce every run's metrics; the ratio is sequential time / sweep time.
Writes experiments/results/bench_sweep.md.
"""

from __future__ import annotations

import argparse
import datetime
import os
import time
from pathlib import Path

import jax
from bench_cartpole import cpu_model

from fppo_jax import sweep, train

VARIANTS = ("fppo-lp", "fppo-qp", "ppo", "tr-ppo", "ppo-rb")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--steps", type=int, default=100_000)
    parser.add_argument(
        "--output", type=Path, default=Path(__file__).parent / "results" / "bench_sweep.md"
    )
    args = parser.parse_args()
    runs = len(VARIANTS) * args.seeds

    start = time.perf_counter()
    result = sweep(
        "cartpole", {"variant": list(VARIANTS)}, seeds=args.seeds, total_steps=args.steps
    )
    sweep_seconds = time.perf_counter() - start
    print(f"sweep: {sweep_seconds:.1f} s ({result.compile_seconds:.1f} s compiling)")

    start, compile_seconds = time.perf_counter(), 0.0
    for variant in VARIANTS:
        for seed in range(args.seeds):
            compile_seconds += train(
                "cartpole", variant, seed=seed, total_steps=args.steps
            ).compile_seconds
    sequence_seconds = time.perf_counter() - start
    print(f"sequence: {sequence_seconds:.1f} s ({compile_seconds:.1f} s compiling)")

    steps = runs * int(result.metrics["env_steps"][0, -1])
    lines = [
        "# A sweep vs the same runs one after another",
        "",
        f"Machine: {cpu_model()}, {os.cpu_count()} cores, no GPU; jax {jax.__version__}; "
        f"{datetime.date.today()}.",
        "",
        f"Command: `python experiments/bench_sweep.py --seeds {args.seeds} --steps {args.steps}`",
        "",
        f"{runs} runs: {', '.join(VARIANTS)} × {args.seeds} seeds on CartPole, the paper's "
        f"protocol, {args.steps:,} steps each. Wall time includes compilation.",
        "",
        "| how | wall time (s) | of which compiling (s) | env steps/s |",
        "|---|---|---|---|",
        f"| one sweep ({result.config['runs_per_call']} runs per call) | {sweep_seconds:.1f} | "
        f"{result.compile_seconds:.1f} | {steps / sweep_seconds:,.0f} |",
        f"| {runs} × `train` | {sequence_seconds:.1f} | {compile_seconds:.1f} | "
        f"{steps / sequence_seconds:,.0f} |",
        "",
        f"The sweep is **{sequence_seconds / sweep_seconds:.1f}×** faster (goal: 3×).",
    ]
    args.output.write_text("\n".join(lines) + "\n")
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
