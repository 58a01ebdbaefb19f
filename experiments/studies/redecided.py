"""The recorded FPPO, SPO and DPO verdicts re-decided with an equivalence margin: which
comparisons with PPO are equivalent within ±0.2 on P(candidate > PPO), as plans/redecided.json
planned before this re-analysis ran.

    python experiments/studies/redecided.py      # results/redecided.md and results/redecided/
    python experiments/studies/redecided.py --studies /tmp/r --output /tmp/r.md

Nothing is trained: each study is the library's own, `fppo_jax.study(..., reuse=<records>/study,
groups=0, margin=0.2)`, which takes every run from the recorded parts (the seed study's and the
spo-dpo plan's) and decides each comparison at one look at the recorded seeds (20 per setting
on MuJoCo, 50 on the classic tasks). One study per seed schedule and protocol within each of the
plan's three families (the seed study's 18 under the project's protocol and 6 without
normalisation, spo-dpo's 18), each at its share of the family's 0.05 (Bonferroni across the
studies of a family, Holm within each); each study is kept whole, with its plan, decisions and
report, in <studies>/<family>-<schedule>/.

Writes the report (default results/redecided.md): per comparison the decision (better, worse,
equivalent or undecided), the seeds per setting, P(candidate > ppo) with the repeated confidence
interval that the equivalence test held against ½ ± 0.2, and the earlier verdict beside it (the
original plan's Mann–Whitney p, Holm-adjusted over the same family), with the plan's commit and
digest.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
from study import PROTOCOLS

import fppo_jax
from fppo_jax.analysis.report_kit import LEVEL, mann_whitney_verdicts
from fppo_jax.analysis.study_runs import run_scores
from fppo_jax.stats.decidable import narrowest_half_width
from fppo_jax.stats.sequential import improvement_estimate
from fppo_jax.stats.spending import boundaries

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: shared modules

from common import (
    RESULTS,
    add_force_flag,
    argument_parser,
    header,
    refuse_to_replace,
    write_result,
)

REPOSITORY = Path(__file__).resolve().parents[2]
PLAN = REPOSITORY / "experiments" / "plans" / "redecided.json"
BASELINE = "ppo"
ENDPOINT = "final"
# Each family's protocol (the seed study's two, by their names in study.py).
PROTOCOL = {"fppo-paper": "paper", "fppo-unnormalised": "unnormalised", "spo-dpo": "paper"}
EARLIER = {
    "fppo-paper": "study.md",
    "fppo-unnormalised": "study.md",
    "spo-dpo": "spo-dpo.md",
}


def plan_identity(path: Path) -> tuple[str, str, str]:
    """The plan's digest (sha256 of its bytes, 12 hex digits), the commit that added it and
    whether the file differs from that commit ("" if not)."""
    digest = hashlib.sha256(path.read_bytes()).hexdigest()[:12]

    def git(*args: str) -> str:
        done = subprocess.run(
            ["git", *args], cwd=REPOSITORY, capture_output=True, text=True, check=False
        )
        return done.stdout.strip() if done.returncode == 0 else ""

    relative = str(path.relative_to(REPOSITORY))
    added = git("log", "--diff-filter=A", "--format=%H", "--", relative).splitlines()
    commit = added[-1] if added else "unknown"
    changed = git("log", "--format=%H", f"{commit}..HEAD", "--", relative) if added else ""
    dirty = git("status", "--porcelain", "--", relative)
    note = ""
    if changed or dirty:
        note = "the plan has changed since that commit"
    return digest, commit, note


def studies_of(plan: dict[str, Any]) -> list[dict[str, Any]]:
    """The studies the plan's families make: one per family and seed schedule, each at its
    share of the family's level (its comparisons over the family's)."""
    found = []
    for family, spec in plan["comparisons"].items():
        for schedule, tasks in spec["tasks"].items():
            comparisons = len(tasks) * len(spec["candidates"])
            found.append(
                {
                    "family": family,
                    "name": f"{family}-{schedule}",
                    "candidates": spec["candidates"],
                    "tasks": tasks,
                    "seeds": plan["seeds"][schedule],
                    "protocol": PROTOCOL[family],
                    "level": LEVEL * comparisons / spec["count"],
                    "comparisons": comparisons,
                }
            )
    for family, spec in plan["comparisons"].items():
        planned = sum(s["comparisons"] for s in found if s["family"] == family)
        if planned != spec["count"]:
            raise SystemExit(f"{family}: the plan counts {spec['count']}, its tasks {planned}")
    return found


def run_study(spec: dict[str, Any], plan: dict[str, Any], records: Path, out: Path) -> list[dict]:
    """One study over the recorded runs, nothing trained; a row per comparison with its
    decision, P(candidate > ppo) and the repeated interval, and the scores for the earlier
    test."""
    with contextlib.chdir(REPOSITORY):  # the plan names the parts' folder as a command would
        result = fppo_jax.study(
            spec["tasks"],
            spec["candidates"],
            BASELINE,
            output=out,
            reuse=os.path.relpath(records / "study"),
            groups=0,
            max_seeds=spec["seeds"],
            group_size=spec["seeds"],
            level=spec["level"],
            margin=plan["margin"],
            endpoint=ENDPOINT,
            progress=False,
            **PROTOCOLS[spec["protocol"]],
        )
    short = [
        f"{row['task']} {row['candidate']} ({row['seeds']} seeds)"
        for row in result.decisions
        if row["seeds"] != spec["seeds"]
    ]
    if not result.finished or short:
        raise SystemExit(
            f"{spec['name']}: the records do not hold every planned run ({', '.join(short)}); "
            "nothing is trained here"
        )
    rows = []
    for row in result.decisions:
        task_runs = result.results[row["task"]]
        candidate = run_scores(task_runs, row["candidate"], ENDPOINT)[: spec["seeds"]]
        baseline = run_scores(task_runs, BASELINE, ENDPOINT)[: spec["seeds"]]
        theta, _ = improvement_estimate(candidate, baseline)
        rows.append(
            {
                **row,
                "family": spec["family"],
                "study": spec["name"],
                "theta": theta,
                "scores": (candidate, baseline),
                "failed": int(np.sum(~np.isfinite(candidate)) + np.sum(~np.isfinite(baseline))),
            }
        )
    return rows


def earlier_verdicts(rows: list[dict]) -> None:
    """Each row's earlier verdict: the original plan's Mann–Whitney p, Holm-adjusted over the
    family, better or worse where it is below the family's level."""
    for family in dict.fromkeys(r["family"] for r in rows):
        members = [r for r in rows if r["family"] == family]
        verdicts = mann_whitney_verdicts([r["scores"] for r in members], level=LEVEL)
        for row, verdict in zip(members, verdicts, strict=True):
            row["holm"], row["earlier"] = verdict.holm, verdict.verdict


def _p(p: float) -> str:
    return f"{p:.1e}" if p < 0.001 else f"{p:.3f}"


def unreachable(studies: list[dict[str, Any]], margin: float) -> list[str]:
    """A line per study whose seeds cannot decide ``equivalent`` at all: its narrowest interval
    (at P = ½, the standard error at its floor, Holm's first level) is wider than the margin."""
    lines = []
    for spec in studies:
        critical = boundaries(spec["level"] / spec["comparisons"], (1.0,), sides=1)[0]
        narrowest = narrowest_half_width(spec["seeds"], critical)
        if narrowest > margin:
            lines.append(
                f"- {spec['name']}: at {spec['seeds']} seeds no interval can fit within "
                f"±{margin:g} (the narrowest is ±{narrowest:.2f}), as the plan said before the "
                "re-analysis: its comparisons can end better, worse or undecided only."
            )
    return lines


def report(
    plan: dict[str, Any],
    studies: list[dict[str, Any]],
    rows: list[dict],
    identity: tuple[str, str, str],
    where: str,
) -> list[str]:
    """The re-decided verdicts: the plan and how it decides, a row per comparison beside its
    earlier verdict, each family's count, where the two differ, and where the studies are."""
    failed = sum(r["failed"] for r in rows)
    return [
        *preamble(plan, studies, identity),
        *comparisons_table(rows),
        *family_counts(rows),
        *changed_lines(rows),
        "",
        f"Runs that diverged or finished no episode (ranked below every other): {failed}.",
        "",
        f"Each study whole (plan.json, decisions.json, report.md with the IQM differences and "
        f"what each interval rules out, figures): `{where}/<family>-<schedule>/` "
        f"({', '.join(s['name'] for s in studies)}).",
    ]


def preamble(
    plan: dict[str, Any], studies: list[dict[str, Any]], identity: tuple[str, str, str]
) -> list[str]:
    """The report's title, the plan (its commit and digest) and how each comparison is
    decided now and was decided before."""
    margin = plan["margin"]
    digest, commit, note = identity
    low, high = 0.5 - margin, 0.5 + margin
    return [
        *header(
            f"Which recorded FPPO, SPO and DPO comparisons with PPO are equivalent within "
            f"±{margin:g}? The re-decided verdicts"
        ),
        "",
        f"The plan: [`plans/redecided.json`](../plans/redecided.json), committed at "
        f"{commit[:12]} before this re-analysis ran (sha256 {digest})"
        + (f"; {note}." if note else ".")
        + " It is a re-analysis after the fact, not a preregistration of data: every run was "
        "recorded, and the earlier reports showed each comparison's probability of improvement, "
        "before the plan was written; what the plan fixed first is the margin, the endpoint, "
        "the families, the level and the seed schedule. Nothing was trained.",
        "",
        "- Endpoint: final return (each run's last-100-episode average return after its last "
        "update), as every original plan had it. Seeds: one look at the recorded count, "
        f"{plan['seeds']['mujoco']} per setting on MuJoCo and {plan['seeds']['classic']} on the "
        "classic tasks.",
        f"- Decisions (`fppo_jax.study` with `margin={margin:g}`, `reuse`, `groups=0`): better "
        "or worse where the two-sided Mann–Whitney z reaches Holm's boundary; **equivalent** "
        f"where the repeated confidence interval of P(candidate > ppo) lies within "
        f"[{low:.1f}, {high:.1f}] (no large effect either way, by Vargha and Delaney's 0.71; "
        "a medium one is not ruled out); undecided otherwise: neither a difference nor "
        "equivalence is shown, so the seeds are too few for the question, which does not say "
        "the variants differ.",
        f"- Families, each at family-wise error {LEVEL} for a false better or worse and {LEVEL} "
        "for a false equivalent, as each original plan had its family: the seed study's 18 "
        "comparisons under the project's protocol, its 6 without normalisation, and spo-dpo's "
        "18. A study has one seed schedule, so each family is one study per schedule at its "
        "share of the level (Bonferroni across them, Holm within each); across the three "
        "families either error may reach 0.15.",
        *unreachable(studies, margin),
        "- *P(> ppo) [repeated CI]*: the point estimate over the runs with the interval the "
        "equivalence test held against the margin (adjusted for the comparisons of its study, so "
        "at a level above 95%). *Earlier verdict*: the original plan's test "
        "recomputed from the same runs (Mann–Whitney's p, Holm over the family).",
        "",
    ]


def comparisons_table(rows: list[dict]) -> list[str]:
    """A row per comparison: its decision, seeds, P with its repeated interval, and the
    earlier verdict with its Holm p."""
    lines = [
        "| family | task | candidate | decision | seeds | P(> ppo) [repeated CI] "
        "| earlier verdict (Holm p) |",
        "|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        interval = row["interval"]
        lines.append(
            f"| {row['family']} | {row['task']} | {row['candidate']} | **{row['decision']}** "
            f"| {row['seeds']} | {row['theta']:.2f} [{interval[0]:.2f}, {interval[1]:.2f}] "
            f"| {row['earlier']} ({_p(row['holm'])}) |"
        )
    return lines


def family_counts(rows: list[dict]) -> list[str]:
    """Each family's decisions counted, with the comparisons decided better, worse or
    equivalent."""
    lines = ["", "Per family:", ""]
    for family in dict.fromkeys(r["family"] for r in rows):
        members = [r for r in rows if r["family"] == family]
        counts = {
            d: [f"{r['task']} {r['candidate']}" for r in members if r["decision"] == d]
            for d in ("better", "worse", "equivalent", "undecided")
        }
        said = "; ".join(
            f"{d} {len(names)}" + (f" ({', '.join(names)})" if names and d != "undecided" else "")
            for d, names in counts.items()
        )
        lines.append(
            f"- {family} ({len(members)} comparisons, earlier: {EARLIER[family]}): {said}."
        )
    return lines


def changed_lines(rows: list[dict]) -> list[str]:
    """The comparisons whose better or worse differs from the earlier verdict's, and why."""
    changed = [
        r
        for r in rows
        if {r["decision"], r["earlier"]} & {"better", "worse"} and r["decision"] != r["earlier"]
    ]
    lines = [""]
    if changed:
        lines += [
            "Where the difference decision differs from the earlier verdict (the study's z test "
            "at one look against Holm's boundary within its schedule, in place of Mann–Whitney's "
            "p with Holm over the whole family):",
            "",
            *(
                f"- {r['task']} {r['candidate']}: now {r['decision']}, earlier {r['earlier']} "
                f"(Holm p {_p(r['holm'])}); {r['reason']}."
                for r in changed
            ),
        ]
    else:
        lines.append("Every better and worse of the earlier verdicts is decided the same way here.")
    return lines


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--records", type=Path, default=RESULTS, help="where the parts are")
    parser.add_argument(
        "--studies", type=Path, default=RESULTS / "redecided", help="where the studies go"
    )
    parser.add_argument("--output", type=Path, default=RESULTS / "redecided.md", help="the report")
    add_force_flag(parser)
    args = parser.parse_args()
    refuse_to_replace([args.output, args.studies], args.force, elsewhere="--studies, --output")
    plan = json.loads(PLAN.read_text())
    studies = studies_of(plan)
    if args.studies.exists():  # --force: decided again from the records, whole
        shutil.rmtree(args.studies)
    rows = [
        row
        for spec in studies
        for row in run_study(spec, plan, args.records, args.studies / spec["name"])
    ]
    earlier_verdicts(rows)
    try:
        where = args.studies.resolve().relative_to(args.output.resolve().parent)
    except ValueError:
        where = args.studies
    write_result(args.output, report(plan, studies, rows, plan_identity(PLAN), str(where)))
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
