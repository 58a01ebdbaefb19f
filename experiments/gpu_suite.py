"""The measurements that need a GPU, in parts of under 9 minutes, each writing its results as it
ends.

    python experiments/gpu_suite.py                       # every part, about 25 minutes on one H100
    python experiments/gpu_suite.py --parts throughput-hopper table1-hopper
    python experiments/gpu_suite.py --smoke          # the same parts, tiny, on a CPU, in a temp dir

Parts (each one of the experiments' own scripts, run in a process of its own, with a time limit
of `--part-seconds`):
- `throughput-<task>` for Hopper and Ant: the `massive` preset at 2,048, 8,192 and 32,768
  environments on MJX; the environment alone, fppo-jax and Brax's own PPO trainer on the same
  environment, with compile times (`bench_mujoco.py`; results `bench_mujoco_<task>_<N>envs_gpu.md`);
- `table1-<task>` for the six MuJoCo tasks: Table 1's rows on MJX, one sweep per task
  (`table1_mujoco.py --backend mjx`; results `table1_mujoco_mjx.md` and its folder);
- `ablation-<task>` for Walker2d and Ant: Fig. 6 on MJX (`ablation.py --backend mjx`; results
  `ablation_mjx/`).
After each part, <results>/gpu_suite_<platform>.md is written again: every part run so far,
its status, its time and the last lines it printed. A part that fails or runs out of time is
recorded as such and the next one runs. `--smoke` runs every kind of part once, on Reacher, at
sizes a CPU finishes in a minute or two (the throughput part on MJX, the sweeps on native
MuJoCo): the suite's own test; it writes to a new temporary directory unless `--results` names
another, and never into experiments/results. A result already recorded is refused unless
`--force` (every part's script refuses it too).
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

from common import (
    add_smoke_flags,
    argument_parser,
    header,
    refuse_to_replace,
    results_of,
    write_result,
)

HERE = Path(__file__).resolve().parent
MUJOCO = ("hopper", "walker2d", "halfcheetah", "ant", "reacher", "swimmer")
THROUGHPUT_ENVS = (2048, 8192, 32768)


def parts(smoke: bool) -> dict[str, list[list[str]]]:
    """Each part's commands: a script's name and its arguments."""
    if smoke:
        tiny = ["--num-envs", "16", "--num-steps", "8", "--minibatches", "2", "--epochs", "1"]
        tiny += ["--updates", "2"]
        # MJX compiles a training program for half a minute on a CPU: the smoke run's
        # sweeps train on native MuJoCo, through the same scripts.
        one = ["--backend", "native", "--tasks", "reacher", "--seeds", "1"]
        return {
            "throughput-reacher": [
                ["benchmarks/bench_mujoco.py", "--env", "reacher", "--backends", "mjx", *tiny]
            ],
            "table1-reacher": [
                ["paper/table1_mujoco.py", *one, "--variants", "ppo", "fppo-lp", "--steps", "4096"]
            ],
            "ablation-reacher": [["paper/ablation.py", *one, "--steps", "2048"]],
        }
    massive = ["--preset", "massive", "--backends", "mjx", "--updates", "30"]
    throughput = {
        f"throughput-{task}": [
            ["benchmarks/bench_mujoco.py", "--env", task, *massive, "--num-envs", str(n)]
            for n in THROUGHPUT_ENVS
        ]
        for task in ("hopper", "ant")
    }
    table1 = {
        f"table1-{task}": [["paper/table1_mujoco.py", "--backend", "mjx", "--tasks", task]]
        for task in MUJOCO
    }
    ablation = {
        f"ablation-{task}": [["paper/ablation.py", "--backend", "mjx", "--tasks", task]]
        for task in ("walker2d", "ant")
    }
    return {**throughput, **table1, **ablation}


def run_part(commands: list[list[str]], results: Path, seconds: float, force: bool) -> dict:
    """Run a part's commands one after another, each given `--results` (and `--force`), within
    `seconds` in all; its status, time and output's last lines."""
    start, lines, status = time.perf_counter(), [], "done"
    for script, *arguments in commands:
        left = seconds - (time.perf_counter() - start)
        command = [sys.executable, str(HERE / script), *arguments, "--results", str(results)]
        command += ["--force"] if force else []
        try:
            done = subprocess.run(
                command, capture_output=True, text=True, timeout=max(left, 1), cwd=HERE.parent
            )
        except subprocess.TimeoutExpired as expired:
            output = expired.stdout or b""
            text = output.decode() if isinstance(output, bytes) else output
            lines += text.splitlines()[-5:]
            status = f"out of time after {seconds:.0f} s"
            break
        lines += (done.stdout + done.stderr).splitlines()[-5:]
        if done.returncode:
            status = f"failed ({script} exited {done.returncode})"
            break
    return {"status": status, "seconds": round(time.perf_counter() - start, 1), "tail": lines}


def report(done: dict[str, dict], path: Path) -> None:
    lines = [
        *header("GPU suite"),
        "",
        "| part | status | seconds |",
        "|---|---|---|",
        *[f"| {name} | {part['status']} | {part['seconds']:.0f} |" for name, part in done.items()],
        "",
    ]
    for name, part in done.items():
        lines += [f"## {name}", "", "```", *part["tail"], "```", ""]
    write_result(path, lines)
    (path.with_suffix(".json")).write_text(json.dumps(done, indent=1) + "\n")


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--parts", nargs="+", help="default: every part (see --list)")
    parser.add_argument("--list", action="store_true", help="print the parts and exit")
    add_smoke_flags(parser, "tiny parts, for a CPU")
    parser.add_argument("--part-seconds", type=float, default=540, help="each part's time limit")
    args = parser.parse_args()
    planned = parts(args.smoke)
    if args.list:
        print("\n".join(planned))
        return
    unknown = sorted(set(args.parts or ()) - set(planned))
    if unknown:
        sys.exit(f"unknown part {', '.join(unknown)}; parts: {', '.join(planned)}")
    chosen = args.parts or list(planned)
    results = results_of(args, "gpu-suite")
    import jax

    platform = jax.devices()[0].platform
    if platform == "cpu" and not args.smoke:
        sys.exit("JAX sees no GPU here: these parts take hours on a CPU (--smoke runs them tiny)")
    results.mkdir(parents=True, exist_ok=True)
    path = results / f"gpu_suite_{platform}.md"
    refuse_to_replace([path], args.force)
    done: dict[str, dict] = {}
    for name in chosen:
        print(f"{name}…", flush=True)
        done[name] = run_part(planned[name], results, args.part_seconds, args.force)
        print(f"{name}: {done[name]['status']} in {done[name]['seconds']:.0f} s", flush=True)
        report(done, path)
    print(f"wrote {path}")
    if any(part["status"] != "done" for part in done.values()):
        sys.exit(1)


if __name__ == "__main__":
    main()
