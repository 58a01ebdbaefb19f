"""The second tuned verdict (experiments/plans/tuned-v2.json) as far as its parts have run:
per family, each task's tune, rung by rung (a racing round or the validation race), with the
runs it trained, the seconds it trained and compiled and the commit that recorded it; each
arm's race where it is decided; the time spent against the plan's estimate; and what remains.

    python experiments/studies/tuned_v2.py              # results/tuned-v2.md
    python experiments/studies/tuned_v2.py --results /tmp/r --output /tmp/tuned-v2.md

Once a family's study has decided a look: its decisions as recorded (the family is the study,
Holm over all of its comparisons), each with P(candidate > PPO) on the primary endpoint and a
95% percentile bootstrap interval over the seeds the decision holds, and the rule's repeated
interval; tuned PPO against PPO's default trained beside it on the same test seeds (the plan's
``ppo_default_beside``: sweeps under <study>/ppo-default/<task>/group-<k>/); and tuned PPO
beside the published PPO. Nothing is trained.
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path
from typing import Any

import numpy as np

from fppo_jax import StudyResult, SweepResult, merge
from fppo_jax.analysis.study_runs import run_scores, runs_of
from fppo_jax.analysis.study_shapes import TaskRuns, holding
from fppo_jax.stats import statistics
from fppo_jax.store.machine import NOT_RECORDED

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: shared modules

from common import RESULTS, argument_parser, header, write_result
from tuned_verdict import capped_lines, decided_study, interval, published_lines

PLAN = RESULTS.parent / "plans" / "tuned-v2.json"
PART = re.compile(r"(group|part)-\d+")


def rung_runs(rung: dict[str, Any], seeds_per_round: int) -> int:
    """The runs a rung trained: each live trial's new seeds in a round, each entrant's
    validation seeds in the race."""
    return sum(
        sum(len(row["seed_scores"]) for row in arm["trials"])
        if "race" in arm
        else len(arm["trials"]) * seeds_per_round
        for arm in rung["arms"].values()
    )


def race_outcome(arm: dict[str, Any]) -> str:
    """An arm's validation race in words: the default kept, or the trial that replaced it."""
    race = arm["race"]
    if race["chosen"] == 0:
        return "default kept"
    return f"trial {race['chosen']}"


class Machines:
    """The machines recorded times were measured on, each named once by a short label (m1,
    m2, …, in the order first met) that a table's cell gives."""

    def __init__(self) -> None:
        self.labels: dict[str, str] = {}

    def cell(self, names: list[str]) -> str:
        """The labels of `names`, — for a record (or a joined share's) that predates them."""
        for name in names:
            if name != NOT_RECORDED:
                self.labels.setdefault(name, f"m{len(self.labels) + 1}")
        return ", ".join(self.labels.get(name, "—") for name in names) or "—"

    def lines(self) -> list[str]:
        return [f"- {label}: {name}" for name, label in self.labels.items()]


def task_rows(
    family: str, task: str, tune: Path, plan: dict[str, Any], machines: Machines
) -> tuple[list[str], float]:
    """A table row per rung of `task` recorded in `tune`, and the seconds they took."""
    rows, seconds = [], 0.0
    for path in sorted((tune / task).glob("rung-*/scores.json"), key=_rung_number):
        rung = json.loads(path.read_text())
        racing = not any("race" in arm for arm in rung["arms"].values())
        what = f"round {_rung_number(path) + 1}" if racing else "validation race"
        outcome = (
            "—"
            if racing
            else ", ".join(f"{name}: {race_outcome(arm)}" for name, arm in rung["arms"].items())
        )
        runs = rung_runs(rung, plan["search"]["seeds_per_round"])
        took = rung["seconds"] + rung["compile_seconds"]
        seconds += took
        # Rungs recorded before scores.json named its commit ran at the tune's first.
        commit = rung.get("commit", plan["commit"])
        rows.append(
            f"| {family} | {task} | {what} | {runs} | {took / 60:.1f} | "
            f"{rung['compile_seconds'] / 60:.1f} | {outcome} | {commit[:7]} | "
            f"{machines.cell(rung.get('machines', []))} |"
        )
    return rows, seconds


def study_lines(
    results: Path, name: str, where: Path, study: StudyResult, tuned: dict[str, Any]
) -> list[str]:
    """The family `name`'s `study`, recorded in `where`: its decisions, tuned PPO against its
    concurrent default, and against the published PPO. `tuned` is the family's tune's results
    (each arm's chosen trial)."""
    plan, runs = study.plan, study.results
    state = "finished" if study.finished else "**not finished** (some comparisons await seeds)"
    level, endpoint = plan["level"], plan["primary_endpoint"]
    lines = [
        f"### The {name} family's study",
        "",
        f"[Its report]({where.relative_to(results)}/report.md), at {plan['commit'][:7]}: "
        f"{state}. Its {len(plan['comparisons'])} comparisons are the plan's family, whole "
        f"(Holm over all of them), on the {endpoint} endpoint with margin {plan['margin']}, "
        f"at level {level} for each of two kinds of error (a wrong better or worse, a wrong "
        f"equivalent), so a chance up to {2 * level:.2f} of one or the other. P(candidate > "
        "PPO) is over the seeds the decision holds, with a 95% percentile bootstrap interval "
        "(descriptive: not adjusted for the looks or the comparisons); the repeated interval is "
        "the rule's, adjusted for both.",
        "",
        "| task | candidate | decision against tuned PPO | seeds | P(candidate > PPO) | "
        "repeated interval |",
        "|---|---|---|---|---|---|",
    ]
    for row in study.decisions:
        task, seeds = row["task"], row["seeds"]
        candidate = run_scores(runs[task], row["candidate"], endpoint)[:seeds]
        baseline = run_scores(runs[task], row["baseline"], endpoint)[:seeds]
        p = statistics.compare(candidate, baseline)["probability_of_improvement"]
        repeated = row.get("interval")
        bounds = f"[{repeated[0]:.2f}, {repeated[1]:.2f}]" if repeated else "—"
        lines.append(
            f"| {task} | {row['candidate']} | {row['decision'] or 'undecided'} | {seeds} | "
            f"{interval(p)} | {bounds} |"
        )
    lines += capped_lines(plan, runs)
    lines += default_lines(where, study, tuned)
    lines += published_lines(plan, runs, endpoint)
    return [*lines, ""]


def default_lines(where: Path, study: StudyResult, tuned: dict[str, Any]) -> list[str]:
    """Tuned PPO against PPO's default trained beside it on the same test seeds: P(tuned >
    default) on the study's endpoint with its 95% bootstrap interval, untested and outside
    the family, as the plan reports it. Where PPO's race kept its default, the study's PPO runs
    are the default's (the plan's amendment): no P there."""
    plan, runs = study.plan, study.results
    baseline, endpoint = plan["baseline"], plan["primary_endpoint"]
    lines = [
        "",
        f"What tuning gained: tuned {baseline} against {baseline}'s default trained beside it "
        f"on the same test seeds (the plan's `ppo_default_beside`), on the {endpoint} endpoint; "
        "IQMs and P with 95% bootstrap intervals, untested and outside the family. Where the "
        f"race kept {baseline}'s default, the study's {baseline} runs are the default's (the "
        "plan's amendment), and there is nothing to compare:",
        "",
        "| task | tuned trial | seeds | tuned IQM | default IQM | P(tuned > default) |",
        "|---|---|---|---|---|---|",
    ]
    for task in plan["tasks"]:
        trial = tuned[task][baseline]["chosen"]["trial"]
        tuned_scores = seed_scores(runs[task], baseline, endpoint)
        if trial == 0:
            mine = run_scores(runs[task], baseline, endpoint)
            lines.append(
                f"| {task} | 0, the default | {len(mine)} | "
                f"{interval(statistics.interval(mine, 'iqm'), 1)} | the same runs | — |"
            )
            continue
        default = concurrent_default(where / "ppo-default" / task)
        if default is None:
            lines.append(f"| {task} | {trial} | — | — | not trained yet | — |")
            continue
        seeds = [seed for seed in default.seeds if seed in tuned_scores]
        default_scores = seed_scores(default, baseline, endpoint)
        mine = np.array([tuned_scores[seed] for seed in seeds])
        theirs = np.array([default_scores[seed] for seed in seeds])
        p = statistics.compare(mine, theirs)["probability_of_improvement"]
        lines.append(
            f"| {task} | {trial} | {len(seeds)} | "
            f"{interval(statistics.interval(mine, 'iqm'), 1)} | "
            f"{interval(statistics.interval(theirs, 'iqm'), 1)} | {interval(p)} |"
        )
    return lines


def defaults_missing(where: Path, study: StudyResult, tuned: dict[str, Any]) -> bool:
    """Whether a task of `study` whose race chose another trial than PPO's default has no
    default runs beside it yet."""
    baseline = study.plan["baseline"]
    return any(
        tuned[task][baseline]["chosen"]["trial"] != 0
        and concurrent_default(where / "ppo-default" / task) is None
        for task in study.plan["tasks"]
    )


def concurrent_default(folder: Path) -> SweepResult | None:
    """PPO's default runs recorded in `folder` (one sweep per group of the study's seeds),
    merged; None where none is recorded."""
    groups = sorted(folder.glob("group-*/sweep.json"), key=lambda p: _number(p.parent, "group-"))
    return merge([SweepResult.read(path.parent) for path in groups]) if groups else None


def seed_scores(runs: TaskRuns, variant: str, endpoint: str) -> dict[int, float]:
    """`variant`'s score per seed in `runs` (a failed run's is −inf)."""
    held = holding(runs, variant)
    seeds = [held.runs[i]["seed"] for i in runs_of(held, variant)]
    return dict(zip(seeds, run_scores(held, variant, endpoint), strict=True))


def _number(path: Path, prefix: str) -> int:
    return int(path.name.removeprefix(prefix))


def _rung_number(path: Path) -> int:
    return int(path.parent.name.removeprefix("rung-"))


def _recorded(results: Path, output: str) -> Path:
    """Where the plan's `output` (a path from the repository's root) is under `results`."""
    return results / Path(output).relative_to("experiments/results")


def study_part_rows(family: str, where: Path, machines: Machines) -> tuple[list[str], float]:
    """A table row per sweep recorded under the study `where` (a group of test seeds of one
    task, a share of one, or PPO's default beside it), and the seconds they took. The commit
    each ran at is in the study's decisions.json (groups), its shares' share.json and the
    commit that recorded it."""
    rows, seconds = [], 0.0
    # A group's own sweep or its shares'; not the task's runs merged beside the groups.
    records = [r for r in where.rglob("sweep.json") if PART.fullmatch(r.parent.name)]
    for record in sorted(records):
        sweep = SweepResult.read(record.parent)
        took = sweep.train_seconds + sweep.compile_seconds
        seconds += took
        part = record.parent.relative_to(where)
        rows.append(
            f"| {family} | {part} | {len(sweep.runs)} | {took / 60:.1f} | "
            f"{sweep.compile_seconds / 60:.1f} | {machines.cell(sweep.machines)} |"
        )
    return rows, seconds


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--results", type=Path, default=RESULTS, help="where the records are")
    parser.add_argument("--plan", type=Path, default=PLAN, help="the plan")
    parser.add_argument("--output", type=Path, help="the write-up (default: <results>/tuned-v2.md)")
    args = parser.parse_args()
    plan = json.loads(args.plan.read_text())
    rows: list[str] = []
    parts: list[str] = []
    studies: list[str] = []
    remaining: list[str] = []
    against: list[str] = []
    spent = 0.0
    machines = Machines()
    for name, family in plan["families"].items():
        tuning = spent
        tune = _recorded(args.results, family["tune_output"])
        tuned = json.loads((tune / "tune.json").read_text()) if tune.exists() else None
        started = []
        for task in family["tasks"]:
            found, seconds = task_rows(name, task, tune, tuned, machines) if tuned else ([], 0.0)
            rows += found
            spent += seconds
            started += [task] if found else []
        untouched = [task for task in family["tasks"] if task not in started]
        if tuned is None:
            remaining.append(f"- {name}: the tune not started.")
        elif not (tune / "results.json").exists():
            waiting = f"; no rung of {', '.join(untouched)} recorded yet" if untouched else ""
            remaining.append(f"- {name}: the tune goes on (the same command, --rungs N){waiting}.")
        where = _recorded(args.results, family["study_output"])
        found, seconds = study_part_rows(name, where, machines)
        parts += found
        tuning, spent = spent - tuning, spent + seconds
        estimates = [v for k, v in plan["compute_estimate"].items() if k.startswith(name)]
        against.append(
            f"- {name}: the tune {tuning / 3600:.1f} hours, the study {seconds / 3600:.1f} hours "
            f"recorded; the plan's estimate: {'; '.join(estimates)}."
        )
        study = decided_study(where)
        chosen = json.loads((tune / "results.json").read_text()) if study is not None else {}
        if study is not None:
            studies += study_lines(args.results, name, where, study, chosen)
        if study is None or not study.finished:
            state = "going on" if where.exists() else "not started"
            remaining.append(f"- {name}: the study {state}.")
        elif defaults_missing(where, study, chosen):
            remaining.append(f"- {name}: PPO's default beside the study goes on.")
    lines = [
        *header("The tuned verdict again: parts run so far"),
        "",
        "The plan: [experiments/plans/tuned-v2.json](../plans/tuned-v2.json), committed before "
        "any of its runs. Every arm (PPO, FPPO-LP, FPPO-QP, SPO) tuned by racing with a "
        "validation race against its default, over a space that holds the run's shape; then "
        "each family decided as one study on test seeds.",
        "",
        "## The tunes",
        "",
        *(
            [
                "| family | task | rung | runs | minutes | of them compiling | race | commit | "
                "machine |",
                "|---|---|---|---|---|---|---|---|---|",
                *rows,
            ]
            if rows
            else ["No rung is recorded yet."]
        ),
        "",
        "## The studies",
        "",
        *(studies or ["No study has decided a look yet.", ""]),
        *(
            [
                "Each sweep the studies recorded (a group of test seeds, or PPO's default beside "
                "it):",
                "",
                "| family | sweep | runs | minutes | of them compiling | machine |",
                "|---|---|---|---|---|---|",
                *parts,
                "",
            ]
            if parts
            else []
        ),
        "## Time and what remains",
        "",
        f"Recorded so far: {spent / 3600:.1f} hours of training and compiling. The plan's "
        f"estimate (for {plan['compute_estimate']['machine']}): "
        f"{plan['compute_estimate']['in_all']}.",
        "",
        *against,
        "",
        "The machines the times were measured on (— in a table: a record from before they were "
        "kept):",
        "",
        *(machines.lines() or ["- none recorded yet"]),
        "",
        "Remaining:",
        "",
        *remaining,
    ]
    write_result(args.output or args.results / "tuned-v2.md", lines)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
