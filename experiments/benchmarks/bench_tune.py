"""Tuning as one program, against tuning the usual way: one process per trial, pruned by
Optuna's SuccessiveHalvingPruner, on the same trials; and what a first tune, cold, spends
compiling against what it spends training.

    python experiments/benchmarks/bench_tune.py [--env cartpole] [--trials 27] [--seeds 2] \
        [--eta 3] [--steps 100000] [--backend auto]

(a) ``fppo_jax.tune`` on PPO alone: every rung's trials × seeds in groups of one program's
size (on a CPU, one trial's seeds: one program for the whole tune), the survivors going on from
their state, then its validation race (the default and one finalist on 5 validation seeds);
and beside it the same tune with each rung's runs in one call (a program per rung).
(b) The usual way (RL Baselines3 Zoo's, Stoix's and CleanRL's tuners): an Optuna study with
``SuccessiveHalvingPruner(min_resource=<(a)'s first rung>, reduction_factor=eta)``, the very
settings (a) drew enqueued, and each trial in a process of its own that trains the trial's seeds
(``fppo_jax.sweep`` of them, the JAX way) and reports their mean return at every chunk of
updates, stopping when pruned; then, as RL Zoo retrains its best trials, a process that trains
(a)'s race: the best trial the pruner let finish and the default on the same validation seeds.
Every arm runs in fresh processes on compilation caches of the benchmark's own, empty at the
start: each tune's first run is cold (a first tune on a new machine; its rungs record what it
compiled and trained), then the arms run `--repeats` times each, interleaved, warm, and the
best wall time of each counts. Each arm's wall time, env steps trained, best score and peak
memory (the largest resident set of its processes) are recorded, and the ratio of wall times.
The pruner is asynchronous (a trial is pruned against those reported before it), so its budget
is not (a)'s: the table gives both. Writes experiments/results/bench_tune_<env>.md.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import fppo_jax

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: shared modules

from common import (
    add_record_flags,
    argument_parser,
    header,
    refuse_to_replace,
    write_result,
)

# One trial of the usual way: its seeds as one sweep (the JAX way to train seeds), the mean
# return written after every chunk of updates; it stops when told "stop" (the pruner's answer).
TRIAL = """
import json, sys
import fppo_jax

env, steps, backend, given = sys.argv[1:5]
given = json.loads(given)

def report(snapshot):
    score = float(snapshot.metrics["average_return"][:, -1].mean())
    print(json.dumps({"update": int(snapshot.update), "score": score}), flush=True)
    return sys.stdin.readline().strip() != "stop"

grid = {"variant": "ppo", **{k: [v] for k, v in given["setting"].items()}}
fppo_jax.sweep(env, grid, seeds=given["seeds"], total_steps=int(steps), backend=backend,
               callback=report, progress=False, **given["config"])
"""

# The usual way's last step: its best trial and the default, retrained on validation seeds.
RACE = """
import json, sys
import fppo_jax

env, steps, backend, given = sys.argv[1:5]
given = json.loads(given)
for setting in given["settings"]:
    grid = {"variant": "ppo", **{k: [v] for k, v in setting.items()}}
    fppo_jax.sweep(env, grid, seeds=given["seeds"], total_steps=int(steps), backend=backend,
                   progress=False, **given["config"])
"""
GOAL_WARM = 10.0  # wall time, the usual way over the tune, warm


def peak_of(process: subprocess.Popen[Any]) -> tuple[int, int]:
    """Waits for `process`: its exit status and peak resident memory in KiB."""
    _, status, usage = os.wait4(process.pid, 0)
    process.returncode = os.waitstatus_to_exitcode(status)
    return process.returncode, usage.ru_maxrss


def run_tune(
    args: Any, where: Path, shape: dict[str, Any], cache: Path, chunk: int | None = None
) -> dict[str, Any]:
    """Arm (a): the tune in a process of its own, its programs cached in `cache`, in groups of
    `chunk` runs (None: the default); with the seconds its rungs record compiling and
    training."""
    flags = [
        sys.executable,
        "-m",
        "fppo_jax",
        "tune",
        "--variants",
        "ppo",
        "--tasks",
        args.env,
        "--trials",
        str(args.trials),
        "--seeds-per-trial",
        str(args.seeds),
        "--eta",
        str(args.eta),
        "--steps",
        str(args.steps),
        "--backend",
        args.backend,
        # The validation race at its smallest (one finalist, 5 seeds), which the usual way
        # trains after its search too.
        "--finalists",
        "1",
        "--validation-seeds",
        "5",
        "--output",
        str(where),
        "--quiet",
        *shape["flags"],
    ]
    start = time.perf_counter()
    if chunk is not None:
        flags += ["--chunk", str(chunk)]
    cached = {**os.environ, "FPPO_JAX_CACHE_DIR": str(cache)}
    process = subprocess.Popen(flags, stdout=subprocess.DEVNULL, env=cached)
    status, peak = peak_of(process)
    seconds = time.perf_counter() - start
    if status:
        sys.exit(f"the tune failed ({status})")
    tuned = fppo_jax.load_tune(where)
    results, rungs = tuned.results[args.env]["ppo"], tuned.rungs[args.env]
    return {
        "seconds": seconds,
        "steps": results["env_steps"],
        "best": results["chosen"]["score"],
        "peak": peak,
        "compiling": sum(rung["compile_seconds"] for rung in rungs),
        "training": sum(rung["seconds"] for rung in rungs),
        "search": seconds - rungs[-1]["seconds"],  # the validation race is the last rung
    }


def run_usual(args: Any, where: Path, tuned: Path, shape: dict[str, Any]) -> dict[str, Any]:
    """Arm (b): one process per trial, pruned by Optuna's SuccessiveHalvingPruner."""
    import optuna

    recorded = fppo_jax.load_tune(tuned)
    plan, trials = recorded.plan, recorded.results[args.env]["ppo"]["trials"]
    first = plan["budget"][args.env]["rungs"][0]["ends_at_update"]
    studies = f"{plan['storage']['studies']}/" if "storage" in plan else ""  # the tune's own
    drawn = optuna.load_study(
        study_name=f"{studies}{args.env}/ppo", storage=f"sqlite:///{tuned}/optuna.db"
    )
    storage = f"sqlite:///{where}/usual.db"  # the usual way's own study, its trials the same
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.create_study(
        study_name="usual",
        storage=storage,
        direction="maximize",
        pruner=optuna.pruners.SuccessiveHalvingPruner(
            min_resource=first, reduction_factor=args.eta, min_early_stopping_rate=0
        ),
    )
    start, updates, peak, best = time.perf_counter(), 0, 0, None
    last_update = plan["budget"][args.env]["rungs"][-1]["ends_at_update"]
    for frozen in sorted(drawn.trials, key=lambda t: t.number):
        study.enqueue_trial(frozen.params)
        trial = study.ask()
        for name, d in frozen.distributions.items():
            trial.suggest_float(name, d.low, d.high, log=d.log)
        given = {
            "setting": trials[frozen.number],
            "seeds": plan["seeds"],
            "config": shape["config"],
        }
        process = subprocess.Popen(
            [
                sys.executable,
                "-c",
                TRIAL,
                args.env,
                str(args.steps),
                args.backend,
                json.dumps(given),
            ],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        done, score = 0, None
        for line in process.stdout:
            reported = json.loads(line)
            done, score = reported["update"], reported["score"]
            trial.report(score, done)
            process.stdin.write("stop\n" if trial.should_prune() else "go\n")
            process.stdin.flush()
        status, used = peak_of(process)
        if status:
            sys.exit(f"trial {trial.number} failed ({status})")
        peak, updates = max(peak, used), updates + done
        if done < last_update:
            study.tell(trial, state=optuna.trial.TrialState.PRUNED)
        else:
            study.tell(trial, score)
            best = score if best is None else max(best, score)
    chosen = trials[study.best_trial.number] if best is not None else trials[0]
    race = {"settings": [trials[0], chosen], "seeds": plan["validation"]["seeds"]}
    raced_from = time.perf_counter()
    process = subprocess.Popen(
        [
            sys.executable,
            "-c",
            RACE,
            args.env,
            str(args.steps),
            args.backend,
            json.dumps({**race, "config": shape["config"]}),
        ]
    )
    status, used = peak_of(process)
    if status:
        sys.exit(f"the race failed ({status})")
    seconds = time.perf_counter() - start
    budget = plan["budget"][args.env]
    samples = budget["env_steps_per_full_run"] // budget["rungs"][-1]["ends_at_update"]
    raced = len(race["settings"]) * len(race["seeds"]) * budget["env_steps_per_full_run"]
    return {
        "seconds": seconds,
        "steps": updates * samples * len(plan["seeds"]) + raced,
        "best": best,
        "peak": max(peak, used),
        "search": raced_from - start,
    }


def _seconds(runs: list[dict[str, Any]]) -> str:
    return ", ".join(f"{run['seconds']:.1f}" for run in runs)


def _score(value: float | None) -> str:
    return "—" if value is None else f"{value:.1f}"


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--env", default="cartpole")
    parser.add_argument("--trials", type=int, default=27)
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--eta", type=int, default=3)
    parser.add_argument("--steps", type=int, default=100_000)
    parser.add_argument("--backend", default="auto")
    parser.add_argument("--tiny", action="store_true", help="a tiny run shape (smoke runs)")
    parser.add_argument("--repeats", type=int, default=2, help="runs of each arm, interleaved")
    add_record_flags(parser)
    args = parser.parse_args()
    output = args.results / f"bench_tune_{args.env}.md"
    refuse_to_replace([output], args.force)
    tiny = {"num_envs": 4, "num_steps": 32, "num_minibatches": 4, "num_epochs": 2}
    shape = {
        "config": tiny if args.tiny else {},
        "flags": ["--num-envs", "4", "--num-steps", "32", "--minibatches", "4", "--epochs", "2"]
        if args.tiny
        else [],
    }
    wide = args.trials * args.seeds  # the first rung's runs: each rung's in one call
    with tempfile.TemporaryDirectory() as work:
        # The benchmark's own caches, empty at the start: the tune's and the usual way's, and
        # the wide tune's apart, so that each tune's first run compiles all it trains.
        cache, wide_cache = Path(work) / "cache", Path(work) / "cache-wide"
        os.environ["FPPO_JAX_CACHE_DIR"] = str(cache)
        cold = run_tune(args, Path(work) / "cold" / "tune", shape, cache)
        cold_wide = run_tune(args, Path(work) / "cold-wide" / "tune", shape, wide_cache, wide)
        tuned_runs, wide_runs, usual_runs = [], [], []
        for repeat in range(args.repeats):  # interleaved, warm
            where = Path(work) / str(repeat)
            tuned_runs.append(run_tune(args, where / "tune", shape, cache))
            wide_runs.append(run_tune(args, where / "wide" / "tune", shape, wide_cache, wide))
            usual_runs.append(run_usual(args, where, where / "tune", shape))
    tuned = min(tuned_runs, key=lambda r: r["seconds"])
    widest = min(wide_runs, key=lambda r: r["seconds"])
    usual = min(usual_runs, key=lambda r: r["seconds"])
    rows = [
        ("fppo-jax tune (one program)", tuned),
        (f"fppo-jax tune, each rung's runs in one call (--chunk {wide})", widest),
        ("one process per trial, SuccessiveHalvingPruner, then the race", usual),
    ]
    ratio = usual["seconds"] / tuned["seconds"]
    met = "met" if ratio >= GOAL_WARM else "missed"
    # The search alone: the usual way's wall time before its race process; the tune's less
    # its race rung's training (its start, draws and report stay in).
    searched = usual["search"] / tuned["search"]
    first = "met" if cold["compiling"] <= cold["training"] else "missed"
    lines = [
        *header(f"Tuning PPO on {args.env}: one program against one process per trial"),
        "",
        f"{args.trials} trials × {args.seeds} seeds, η = {args.eta}, {args.steps:,} env steps "
        f"per full run, backend {args.backend}, then the race of the default and one finalist "
        "on 5 validation seeds in both arms. Every process shares the benchmark's own "
        "compilation cache, empty at the start.",
        "",
        f"A first tune, cold (nothing cached): {cold['seconds']:.1f} s, of which "
        f"{cold['compiling']:.1f} s compiling and {cold['training']:.1f} s training (its rungs' "
        f"records); compiling at most training: **{first}**. With each rung's runs in one "
        f"call instead (a program per rung, `--chunk {wide}`): {cold_wide['seconds']:.1f} s, "
        f"{cold_wide['compiling']:.1f} s compiling and {cold_wide['training']:.1f} s training.",
        "",
        f"Then warm, the arms {args.repeats} times each, interleaved, the best wall time of each "
        "counting: "
        + "; ".join(
            f"{name} {_seconds(runs)} s"
            for name, runs in (
                ("tune", tuned_runs),
                ("tune, each rung in one call", wide_runs),
                ("the usual way", usual_runs),
            )
        )
        + ".",
        "",
        "| arm | wall s | env steps trained | best trial's score | peak memory (MiB) |",
        "|---|---|---|---|---|",
        *(
            f"| {name} | {r['seconds']:.1f} | {r['steps']:,} | {_score(r['best'])} | "
            f"{r['peak'] / 1024:.0f} |"
            for name, r in rows
        ),
        "",
        f"Wall time, the usual way over the tune, warm: **{ratio:.1f}×** (goal {GOAL_WARM:g}×: "
        f"{met}); per env step trained: "
        f"**{(usual['seconds'] / usual['steps']) / (tuned['seconds'] / tuned['steps']):.1f}×**. "
        f"The search alone (the usual way's {usual['search']:.1f} s before its race; the "
        f"tune's {tuned['search']:.1f} s, its wall time less its race's training): "
        f"**{searched:.1f}×** ({'met' if searched >= GOAL_WARM else 'missed'}). "
        f"The warm tune's rungs record {tuned['compiling']:.1f} s loading its program and "
        f"{tuned['training']:.1f} s training; the rest of its {tuned['seconds']:.1f} s starts "
        "the process, draws the trials and writes the report. Each rung's runs in one call "
        f"train in {widest['training']:.1f} s (the one program's groups of one trial's seeds: "
        f"{tuned['training'] / widest['training']:.2f}× that time) and load "
        f"{widest['compiling']:.1f} s of programs, one per rung.",
    ]
    write_result(output, lines)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
