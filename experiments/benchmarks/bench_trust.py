"""Does tuning leave PPO at least as strong as its default? PPO tuned by racing with the
validation race (``fppo_jax.tune(..., scheduler="racing")``), then the chosen setting and the
default trained side by side on fresh test seeds, per task.

    python experiments/benchmarks/bench_trust.py --tasks cartpole,acrobot,mountaincar
    python experiments/benchmarks/bench_trust.py --tasks hopper        # a part of its own
    python experiments/benchmarks/bench_trust.py --tasks hopper --rounds 1   # one round of it
    python experiments/benchmarks/bench_trust.py --tasks hopper --part 1/3   # a third of a round
    python experiments/benchmarks/bench_trust.py --report              # the write-up alone

Per task, in <results>/trust/<task>/: the tune (``tune/``: racing over 9 trials, 2 tuning seeds
a round, then the default and 3 finalists on 10 validation seeds, within --budget full runs),
then one sweep of the chosen setting and the default on test seeds 0 … 19, evaluated once at
the end (``test/``: the deterministic policy's mean return over 10 episodes, the study's eval
endpoint; where the race chose a run shape of its own, the default's runs in ``test-default/``).
The tune searches the run's shape as racing does by default (``fppo_jax.core.shape_space``).
A task recorded is not trained again: the same command goes on where it stopped, with the
next round or share of the tune, or the test sweep not yet written.
The write-up, ``bench_trust.md``, gives per task P(tuned > default) with its 95% bootstrap
interval, the IQM of both on the test seeds beside RL Zoo's tuned PPO, the race's outcome, the
tune's wall time and its budget in full runs; and the goals: P ≥ 0.5 on every task, its interval
above 0.5 on the MuJoCo ones, tuned PPO at RL Zoo's level. Nothing here is a test of FPPO.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

import fppo_jax
from fppo_jax.core.shape_space import ChoiceValue, config_values, split_setting
from fppo_jax.stats import statistics

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: shared modules

from common import (
    RUN_RECORD,
    argument_parser,
    header,
    machine,
    read_run_record,
    write_result,
    write_run_record,
)

TEST_SEEDS = 20
EVAL_EPISODES = 10
TRIALS, SEEDS_PER_ROUND, FINALISTS, VALIDATION_SEEDS = 9, 2, 3, 10
MUJOCO = ("hopper", "halfcheetah", "swimmer", "walker2d", "ant", "reacher")
# RL Baselines3 Zoo's tuned PPO (benchmark.md, one run, deterministic evaluation, 1M steps).
ZOO = {"hopper": 2410.0, "halfcheetah": 5819.0, "swimmer": 282.0}
GOAL = {"halfcheetah": 3000.0}  # at least this IQM where RL Zoo's is out of reach
# The recorded tuned verdict's studies (experiments/results/tuned.md: 9 trials × 2 tuning seeds
# at a third of the budget, η = 3), under <results>: their PPO trained on test seeds from 0 too,
# scored at the same endpoint (one evaluation after the final update, 10 episodes).
RECORDED = {
    **dict.fromkeys(("cartpole", "acrobot", "mountaincar"), "tuned/classic/study"),
    **{task: f"tuned/mujoco/study-{task}" for task in ("hopper", "halfcheetah", "swimmer")},
}


def tune_task(
    task: str,
    where: Path,
    budget: int,
    tiny: dict[str, int],
    steps: int | None,
    rounds: int | None,
    part: tuple[int, int] | None = None,
) -> None:
    """The task's tune, `rounds` rounds of it (all if None), or `part`'s share of its next
    round: it goes on from what is recorded, and its record adds up the wall time of its
    parts."""
    began = time.perf_counter()
    fppo_jax.tune(
        task,
        "ppo",
        output=where,
        scheduler="racing",
        trials=TRIALS,
        seeds=SEEDS_PER_ROUND,
        budget=budget,
        finalists=FINALISTS,
        validation_seeds=VALIDATION_SEEDS,
        eval_episodes=EVAL_EPISODES,
        total_steps=steps,
        rungs=rounds,
        part=part,
        **tiny,
    )
    spent = time.perf_counter() - began
    before = read_run_record(where) if (where / RUN_RECORD).exists() else {}
    parts = str(int(before.get("parts", 0)) + 1)
    # Parts may run on different machines: the record keeps every one, not only the last.
    machines = list(dict.fromkeys([*tune_machines(before), machine()]))
    spent += before.get("wall_seconds", 0.0)
    write_run_record(where, spent, parts=parts, machines=machines)


def tune_machines(record: dict[str, Any]) -> list[str]:
    """The machines a tune's parts ran on, as its run record names them (a record written
    before they were listed names its last part's alone)."""
    return record.get("machines") or ([record["machine"]] if "machine" in record else [])


def test_sweeps(
    task: str, tuned: Path, where: Path
) -> list[tuple[Path, list[dict[str, Any]], dict[str, ChoiceValue]]]:
    """The test's sweeps, each (its directory, its grid, its run shape): the chosen setting
    and the default side by side in `where`, or where the race chose another run shape, the
    default's apart in ``test-default`` beside it."""
    recorded = fppo_jax.load_tune(tuned)
    chosen, default = recorded.chosen(task, "ppo"), recorded.results[task]["ppo"]["default"]
    (ours, shape), (theirs, own) = split_setting(chosen), split_setting(default["setting"])
    if shape != own:
        return [
            (where, [{"variant": "ppo", **ours}], shape),
            (where.parent / "test-default", [{"variant": "ppo", **theirs}], own),
        ]
    grid = [{"variant": "ppo", **ours}]
    if chosen != default["setting"]:
        grid.append({"variant": "ppo", **theirs})
    return [(where, grid, shape)]


def test_task(task: str, tuned: Path, where: Path, seeds: int, tiny: dict[str, int]) -> None:
    """The test's sweeps on test seeds 0 … seeds − 1, those not yet recorded: each is written
    as it ends, so a call stopped between them goes on with the next."""
    recorded = fppo_jax.load_tune(tuned)
    for directory, grid, shape in test_sweeps(task, tuned, where):
        if not (directory / "sweep.json").exists():
            test_sweep(task, grid, recorded, directory, seeds, {**tiny, **config_values(shape)})


def test_recorded(task: str, directory: Path) -> bool:
    """Whether the task's tune and every one of its test's sweeps are recorded."""
    tune = directory / "tune"
    return (tune / "results.json").exists() and all(
        (where / "sweep.json").exists()
        for where, _, _ in test_sweeps(task, tune, directory / "test")
    )


def test_sweep(
    task: str,
    grid: list[dict[str, Any]],
    recorded: fppo_jax.TuneResult,
    where: Path,
    seeds: int,
    shape: dict[str, Any],
) -> None:
    """`grid` on test seeds 0 … seeds − 1, evaluated once at the end, in run shape `shape`."""
    budget = recorded.plan["budget"][task]
    began = time.perf_counter()
    result = fppo_jax.sweep(
        task,
        grid,
        seeds=seeds,
        total_steps=budget["env_steps_per_full_run"],
        eval_every=10**9,  # once, after the final update
        eval_episodes=EVAL_EPISODES,
        log_dir=where,
        progress=False,
        **shape,
    )
    write_run_record(where, time.perf_counter() - began, settings=str(len(result.settings)))


def recorded_protocol(results: Path, task: str, seeds: list[int]) -> np.ndarray | None:
    """The recorded protocol's tuned PPO on `seeds` at the eval endpoint, or None where its
    study is not under `results` or did not score every one of them."""
    where = results / RECORDED[task] if task in RECORDED else None
    if where is None or not (where / "plan.json").exists():
        return None
    runs = fppo_jax.load_study(where).results[task]
    arm = [setting["variant"] for setting in runs.settings].index("ppo")
    scored = dict(zip(runs.seeds, runs.scores("eval")[arm], strict=True))
    found = np.array([scored.get(seed, np.nan) for seed in seeds])
    return found if np.isfinite(found).all() else None


def task_lines(task: str, directory: Path) -> tuple[list[str], dict[str, Any]]:
    """The task's row of the write-up and what the goals read of it."""
    tuned = fppo_jax.load_tune(directory / "tune")
    test = fppo_jax.SweepResult.read(directory / "test")
    scores = test.scores("eval")
    ours, theirs = scores[0], scores[-1]  # one setting: the race kept the default
    if (directory / "test-default" / "sweep.json").exists():  # the chosen in a shape of its own
        theirs = fppo_jax.SweepResult.read(directory / "test-default").scores("eval")[0]
    race = tuned.results[task]["ppo"]["race"]
    kept = race["chosen"] == 0
    # Where the race kept the default, both arms are the same runs: P is ½, exactly.
    p = (0.5, 0.5, 0.5) if kept else statistics.compare(ours, theirs)["probability_of_improvement"]
    spent = read_run_record(directory / "tune")["wall_seconds"]
    runs = (
        tuned.results[task]["ppo"]["env_steps"]
        / tuned.plan["budget"][task]["env_steps_per_full_run"]
    )
    iqm = statistics.interval(ours, "iqm")
    zoo = f"{ZOO[task]:,.0f}" if task in ZOO else "—"
    outcome = "default kept" if kept else f"trial {race['chosen']}"
    # The recorded protocol's tuned PPO against this default, on the same seeds and endpoint.
    before = recorded_protocol(directory.parent.parent, task, list(test.seeds))
    then_p = None
    then = "—"
    if before is not None:
        then_p = statistics.compare(before, theirs)["probability_of_improvement"]
        then = f"{statistics.iqm(before):.1f} ({then_p[0]:.2f} [{then_p[1]:.2f}, {then_p[2]:.2f}])"
    # Tunes recorded before the run-shape axes searched the optimisation settings alone.
    shape = "searched" if task in tuned.plan.get("run_shape", {}) else "fixed"
    row = (
        f"| {task} | {shape} | {outcome} | "
        f"{p[0]:.2f} [{p[1]:.2f}, {p[2]:.2f}] | {iqm[0]:.1f} [{iqm[1]:.1f}, {iqm[2]:.1f}] | "
        f"{statistics.iqm(theirs):.1f} | {then} | {zoo} | {runs:.0f} | {spent / 60:.1f} |"
    )
    facts = {
        "task": task,
        "p": p,
        "iqm": iqm[0],
        "seeds": len(test.seeds),
        "kept": kept,
        "machines": tune_machines(read_run_record(directory / "tune")),
        "recorded_p": then_p,
    }
    return [row], facts


def goal_lines(found: list[dict[str, Any]]) -> list[str]:
    """The goals, each met or missed, in words."""
    kept = [f["task"] for f in found if f["kept"]]
    lines = [
        f"- The race kept the default on {len(kept)} of {len(found)} tasks"
        + (f" ({', '.join(kept)}): there tuning changed nothing." if kept else ".")
    ]
    below = [f["task"] for f in found if f["p"][0] < 0.5]
    lines.append(
        "- Tuned PPO never below its default (P ≥ 0.5 on every task): "
        + ("met." if not below else f"**missed** on {', '.join(below)}.")
    )
    mujoco = [f for f in found if f["task"] in MUJOCO]
    unclear = [f["task"] for f in mujoco if f["p"][1] <= 0.5]
    if not mujoco:
        lines.append(
            "- The MuJoCo tasks' parts are not recorded yet: their goals are not measured."
        )
    else:
        lines.append(
            "- On the MuJoCo tasks the interval above 0.5: "
            + ("met." if not unclear else f"**missed** on {', '.join(unclear)}.")
        )
        stood = [t for t in unclear if t in kept]
        if stood:
            lines.append(
                f"- What stands in the way on {', '.join(stood)}: the race kept the default "
                "(no finalist was shown better on the validation seeds), so tuned and default "
                "are the same runs and P is ½ by construction."
            )
        for f in mujoco:
            then = f.get("recorded_p")
            if f["task"] in stood and then and then[1] > 0.5:
                lines.append(
                    f"- On {f['task']} a better setting than the default exists: the recorded "
                    f"protocol's tuned PPO beats it, P = {then[0]:.2f} [{then[1]:.2f}, "
                    f"{then[2]:.2f}]; this tune's search found none."
                )
    weaker = [f["task"] for f in found if f.get("recorded_p") and f["recorded_p"][0] < 0.5]
    if weaker:
        lines.append(
            "- Beside it, the recorded protocol's tuned PPO (9 × 2, η = 3) below the same "
            f"default (P's point below 0.5; its interval in the table): on {', '.join(weaker)}."
        )
    for f in found:
        bar = ZOO.get(f["task"]) if f["task"] not in GOAL else GOAL[f["task"]]
        if bar is not None:
            met = f["iqm"] >= bar
            lines.append(
                f"- {f['task']}: IQM {f['iqm']:.0f} against {bar:,.0f}: "
                + ("met." if met else "**missed**.")
            )
    return lines


def machine_lines(found: list[dict[str, Any]]) -> list[str]:
    """A line per set of machines the recorded tunes ran on, naming its tasks."""
    tasks: dict[tuple[str, ...], list[str]] = {}
    for f in found:
        tasks.setdefault(tuple(f["machines"]), []).append(f["task"])
    return [f"- {', '.join(t)}: {' and '.join(m)}" for m, t in tasks.items()]


def progress_lines(results: Path) -> list[str]:
    """A line per tune still going on: the rounds and full runs its parts have recorded of
    its budget, and their wall time."""
    lines = []
    for tune in sorted((results / "trust").glob("*/tune")):
        if (tune / "results.json").exists():
            task = tune.parent.name
            sweeps = test_sweeps(task, tune, tune.parent / "test")
            left = [where.name for where, _, _ in sweeps if not (where / "sweep.json").exists()]
            if left:
                lines.append(
                    f"- {task}: its tune is recorded, its test goes on: {len(sweeps) - len(left)} "
                    f"of its {len(sweeps)} sweeps recorded ({', '.join(left)}/ to train)."
                )
            continue
        if not (tune / RUN_RECORD).exists():
            continue
        task, record = tune.parent.name, read_run_record(tune)
        rounds = sorted((tune / task).glob("rung-*/scores.json"))
        plan = json.loads((tune / "tune.json").read_text())
        trained = [len(json.loads(s.read_text())["arms"]["ppo"]["trials"]) for s in rounds]
        runs = sum(trained) * plan["search"]["seeds_per_round"]  # each trial's new seeds
        budget = plan["budget"][task]
        parts = int(record["parts"])
        lines.append(
            f"- {task}: its tune goes on: {len(rounds)} round{'s' * (len(rounds) != 1)}, {runs} "
            f"of its {budget['full_runs_per_arm']:.0f} full runs, {parts} "
            f"part{'s' * (parts != 1)} of {record['wall_seconds'] / 60:.0f} minutes in all "
            f"(the last at {record['commit'][:7]}), on {' and '.join(tune_machines(record))}."
        )
    return lines


def report(results: Path, output: Path) -> None:
    """The write-up of every task recorded under `results`/trust."""
    rows: list[str] = []
    found: list[dict[str, Any]] = []
    for directory in sorted((results / "trust").iterdir()):
        if not test_recorded(directory.name, directory):
            continue  # its tune or test goes on (progress_lines)
        lines, facts = task_lines(directory.name, directory)
        rows += lines
        found.append(facts)
    last_seed = max((f["seeds"] for f in found), default=TEST_SEEDS) - 1
    write_result(
        output,
        [
            *header("Tuned PPO against its default, on fresh test seeds"),
            "",
            f"PPO tuned per task by racing ({TRIALS} trials, {SEEDS_PER_ROUND} tuning seeds a "
            f"round), then {FINALISTS} finalists and the default raced on {VALIDATION_SEEDS} "
            "validation seeds (one-sided Wilcoxon signed-rank, paired by seed, Holm, level "
            f"0.05); then the chosen setting and the default trained on test seeds 0 … "
            f"{last_seed}, each scored by its deterministic policy's mean return over "
            f"{EVAL_EPISODES} episodes after the final update. P(tuned > default) with its 95% "
            "percentile bootstrap interval; IQM with its interval. Where the race kept the "
            "default, both arms are the same runs (P = 0.5). Run shape: whether the tune "
            "searched it (fppo_jax.core.shape_space: steps per rollout, minibatches, epochs, "
            "hidden sizes, observation normalisation, initial log-std), or kept the task's, as "
            "tunes recorded before those axes did. Beside them, the recorded protocol's "
            "tuned PPO (experiments/results/tuned.md: 9 trials × 2 tuning seeds, chosen at a "
            "third of the budget, η = 3; the run shape fixed) on the same test seeds and "
            "endpoint, from its study's runs: its IQM and P(it > this default).",
            "",
            "| task | run shape | race | P(tuned > default) | tuned IQM | default IQM | "
            "the recorded protocol's tuned PPO: IQM (P(it > default)) | "
            "RL Zoo's tuned PPO | full runs in the tune | tune minutes |",
            "|---|---|---|---|---|---|---|---|---|---|",
            *rows,
            "",
            "Tune minutes add up the wall time of each tune's parts, on the machines its record "
            "names:",
            "",
            *machine_lines(found),
            "",
            "Goals:",
            "",
            *goal_lines(found),
            *(["", "In progress:", "", *going] if (going := progress_lines(results)) else []),
        ],
    )


def share(text: str) -> tuple[int, int]:
    """``K/N`` as (K, N); the tune checks 1 <= K <= N."""
    k, _, n = text.partition("/")
    try:
        return int(k), int(n)
    except ValueError:
        raise argparse.ArgumentTypeError(f"a part is K/N, such as 1/3, got {text!r}") from None


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--tasks", default="", help="tasks to tune and test, e.g. hopper")
    parser.add_argument("--budget", type=int, default=100, help="full runs per task, the race's in")
    parser.add_argument("--test-seeds", type=int, default=TEST_SEEDS)
    parser.add_argument("--steps", type=int, default=None, help="env steps per run (tiny runs)")
    parser.add_argument("--tiny", action="store_true", help="a tiny run shape (smoke runs)")
    parser.add_argument(
        "--results", type=Path, default=Path(__file__).resolve().parents[1] / "results"
    )
    parser.add_argument("--report", action="store_true", help="the write-up alone")
    parser.add_argument(
        "--rounds", type=int, default=None, help="rounds of each tune this call trains (a part)"
    )
    parser.add_argument(
        "--part",
        type=share,
        default=None,
        metavar="K/N",
        help="train the K-th of N shares of each tune's next round, then stop; a later call "
        "without --part joins them (--rounds 0: the join alone)",
    )
    args = parser.parse_args()
    tiny = (
        {"num_envs": 4, "num_steps": 32, "num_minibatches": 4, "num_epochs": 2} if args.tiny else {}
    )
    for task in [t for t in args.tasks.split(",") if t and not args.report]:
        where = args.results / "trust" / task
        if not (where / "tune" / "results.json").exists():
            tune_task(task, where / "tune", args.budget, tiny, args.steps, args.rounds, args.part)
        if not (where / "tune" / "results.json").exists():
            print(f"{task}: the tune goes on in a later part (--rounds)")
        elif not test_recorded(task, where):
            test_task(task, where / "tune", where / "test", args.test_seeds, tiny)
    report(args.results, args.results / "bench_trust.md")
    print((args.results / "bench_trust.md").read_text())


if __name__ == "__main__":
    main()
