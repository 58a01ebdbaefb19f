"""The second tuned verdict (experiments/plans/tuned-v2.json) as far as its parts have run:
per family, each task's tune, rung by rung (a racing round or the validation race), with the
runs it trained, the seconds it trained and compiled and the commit that recorded it; each
arm's race where it is decided; the time spent against the plan's estimate; and what remains.

    python experiments/studies/tuned_v2.py              # results/tuned-v2.md
    python experiments/studies/tuned_v2.py --results /tmp/r --output /tmp/tuned-v2.md

Nothing is trained. A family's study is named as going on or not started: no decision is
written here until the studies' records hold one.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: shared modules

from common import RESULTS, argument_parser, header, write_result

PLAN = RESULTS.parent / "plans" / "tuned-v2.json"


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


def task_rows(family: str, task: str, tune: Path, plan: dict[str, Any]) -> tuple[list[str], float]:
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
            f"{rung['compile_seconds'] / 60:.1f} | {outcome} | {commit[:7]} |"
        )
    return rows, seconds


def _rung_number(path: Path) -> int:
    return int(path.parent.name.removeprefix("rung-"))


def _recorded(results: Path, output: str) -> Path:
    """Where the plan's `output` (a path from the repository's root) is under `results`."""
    return results / Path(output).relative_to("experiments/results")


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--results", type=Path, default=RESULTS, help="where the records are")
    parser.add_argument("--plan", type=Path, default=PLAN, help="the plan")
    parser.add_argument("--output", type=Path, help="the write-up (default: <results>/tuned-v2.md)")
    args = parser.parse_args()
    plan = json.loads(args.plan.read_text())
    rows: list[str] = []
    remaining: list[str] = []
    spent = 0.0
    for name, family in plan["families"].items():
        tune = _recorded(args.results, family["tune_output"])
        tuned = json.loads((tune / "tune.json").read_text()) if tune.exists() else None
        started = []
        for task in family["tasks"]:
            found, seconds = task_rows(name, task, tune, tuned) if tuned else ([], 0.0)
            rows += found
            spent += seconds
            started += [task] if found else []
        untouched = [task for task in family["tasks"] if task not in started]
        if tuned is None:
            remaining.append(f"- {name}: the tune not started.")
        elif not (tune / "results.json").exists():
            waiting = f"; no rung of {', '.join(untouched)} recorded yet" if untouched else ""
            remaining.append(f"- {name}: the tune goes on (the same command, --rungs N){waiting}.")
        study = _recorded(args.results, family["study_output"])
        remaining.append(f"- {name}: the study {'going on' if study.exists() else 'not started'}.")
    lines = [
        *header("The tuned verdict again: parts run so far"),
        "",
        "The plan: [experiments/plans/tuned-v2.json](../plans/tuned-v2.json), committed before "
        "any of its runs. Every arm (PPO, FPPO-LP, FPPO-QP, SPO) tuned by racing with a "
        "validation race against its default, over a space that holds the run's shape; then "
        "each family decided as one study on test seeds. No decision is recorded yet.",
        "",
        *(
            [
                "| family | task | rung | runs | minutes | of them compiling | race | commit |",
                "|---|---|---|---|---|---|---|---|",
                *rows,
            ]
            if rows
            else ["No rung is recorded yet."]
        ),
        "",
        f"Recorded so far: {spent / 3600:.1f} hours of training and compiling. The plan's "
        f"estimate: {plan['compute_estimate']['in_all']}.",
        "",
        "Remaining:",
        "",
        *remaining,
    ]
    write_result(args.output or args.results / "tuned-v2.md", lines)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
