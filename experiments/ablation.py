"""The paper's Fig. 6 ablation: FPPO-LP's α and FPPO-QP's k, × seeds, as one program per task.

    python experiments/ablation.py                                  # Walker2d and Ant
    python experiments/ablation.py --backend native                 # the same on a CPU
    python experiments/ablation.py --tasks reacher --steps 4096 --seeds 1   # a smoke run

α ∈ {1.1, …, 1.5} and k ∈ {0.1, …, 0.5} (SPEC §2): 10 settings × 5 seeds = 50 runs of 1M
steps per task, one vmapped sweep (`fppo_jax.sweep`, `paper` preset), chunked automatically to
fit device memory, on `--backend` (default auto: MJX on a GPU, native MuJoCo on a CPU). Writes,
per task, <results>/ablation_<backend>/<task>/ (curves.csv, sweep.json, curves.png,
ablation.png) and a Markdown summary, ablation.md, beside them.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import jax

from fppo_jax import sweep
from fppo_jax.envs import BACKENDS, TASKS, choose_backend
from fppo_jax.plots import plot_sweep

ALPHAS = [1.1, 1.2, 1.3, 1.4, 1.5]
KS = [0.1, 0.2, 0.3, 0.4, 0.5]
RESULTS = Path(__file__).resolve().parent / "results"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tasks", nargs="+", default=["walker2d", "ant"], choices=list(TASKS))
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--steps", type=int, default=1_000_000)
    parser.add_argument("--chunk", type=int, help="runs per compiled call (default: automatic)")
    parser.add_argument("--backend", default="auto", choices=list(BACKENDS))
    parser.add_argument("--results", type=Path, default=RESULTS, help="where results go")
    args = parser.parse_args()

    platform = jax.devices()[0].platform
    backend = choose_backend(args.tasks[0], args.backend)[0]
    out = args.results / f"ablation_{backend}"
    lines = [
        "# Fig. 6 ablation: FPPO-LP α and FPPO-QP k",
        "",
        f"- Machine: {platform.upper()} ({jax.devices()[0].device_kind}), jax {jax.__version__}; "
        f"backend {backend}",
        f"- Command: `python experiments/ablation.py {' '.join(sys.argv[1:])}`",
        f"- α ∈ {ALPHAS} (FPPO-LP), k ∈ {KS} (FPPO-QP), {args.seeds} seeds, "
        f"{args.steps:,} steps, `paper` preset (learning rate annealed linearly to 0, as "
        "baselines' ppo2 MuJoCo defaults); each task one sweep.",
        "",
    ]
    for task in args.tasks:
        grid = {"variant": ["fppo-lp", "fppo-qp"], "alpha": ALPHAS, "k": KS}
        start = time.perf_counter()
        result = sweep(
            task,
            grid,
            seeds=args.seeds,
            total_steps=args.steps,
            chunk=args.chunk,
            backend=args.backend,
            progress=True,
        )
        seconds = time.perf_counter() - start
        result.write(out / task)
        plots = plot_sweep(result, out / task)
        lines += [
            f"## {task}",
            "",
            f"{len(result.runs)} runs in {seconds:.0f} s wall ({result.compile_seconds:.0f} s "
            f"compiling), {result.config['runs_per_call']} runs per compiled call. Plots: "
            + ", ".join(f"`{p.relative_to(out)}`" for p in plots),
            "",
            result.table(),
            "",
        ]
    path = out / "ablation.md"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
