"""What users wait for before anything trains: importing the package, and the README's first
command with an empty compilation cache (cold) and with the cache that run filled (warm).

    python experiments/benchmarks/bench_startup.py [--repeats 5]
    python experiments/benchmarks/bench_startup.py --smoke    # tiny, into a new temporary directory

Each measurement is the wall time of a fresh process of this checkout, from its start to its
exit; the arms are interleaved and each one's best of `--repeats` is kept. Imports: ``import
jax``, ``import fppo_jax``, ``from fppo_jax import train`` and ``fppo-jax --help``. The README's
first command (``fppo-jax train --env cartpole --variant fppo-lp --steps 50000``): cold, in a
new empty cache directory (``FPPO_JAX_CACHE_DIR``); warm, the same command again in that
directory; another budget, the command with ``--steps 60000`` (29 updates against 24, in
chunks of two updates as theirs are) in that directory, which its program serves too; and
with the cache off, for what writing the cache costs. Writes
experiments/results/bench_startup.md; `--smoke` trains a few tiny updates instead and writes
into a new temporary directory unless `--results` names another (never the recorded results).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: shared modules

from common import (
    add_smoke_flags,
    argument_parser,
    header,
    refuse_to_replace,
    results_of,
    write_result,
)

ROOT = Path(__file__).resolve().parents[2]
FIRST_COMMAND = ["train", "--env", "cartpole", "--variant", "fppo-lp", "--steps", "50000"]
SMOKE_COMMAND = [*FIRST_COMMAND[:-1], "512", "--num-envs", "4", "--num-steps", "32"]
SMOKE_COMMAND += ["--minibatches", "4", "--epochs", "2"]
# The same command with another step budget whose chunks are as long (see the docstring).
OTHER_STEPS = {"50000": "60000", "512": "768"}
IMPORTS = {
    "import jax": ["-c", "import jax"],
    "import fppo_jax": ["-c", "import fppo_jax"],
    "from fppo_jax import train": ["-c", "from fppo_jax import train"],
    "fppo-jax --help": ["-m", "fppo_jax", "--help"],
}


def timed(arguments: list[str], cache: str) -> tuple[float, str]:
    """Wall seconds of ``python <arguments>`` in a fresh process of this checkout, with
    FPPO_JAX_CACHE_DIR set to `cache` (and no cache directory of JAX's own), and its output."""
    env = {k: v for k, v in os.environ.items() if k != "JAX_COMPILATION_CACHE_DIR"}
    env |= {"PYTHONPATH": str(ROOT), "FPPO_JAX_CACHE_DIR": cache}
    start = time.perf_counter()
    done = subprocess.run(
        [sys.executable, *arguments],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    return time.perf_counter() - start, done.stdout + done.stderr


def compile_seconds(output: str) -> float:
    """The compile time the run's summary reports."""
    return float(re.search(r"compile ([\d.]+) s", output).group(1))


def shared_machine(load_before: float, load_after: float, cores: int) -> bool:
    """Whether other work shared the machine, by the 1-minute load average before and after:
    more than half the cores busy, beyond the one core this benchmark's processes keep busy
    (which the load after includes)."""
    return max(load_before, load_after - 1) > 0.5 * cores


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--repeats", type=int, default=5)
    add_smoke_flags(parser, "a few tiny updates, once")
    args = parser.parse_args()
    path = results_of(args, "bench-startup") / "bench_startup.md"
    refuse_to_replace([path], args.force)
    command = SMOKE_COMMAND if args.smoke else FIRST_COMMAND
    repeats = 1 if args.smoke else args.repeats
    at = command.index("--steps") + 1
    other = [*command[:at], OTHER_STEPS[command[at]], *command[at + 1 :]]

    loads = [os.getloadavg()[0]]
    best: dict[str, float] = {}
    compiled: dict[str, float] = {}

    def measure(name: str, arguments: list[str], cache: str) -> None:
        seconds, output = timed(arguments, cache)
        print(f"{name}: {seconds:.2f} s", file=sys.stderr)
        best[name] = min(best.get(name, float("inf")), seconds)
        if arguments[:2] == ["-m", "fppo_jax"] and arguments[2] == "train":
            compiled[name] = min(compiled.get(name, float("inf")), compile_seconds(output))

    with tempfile.TemporaryDirectory() as scratch:
        for repeat in range(repeats):
            for name, arguments in IMPORTS.items():
                measure(name, arguments, "off")
            cache = str(Path(scratch) / f"cache{repeat}")  # new and empty: cold
            for name, directory in [("cold", cache), ("warm", cache), ("cache off", "off")]:
                measure(name, ["-m", "fppo_jax", *command], directory)
                if name == "warm":
                    measure("another budget", ["-m", "fppo_jax", *other], cache)
    loads.append(os.getloadavg()[0])

    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    shared = shared_machine(loads[0], loads[-1], cores)
    first = " ".join(["fppo-jax", *command])
    lines = [
        *header("Startup: importing, and the first command cold and warm"),
        "- Load average (1 min) at the start and the end: "
        + " and ".join(f"{load:.1f}" for load in loads)
        + f" on {cores} cores"
        + (": the machine was shared with other work while this ran" if shared else ""),
        "",
        f"Wall time of a fresh process, best of {repeats}, the arms interleaved.",
        "",
        "| import | seconds | beyond `import jax` |",
        "|---|---|---|",
        *[
            f"| `{name}` | {best[name]:.2f} | {best[name] - best['import jax']:+.2f} |"
            for name in IMPORTS
        ],
        "",
        f"`{first}`: cold in a new empty compilation cache, warm in the cache it filled, and "
        f"with another step budget (`--steps {other[at]}`) in that cache.",
        "",
        "| run | seconds | compile (its summary) | ratio to cold |",
        "|---|---|---|---|",
        *[
            f"| {name} | {best[name]:.2f} | {compiled[name]:.2f} s | "
            f"{best[name] / best['cold']:.2f} |"
            for name in ("cold", "warm", "another budget", "cache off")
        ],
    ]
    write_result(path, lines)
    print("\n".join(lines))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
