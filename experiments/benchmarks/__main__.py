"""Benchmarks: training throughput against peers and across backends, sweeps, parts, feedback
and start-up, each measured side by side in one run.

    python experiments/benchmarks            # its scripts, each with what it does
    python experiments/benchmarks --smoke    # each one run tiny, into a new temporary directory
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: shared modules

from common import folder_entry_point

TINY_UPDATE = "--num-envs 16 --num-steps 8 --minibatches 2 --epochs 1 --updates 2"
SMOKE = {
    "bench_cartpole.py": "--smoke --output {tmp}/bench_cartpole.md",
    "bench_mujoco.py": f"--env reacher --backends mjx {TINY_UPDATE} --results {{tmp}}",
    "bench_gymnasium.py": "--steps 4096 --repeats 1 --results {tmp}",
    "bench_sweep.py": "--seeds 2 --steps 4096 --output {tmp}/bench_sweep.md",
    "bench_parts.py": "--seeds 1 --steps 2048 --repeats 1 --results {tmp}",
    "bench_logging.py": "--steps 4096 --repeats 1 --results {tmp}",
    "bench_startup.py": "--smoke",
    "bench_tune.py": "--trials 4 --eta 2 --steps 1024 --tiny --results {tmp}",
    "bench_trust.py": "--tasks cartpole --tiny --steps 1024 --budget 58 --test-seeds 4 "
    "--results {tmp}",
}

if __name__ == "__main__":
    folder_entry_point(__doc__, Path(__file__).resolve().parent, SMOKE)
