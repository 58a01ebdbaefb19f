"""The tuned verdict's write-up (experiments/plans/tuned.json): each family's tune and study,
read from their records, the plan's families decided as it names them, and what tuning gained
over each arm's default.

    python experiments/studies/tuned_verdict.py              # results/tuned.md
    python experiments/studies/tuned_verdict.py --results /tmp/r --output /tmp/tuned.md

First the plan's families (``_tuned_families.py``): each family the plan names decided as one
by the library's sequential rule replayed on the runs its studies recorded, Holm's procedure
over the whole family, a comparison holding only the seeds its study ran. Where a family's
tasks ran as studies of their own (the MuJoCo tasks, one study each), each comparison's
decision in its study beside the family's, with z against its boundary or P's repeated
interval; a family whose studies are not all recorded is not decided, and says why. Then per
part recorded under <results>/tuned/ (the classic tasks' ``classic/tune/`` by ``fppo-jax
tune`` and ``classic/study/`` by ``fppo-jax study --tuned``; each MuJoCo task's
``mujoco/tune-<task>/`` and ``mujoco/study-<task>/``): the budget every arm had, the family's
decisions (better, worse, equivalent or undecided against tuned PPO) with the seeds each holds
and P(candidate > PPO) on the primary endpoint with a 95% percentile bootstrap interval over
those runs, and on a task with a capped return how many runs reach the cap; then each arm's
tuned setting against its default on the test seeds, on the final training return (the
defaults' runs are the seed study's, recorded from seed 0 under <results>/study/<task>/paper/,
which were not evaluated), where tuning left PPO below its own default each decided arm
against default PPO's runs, and tuned PPO beside the published PPO (RL Zoo's tuned, CleanRL's
at OpenAI baselines' settings). A family whose study is not finished is reported as far as it
went, and says so. Nothing is trained.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

import fppo_jax
from fppo_jax import MissingFile, StudyResult, SweepResult, TuneResult, merge
from fppo_jax.analysis.arms import task_folder
from fppo_jax.analysis.report_kit import interval_cell
from fppo_jax.analysis.study_runs import run_scores
from fppo_jax.stats import statistics

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: shared modules

from _tuned_families import (
    Family,
    FamilyNotAssembled,
    decide_family,
    families_lines,
    listed,
    planned_families,
    recorded_study,
)
from common import RESULTS, argument_parser, header, recorded_parts, write_result

PLAN = RESULTS.parent / "plans" / "tuned.json"

# RL Baselines3 Zoo's tuned PPO (benchmark.md: one run, deterministic evaluation), with the
# budget it trained; CartPole-v1 there ends episodes at 500 steps, this project's at 200. It
# reports no PPO on MuJoCo's Reacher (only on PyBullet's, another task).
ZOO = {
    "cartpole": "500.0 (CartPole-v1, capped at 500, 100k steps)",
    "acrobot": "−73.5 (1M steps)",
    "mountaincar": "−110.4 (1M steps)",
    "hopper": "2410 (Hopper-v3, 1M steps)",
    "walker2d": "3479 (Walker2d-v3, 1M steps)",
    "halfcheetah": "5819 (HalfCheetah-v3, 1M steps)",
    "ant": "1327 (Ant-v3, 1M steps)",
    "swimmer": "282 (Swimmer-v3, 1M steps, γ = 0.9999)",
}
# CleanRL's PPO at OpenAI baselines' settings, not tuned per task (docs/rl-algorithms/ppo.md
# and docs/benchmark/ppo_continuous_action.md: the mean ± std of 3 seeds' episodic returns as
# reported), with its budget; it reports no Ant, Reacher or Swimmer.
CLEANRL = {
    "cartpole": "490.04 ± 6.12 (CartPole-v1, capped at 500; 4 × 128, 500k steps)",
    "acrobot": "−86.36 ± 1.32 (4 × 128, 500k steps)",
    "mountaincar": "−200.00 ± 0.00 (4 × 128, 500k steps)",
    "hopper": "2382.86 ± 271.74 (Hopper-v4, 1 × 2,048, 1M steps)",
    "walker2d": "2287.95 ± 571.78 (Walker2d-v4, 1 × 2,048, 1M steps)",
    "halfcheetah": "1442.64 ± 46.03 (HalfCheetah-v4, 1 × 2,048, 1M steps)",
}
# The most a run can return: this project's CartPole ends an episode at 200 steps, each worth
# 1. Where most runs end there, a decision says little of how well an arm learns.
CAPS = {"cartpole": 200.0}


def interval(point: tuple[float, float, float], digits: int = 2) -> str:
    return interval_cell(point, f".{digits}f")


def recorded_defaults(results: Path, task: str) -> SweepResult | None:
    """Each arm's default runs on `task`: the seed study's parts, merged."""
    parts = list(recorded_parts(results / "study" / task / "paper").values())
    return merge(parts) if parts else None


def finished_tune(directory: Path) -> TuneResult | None:
    """The tune recorded in `directory` (:func:`fppo_jax.load_tune`) once it has finished;
    None before."""
    try:
        tune = fppo_jax.load_tune(directory)
    except MissingFile:
        return None
    return tune if tune.finished else None


def decided_study(directory: Path) -> StudyResult | None:
    """The study recorded in `directory` once it has decided a look; None before."""
    try:
        study = recorded_study(directory)
    except MissingFile:
        return None
    return study if study.decisions else None


def finite_final(runs: SweepResult, arm: str) -> np.ndarray:
    """An arm's final training returns, the runs that ended with a finite one."""
    final = run_scores(runs, arm, "final")
    return final[np.isfinite(final)]


def part_lines(results: Path, tune: TuneResult, where: Path, family: Family | None) -> list[str]:
    """One part of the plan: the finished `tune` and its study in `where`, whose comparisons
    are decided in the plan's `family` (None where it could not be assembled: then the
    study's own decisions, and the lines say so)."""
    lines = tune_lines(results, tune)
    study = decided_study(where)
    if study is None:
        return [*lines, not_started(results, where), ""]
    plan, runs = study.plan, study.results
    rows = planned_rows(study.decisions, family)
    lines += study_lines(results, where, study, family)
    lines += decisions_table(plan, rows, runs)
    lines += capped_lines(plan, runs)
    lines += gains_lines(results, plan, tune.results, runs, rows)
    lines += published_lines(plan, runs)
    return [*lines, ""]


def tune_lines(results: Path, tune: TuneResult) -> list[str]:
    """The finished `tune`: its budget, its curves and each arm's chosen trial."""
    tune_plan, tuned, folder = tune.plan, tune.results, tune.directory.relative_to(results)
    budget = ", ".join(
        f"{task} {b['env_steps_per_arm']:,}" for task, b in tune_plan["budget"].items()
    )
    lines = [
        f"Tune ([report]({folder}/report.md), at {tune_plan['commit'][:7]}): "
        f"{tune_plan['trials']} trials per arm and task, {len(tune_plan['seeds'])} tuning seeds "
        f"per trial, η = {tune_plan['eta']}; every arm trained the same env steps per task "
        f"({budget}).",
        "",
        f"![Best score against env steps per arm, {', '.join(tuned)}]({folder}/tuning_curves.png)",
        "",
    ]
    for task, arms in tuned.items():
        best = ", ".join(
            f"{arm} {found['chosen']['score']:.1f} (trial {found['chosen']['trial']}; its default "
            f"{found['default']['first_rung_score']:.1f} at the first rung)"
            for arm, found in arms.items()
            if found["chosen"] and found["chosen"]["score"] is not None
        )
        lines += [f"Best trial per arm on {task}'s tuning seeds at the full budget: {best}.", ""]
        tied = [arm for arm, found in arms.items() if found.get("tied_rungs")]
        if tied:
            lines += [
                f"On {task} the first rung scored every trial of {listed(tied)} alike, so the "
                "trials that went on were the first by number, not the best: there the tune "
                "chose among those alone.",
                "",
            ]
    return lines


def not_started(results: Path, study: Path) -> str:
    """A study that has decided no look yet: how far it went."""
    shares = len(list(study.glob("*/group-*/part-*/sweep.json")))
    started = (
        f"has not decided a look yet ({shares} share{'s' * (shares != 1)} of a look recorded "
        f"under {study.relative_to(results)}/)"
        if study.exists()
        else "has not run yet"
    )
    return f"The study on fresh seeds {started}."


def planned_rows(decided: list, family: Family | None) -> list[dict]:
    """The study's comparisons (`decided`, as recorded) with the plan's family's decision and
    the seeds it holds, and (`own`) the study's own decision where the family's differs; the
    study's as recorded where the family could not be assembled."""
    if family is None:
        return [{**row, "own": None} for row in decided]
    by_key = {(one.task, one.candidate): one for one in family.replayed}
    rows = []
    for row in decided:
        planned = by_key[row["task"], row["candidate"]].planned
        decision = planned.decision or "undecided"
        own = row["decision"] if row["decision"] != decision else None
        rows.append({**row, "decision": decision, "seeds": planned.seeds, "own": own})
    return rows


def study_lines(results: Path, where: Path, study: StudyResult, family: Family | None) -> list[str]:
    """The study recorded in `where`: its design and levels, and which family its table's
    decisions are."""
    plan = study.plan
    state = "finished" if study.finished else "**not finished** (some comparisons await seeds)"
    count, level = len(plan["comparisons"]), plan["level"]
    said = (
        f"Study on test seeds ([report]({where.relative_to(results)}/report.md), at "
        f"{plan['commit'][:7]}): {state}; primary endpoint {plan['primary_endpoint']}, margin "
        f"{plan.get('margin')}, level {level} for each of two kinds of error over its {count} "
        f"comparisons (a wrong better or worse, a wrong equivalent), so a chance up to "
        f"{2 * level:.2f} of one or the other"
    )
    if family is None:
        said += ". Its decisions are its own: the plan's family is not decided here (above)."
    elif family.split:
        said += (
            f". It decided {plan['tasks'][0]} alone, where the plan's family is the "
            f"{len(family.replayed)} comparisons of {listed(family.tasks)}: the table gives "
            "that family's decision (above), and this study's own where it differs."
        )
    else:
        said += ": the plan's family, whole."
    return [said, ""]


def decisions_table(plan: dict, rows: list[dict], runs: dict[str, SweepResult]) -> list[str]:
    """Each comparison's decision against tuned PPO with the seeds it holds, and P(candidate >
    PPO) on the primary endpoint over those seeds."""
    endpoint = plan["primary_endpoint"]
    lines = [
        "| task | candidate | decision against tuned PPO | seeds | "
        f"P(candidate > PPO), {endpoint} |",
        "|---|---|---|---|---|",
    ]
    for row in rows:
        task, seeds = row["task"], row["seeds"]
        candidate = run_scores(runs[task], row["candidate"], endpoint)[:seeds]
        baseline = run_scores(runs[task], row["baseline"], endpoint)[:seeds]
        p = statistics.compare(candidate, baseline)["probability_of_improvement"]
        decision = row["decision"] + (f" (its study alone: {row['own']})" if row["own"] else "")
        lines.append(f"| {task} | {row['candidate']} | {decision} | {seeds} | {interval(p)} |")
    return lines


def capped_lines(plan: dict, runs: dict[str, SweepResult]) -> list[str]:
    """On a task whose return has a cap, how many of each arm's runs reach it on the primary
    endpoint: where most do, the decisions there say little of how well an arm learns."""
    endpoint, lines = plan["primary_endpoint"], []
    for task in [task for task in plan["tasks"] if task in CAPS]:
        counts = []
        for arm in [plan["baseline"], *plan["candidates"]]:
            scores = run_scores(runs[task], arm, endpoint)
            counts.append(f"{arm} {int(np.sum(scores >= CAPS[task]))} of {len(scores)}")
        lines += [
            "",
            f"On {task} the return cannot exceed {CAPS[task]:g}; the runs at that cap on the "
            f"primary endpoint ({endpoint}): {', '.join(counts)}.",
        ]
    return lines


def gains_lines(
    results: Path,
    plan: dict,
    tuned: dict,
    runs: dict[str, SweepResult],
    rows: list[dict],
) -> list[str]:
    """What tuning gained: each arm's tuned runs against its default's on the final return,
    and where tuning left PPO below its default, each decided arm against default PPO."""
    lines = [
        "",
        "What tuning gained, on the final training return at the test seeds (IQM with its 95% "
        "interval; the default's runs are the seed study's, at its seeds from 0, as many as it "
        "recorded; the runs of each, those with a finite final return):",
        "",
        "| task | arm | tuned trial | tuned runs | tuned IQM | default runs | default IQM | "
        "P(tuned > default) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    weakened = []
    for task in plan["tasks"]:
        defaults = recorded_defaults(results, task)
        for arm in [plan["baseline"], *plan["candidates"]]:
            cells, gain = gain_cells(runs[task], defaults, arm)
            if arm == plan["baseline"] and gain is not None and gain[0][2] < 0.5:
                weakened.append((task, *gain))
            tuned_final = finite_final(runs[task], arm)
            lines.append(
                f"| {task} | {arm} | {tuned[task][arm]['chosen']['trial']} | {len(tuned_final)} | "
                f"{interval(statistics.interval(tuned_final, 'iqm'), 1)} | {' | '.join(cells)} |"
            )
    for task, gain, default_final in weakened:
        lines += [
            "",
            *weakened_baseline(task, plan["baseline"], gain, default_final, runs[task], rows),
        ]
    return lines


def gain_cells(
    runs: SweepResult, defaults: SweepResult | None, arm: str
) -> tuple[list[str], tuple[tuple[float, float, float], np.ndarray] | None]:
    """An arm's default runs, their IQM and P(tuned > default) as table cells, and that P with
    the default's final returns (None where its default is not recorded)."""
    names = [] if defaults is None else [s["variant"] for s in defaults.settings]
    if defaults is None or arm not in names:
        return ["—", "not recorded", "—"], None
    default_final = finite_final(defaults, arm)
    gain = statistics.compare(finite_final(runs, arm), default_final)["probability_of_improvement"]
    cells = [
        str(len(default_final)),
        interval(statistics.interval(default_final, "iqm"), 1),
        interval(gain),
    ]
    return cells, (gain, default_final)


def published_lines(plan: dict, runs: dict[str, SweepResult], endpoint: str = "final") -> list[str]:
    """Tuned PPO's IQM on `endpoint` (its runs with a finite score) beside RL Zoo's tuned PPO
    and CleanRL's."""
    lines = [
        "",
        "Tuned PPO beside the published PPO: RL Baselines3 Zoo's tuned PPO (`benchmark.md`, one "
        "run each) and CleanRL's PPO at OpenAI baselines' settings, not tuned per task (3 seeds, "
        "mean ± std as CleanRL reports it); each at its own budgets and task versions, so not "
        "a comparison at equal budget:",
        "",
        f"| task | tuned PPO here, IQM of the {endpoint} return | RL Zoo's tuned PPO | "
        "CleanRL's PPO |",
        "|---|---|---|---|",
    ]
    for task in plan["tasks"]:
        scores = run_scores(runs[task], plan["baseline"], endpoint)
        iqm = interval(statistics.interval(scores[np.isfinite(scores)], "iqm"), 1)
        lines.append(f"| {task} | {iqm} | {ZOO.get(task, '—')} | {CLEANRL.get(task, '—')} |")
    return lines


def weakened_baseline(
    task: str,
    baseline: str,
    gain: tuple[float, float, float],
    default_final: np.ndarray,
    runs: SweepResult,
    rows: list[dict],
) -> list[str]:
    """Where tuning left the baseline below its own default on the test seeds, what the task's
    decisions (the plan's family's, `rows`) are not: decisions against the baseline at its
    default. Beside each decided candidate, its tuned runs against the baseline's default ones
    on the final return (descriptive: outside the planned family, not adjusted for the looks)."""
    said = (
        f"On {task} tuning left {baseline} below its own default on the test seeds "
        f"(P(tuned > default) = {interval(gain)} on the final return, an interval outside the "
        "planned family and not adjusted for the looks)"
    )
    rows = [r for r in rows if r["task"] == task and r["decision"] != "undecided"]
    if not rows:
        return [f"{said}."]
    against = []
    for row in rows:
        final = finite_final(runs, row["candidate"])
        p = statistics.compare(final, default_final)["probability_of_improvement"]
        against.append(f"{row['candidate']} {interval(p)}")
    decisions = ", ".join(f"{r['candidate']} {r['decision']}" for r in rows)
    return [
        f"{said}: its decisions ({decisions}) are against a tuned {baseline} that tuning made "
        f"weaker, not against {baseline} at its default. Against {baseline}'s default runs, on "
        f"the final return and with the same caveats: P(tuned candidate > default {baseline}) = "
        f"{', '.join(against)}."
    ]


def mujoco_lines(results: Path, tasks: list[str], family: Family | None) -> list[str]:
    """The MuJoCo family, a part per task (its tune, then its study), and what is left."""
    where = results / "tuned" / "mujoco"
    lines = ["## MuJoCo tasks", ""]
    tunes = {task: finished_tune(where / f"tune-{task_folder(task)}") for task in tasks}
    for task, tune in tunes.items():
        if tune is not None:
            lines += [f"### {task}", ""]
            lines += part_lines(results, tune, where / f"study-{task_folder(task)}", family)
    left = [f"the tune of {task}" for task, tune in tunes.items() if tune is None]
    for task in tasks:
        study = decided_study(where / f"study-{task_folder(task)}")
        if study is None:
            left.append(f"the study of {task}")
        elif not study.finished:
            left.append(f"the rest of {task}'s study")
    return [*lines, *left_lines(left)]


def left_lines(left: list[str]) -> list[str]:
    """What of the MuJoCo family is not run yet, with what it would take, and what the plan
    leaves out."""
    return [
        f"Not run yet: {', '.join(left)}. Each task's tune trains 6 arms × 4.65M env steps "
        "(33 to 57 minutes each here, on a shared 2-core machine), its study up to 5 looks of "
        "60 runs × 1M env steps; a share of 15 runs took 10 to 21 minutes here (about 16 on "
        "Hopper, 10.5 on HalfCheetah with the machine to itself), so a look of 60 runs takes "
        "45 to 85 minutes and a task's study up to 4 to 7 hours (Hopper's, which stopped arms "
        "at its second look, took under 4)."
        if left
        else "Every MuJoCo task the plan names is recorded.",
        "",
        "Not planned, not run: walker2d, ant and reacher (the plan adds each only by an "
        "amendment committed before its runs). Estimated from native MuJoCo's speeds on this "
        "machine against Hopper's (envpool, 2 threads: Hopper ~17k env steps/s, Walker2d ~13k, "
        "Ant ~6k, Reacher ~67k, the environments alone): Walker2d about 1.3 times Hopper's time "
        "(a tune of about an hour, a study up to about 9 hours), Ant about 3 times (up to about "
        "a day in all), Reacher at most Hopper's (its physics is fast; the update bounds it).",
        "",
    ]


def decided_families(results: Path, plan: dict) -> dict[str, Family | str]:
    """Each family the plan names decided as one, or why it cannot be (in words)."""
    families: dict[str, Family | str] = {}
    for name, tasks in planned_families(plan).items():
        try:
            families[name] = decide_family(results, name, tasks)
        except FamilyNotAssembled as refused:
            families[name] = str(refused)
    return families


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--results", type=Path, default=RESULTS, help="where the records are")
    parser.add_argument("--plan", type=Path, default=PLAN, help="the plan (its families)")
    parser.add_argument("--output", type=Path, help="the write-up (default: <results>/tuned.md)")
    args = parser.parse_args()
    plan = json.loads(args.plan.read_text())
    families = decided_families(args.results, plan)
    lines = [
        *header("Tuned against tuned: does a variant beat PPO when every arm is tuned?"),
        "",
        "The plan: [experiments/plans/tuned.json](../plans/tuned.json), committed before any of "
        "its runs. Every arm, PPO included, tuned with the same budget by `fppo-jax tune`, then "
        "each arm's chosen setting tested on seeds the tune never used by `fppo-jax study "
        "--tuned`. Intervals here are 95% percentile bootstrap intervals over the runs; they "
        "describe those runs and are not adjusted for stopping early or for the comparisons "
        "(the decisions are, and so are the repeated intervals in the MuJoCo family's table "
        "below and in the studies' reports).",
        "",
        *families_lines(args.results, plan, families),
    ]
    classic = args.results / "tuned" / "classic"
    tune = finished_tune(classic / "tune")
    if tune is not None:
        lines += ["## Classic tasks", ""]
        lines += part_lines(args.results, tune, classic / "study", _of(families, "classic"))
    mujoco = planned_families(plan)["mujoco"]
    lines += mujoco_lines(args.results, mujoco, _of(families, "mujoco"))
    output = args.output or args.results / "tuned.md"
    write_result(output, lines)
    print("\n".join(lines))


def _of(families: dict[str, Family | str], name: str) -> Family | None:
    family = families.get(name)
    return family if isinstance(family, Family) else None


if __name__ == "__main__":
    main()
