"""The same runs as one sweep vs one after another with train: training time and compilation
apart.

    python experiments/benchmarks/bench_sweep.py [--seeds 5] [--steps 100000]

25 runs by default: the 5 compared variants × 5 seeds on CartPole with the paper's protocol.
Both sides produce every run's metrics. The sequential `train` calls compile once: every later
call has the same shapes and reuses the program. The ratios are sequential / sweep, for the
training time alone (each result's `train_seconds`: the compiled calls, with what the host
does between them) and for the wall time (compilation and set-up included).
Writes experiments/results/bench_sweep.md.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from fppo_jax import sweep, train

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: shared modules

from common import (
    PAPER_VARIANTS,
    RESULTS,
    add_output_flags,
    argument_parser,
    header,
    refuse_to_replace,
    write_result,
)


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--steps", type=int, default=100_000)
    add_output_flags(parser, RESULTS / "bench_sweep.md")
    args = parser.parse_args()
    refuse_to_replace([args.output], args.force, elsewhere="--output FILE")
    runs = len(PAPER_VARIANTS) * args.seeds

    start = time.perf_counter()
    result = sweep(
        "cartpole", {"variant": list(PAPER_VARIANTS)}, seeds=args.seeds, total_steps=args.steps
    )
    sweep_wall = time.perf_counter() - start
    sweep_train = result.train_seconds
    print(f"sweep: {sweep_train:.1f} s training, {result.compile_seconds:.1f} s compiling")

    start, compile_seconds, train_seconds = time.perf_counter(), 0.0, 0.0
    for variant in PAPER_VARIANTS:
        for seed in range(args.seeds):
            run = train("cartpole", variant, seed=seed, total_steps=args.steps)
            compile_seconds += run.compile_seconds
            train_seconds += run.train_seconds
    sequence_wall = time.perf_counter() - start
    print(f"sequence: {train_seconds:.1f} s training, {compile_seconds:.1f} s compiling")

    steps = runs * int(result.metrics["env_steps"][0, -1])
    training_ratio = train_seconds / sweep_train
    lines = [
        *header("A sweep vs the same runs one after another"),
        "",
        f"{runs} runs: {', '.join(PAPER_VARIANTS)} × {args.seeds} seeds on CartPole, the paper's "
        f"protocol, {args.steps:,} steps each. Training is the compiled calls and the host's "
        "work between them; the sequential calls compile once and reuse the program.",
        "",
        "| how | training (s) | env steps/s in training | compiling (s) | wall time (s) |",
        "|---|---|---|---|---|",
        f"| one sweep ({result.config['runs_per_call']} runs per call) | {sweep_train:.1f} | "
        f"{steps / sweep_train:,.0f} | {result.compile_seconds:.1f} | {sweep_wall:.1f} |",
        f"| {runs} × `train` | {train_seconds:.1f} | {steps / train_seconds:,.0f} | "
        f"{compile_seconds:.1f} | {sequence_wall:.1f} |",
        "",
        f"Training time alone: the sweep is **{training_ratio:.2f}×** faster (goal: 2×, "
        f"{'met' if training_ratio >= 2 else 'missed'}); wall time "
        f"{sequence_wall / sweep_wall:.2f}×.",
    ]
    write_result(args.output, lines)
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
