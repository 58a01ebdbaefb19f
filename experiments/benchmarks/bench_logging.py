"""What feedback costs: training throughput with and without progress, logging and checkpoints.

    python experiments/benchmarks/bench_logging.py [--steps 500000] [--chunks 20] [--repeats 3]

The same run (CartPole, FPPO-LP, the paper preset, seed 0) through ``fppo_jax.train`` in four
ways, side by side: (a) one compiled call, nothing on the host until the end; (b) `--chunks`
compiled calls with nothing done between them; (c) the same chunks with a progress line, the
CSV and the TensorBoard log written after each; (d) as (c), plus a full checkpoint after each.
Throughput is env steps over training time (compilation excluded), the best of `--repeats`,
the arms interleaved. All four end with bit-identical parameters, which is checked.
Writes experiments/results/bench_logging.md.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import jax
import numpy as np

import fppo_jax
from fppo_jax.run.progress import print_progress

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: shared modules

from common import add_record_flags, argument_parser, header, refuse_to_replace, write_result


def arms(chunks: int, per_call: int, scratch: Path) -> dict[str, dict]:
    def quiet(_: fppo_jax.Progress) -> None:
        pass

    counter = iter(range(10**6))
    return {
        "(a) one compiled call": lambda: {},
        f"(b) {chunks} calls, nothing between": lambda: {"progress": quiet},
        f"(c) {chunks} calls + progress line, CSV, TensorBoard": lambda: {
            "progress": print_progress,
            "log_dir": scratch / f"log{next(counter)}",
        },
        "(d) as (c) + a checkpoint after each call": lambda: {
            "progress": print_progress,
            "log_dir": scratch / f"log{next(counter)}",
            "checkpoint_dir": scratch / f"ckpt{next(counter)}",
            "checkpoint_every": per_call,
        },
    }


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--steps", type=int, default=500_000)
    parser.add_argument("--chunks", type=int, default=20)
    parser.add_argument("--repeats", type=int, default=3)
    add_record_flags(parser)
    args = parser.parse_args()
    path = args.results / "bench_logging.md"
    refuse_to_replace([path], args.force)

    num_updates = args.steps // 2048
    per_call = -(-num_updates // args.chunks)
    best: dict[str, float] = {}
    params: dict[str, object] = {}
    with tempfile.TemporaryDirectory() as scratch:
        ways = arms(args.chunks, per_call, Path(scratch))
        for repeat in range(args.repeats):
            for name, options in ways.items():
                print(f"repeat {repeat + 1}: {name}", file=sys.stderr)
                result = fppo_jax.train("cartpole", "fppo-lp", total_steps=args.steps, **options())
                rate = int(result.metrics["env_steps"][-1]) / result.train_seconds
                best[name] = max(best.get(name, 0.0), rate)
                params[name] = result.params
    reference = jax.tree.leaves(params["(a) one compiled call"])
    identical = all(
        all(np.array_equal(x, y) for x, y in zip(reference, jax.tree.leaves(p), strict=True))
        for p in params.values()
    )
    baseline = best["(a) one compiled call"]
    with_log, with_checkpoints = list(best.values())[2:]
    checkpoints = -(-num_updates // per_call)
    per_checkpoint = (args.steps / with_checkpoints - args.steps / with_log) / checkpoints
    lines = [
        *header("What feedback costs: progress, logging and checkpoints"),
        "",
        f"Run: `fppo_jax.train('cartpole', 'fppo-lp', total_steps={args.steps})`, the paper "
        f"preset (8 envs × 256 steps, 32 minibatches × 10 epochs), {num_updates} updates; "
        f"{per_call} updates per call when chunked. Throughput is env steps / training seconds "
        f"(compilation excluded), best of {args.repeats}, arms interleaved.",
        "",
        "| how | env steps/s | ratio to (a) |",
        "|---|---|---|",
        *[f"| {name} | {rate:,.0f} | {rate / baseline:.3f} |" for name, rate in best.items()],
        "",
        f"Final parameters bit-identical across the four: {'yes' if identical else 'NO'}.",
        "",
        f"Cost of one checkpoint, (d) − (c) over its {checkpoints} checkpoints: "
        f"{per_checkpoint * 1000:.0f} ms of training time.",
        "",
        "After each call the host fetches that call's metrics, writes the CSV rows and "
        "TensorBoard scalars, prints the line and (d) copies the state to the host and starts "
        "an asynchronous orbax save; the next call is dispatched before that work starts, so "
        "the two overlap.",
    ]
    write_result(path, lines)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
