"""The verdict of a comparison planned in experiments/plans/: candidates against a baseline's
recorded seed-study runs, with the plan's fixed seeds, test and family.

    python experiments/planned_verdict.py plans/spo-dpo.json    # results/spo-dpo.md
    python experiments/planned_verdict.py plans/spo-dpo.json --results /tmp/smoke --output /tmp/v.md

Reads the plan (its baseline, candidates and tasks), merges every part recorded under
<results>/study/<task>/paper/ that ran one of its variants (the baseline's are the seed study's
own, same seeds), and writes results/<plan's name>.md (or --output). The plan's seeds are 50 per
variant on the classic tasks and 20 on MuJoCo; until every comparison has them, no verdict is
written: the command names what is missing and exits with 1, since the planned test is over the
whole family.

Per comparison: Mann–Whitney's test of P(candidate > baseline) = ½ on final returns, Holm's
step-down adjustment over the family (a *Holm p* below 0.05 is a difference that survives the
number of comparisons), P(candidate > baseline) and the IQM difference with 95% percentile
bootstrap intervals, and the relative effects that interval rules out.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from common import (
    CLASSIC_TASKS,
    RESULTS,
    RUN_RECORD,
    add_force_flag,
    argument_parser,
    header,
    refuse_to_replace,
    write_result,
)
from verdict import by_variant, interval_text, outcome, run_counts

from fppo_jax import SweepResult, merge, statistics
from fppo_jax.envs import MUJOCO_TASKS
from fppo_jax.study_report import ruled_out

EXPERIMENTS = Path(__file__).resolve().parent
SEEDS = {**dict.fromkeys(CLASSIC_TASKS, 50), **dict.fromkeys(MUJOCO_TASKS, 20)}
FAMILY_ERROR = 0.05


def recorded(results: Path, task: str, variants: set[str]) -> SweepResult | None:
    """Every part of `task` under the paper protocol that ran one of `variants`, merged."""
    parts = [
        SweepResult.read(record.parent)
        for record in sorted((results / "study" / task / "paper").glob(f"*/{RUN_RECORD}"))
    ]
    parts = [p for p in parts if variants & {s["variant"] for s in p.settings}]
    return merge(parts) if parts else None


def missing(plan: dict, merged: dict[str, SweepResult | None]) -> list[str]:
    """What the plan needs and the results do not hold yet, a line per task."""
    variants = (plan["baseline"]["variant"], *plan["candidates"])
    lines = []
    for task in plan["tasks"]:
        counts = run_counts(merged[task], variants)
        short = [f"{v} {n} of {SEEDS[task]}" for v, n in counts.items() if n < SEEDS[task]]
        if short:
            lines.append(f"{task}: {', '.join(short)} seeds")
    return lines


def comparisons(plan: dict, merged: dict[str, SweepResult]) -> list[dict]:
    """A row per (task, candidate): the test's raw and Holm-adjusted p and the effects."""
    baseline = plan["baseline"]["variant"]
    rows = []
    for task in plan["tasks"]:
        result = merged[task]
        index, final, area = by_variant(result), result.scores("final"), result.scores("auc")
        base = final[index[baseline]][: SEEDS[task]]
        for candidate in plan["candidates"]:
            runs = final[index[candidate]][: SEEDS[task]]
            on_final = statistics.compare(runs, base)
            rows.append(
                {
                    "task": task,
                    "candidate": candidate,
                    "p": statistics.improvement_test(runs, base),
                    "probability": on_final["probability_of_improvement"],
                    "difference": on_final["iqm_difference"],
                    "baseline_iqm": float(statistics.iqm(base)),
                    "candidate_iqm": statistics.interval(runs),
                    "area": statistics.compare(
                        area[index[candidate]][: SEEDS[task]], area[index[baseline]][: SEEDS[task]]
                    )["probability_of_improvement"],
                }
            )
    for row, adjusted in zip(rows, statistics.holm([r["p"] for r in rows]), strict=True):
        row["holm"] = float(adjusted)
    return rows


def _p(p: float) -> str:
    return f"{p:.1e}" if p < 0.001 else f"{p:.3f}"


def decision(row: dict) -> str:
    """The planned test's answer: better or worse where Holm's p is below the family's error."""
    if row["holm"] >= FAMILY_ERROR:
        return "no measurable difference"
    return "better" if row["probability"][0] > 0.5 else "worse"


def report(plan: dict, name: str, rows: list[dict], merged: dict[str, SweepResult]) -> list[str]:
    baseline = plan["baseline"]["variant"]
    lines = [
        *header(f"{plan['question']} The planned verdict"),
        "",
        f"The plan ([`plans/{name}.json`](../plans/{name}.json), written {plan['written']}): "
        f"{' and '.join(plan['candidates'])} against {baseline}'s recorded runs on "
        f"{len(plan['tasks'])} tasks, 50 seeds on the classic tasks and 20 on MuJoCo; "
        f"{plan['test']}. Endpoint: {plan['primary_endpoint']}. Intervals are 95% percentile "
        "bootstraps (2,000 resamples, seeded); P(X > Y) counts ties as ½.",
        "",
        f"| task | candidate | IQM final [95% CI] | {baseline} IQM final "
        f"| P(> {baseline}), final [95% CI] | p | Holm p | verdict | Δ IQM final [95% CI] "
        f"| the interval rules out | P(> {baseline}), AUC [95% CI] |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        lines.append(
            f"| {row['task']} | {row['candidate']} | {interval_text(row['candidate_iqm'])} "
            f"| {row['baseline_iqm']:.1f} | {interval_text(row['probability'], '.2f')} "
            f"| {_p(row['p'])} | {_p(row['holm'])} | {decision(row)} "
            f"| {interval_text(row['difference'])} "
            f"| {ruled_out(row['difference'], row['baseline_iqm'])} "
            f"| {interval_text(row['area'], '.2f')} |"
        )
    mujoco = [t for t in plan["tasks"] if t in MUJOCO_TASKS]
    lines += [
        "",
        f"Across the {len(mujoco)} MuJoCo tasks (secondary, not in the family): P(> {baseline}) "
        "on final returns averaged over tasks, with a bootstrap that resamples each task's runs "
        "among themselves.",
        "",
        f"| candidate | mean P(> {baseline}) [95% CI] | the interval says |",
        "|---|---|---|",
    ]
    for candidate in plan["candidates"]:
        pairs = []
        for task in mujoco:
            index, final = by_variant(merged[task]), merged[task].scores("final")
            pairs.append(
                (final[index[candidate]][: SEEDS[task]], final[index[baseline]][: SEEDS[task]])
            )
        value = statistics.aggregate_improvement(pairs)
        lines.append(f"| {candidate} | {interval_text(value, '.2f')} | {outcome(value)} |")
    return lines


def main() -> int:
    parser = argument_parser(__doc__)
    parser.add_argument("plan", type=Path, help="the plan, relative to experiments/ or not")
    parser.add_argument("--results", type=Path, default=RESULTS, help="where the parts are")
    parser.add_argument("--output", type=Path, help="the report (default: results/<plan>.md)")
    add_force_flag(parser)
    args = parser.parse_args()
    path = args.plan if args.plan.exists() else EXPERIMENTS / args.plan
    plan = json.loads(path.read_text())
    out = args.output or RESULTS / f"{path.stem}.md"
    refuse_to_replace([out], args.force, elsewhere="--output FILE")
    variants = {plan["baseline"]["variant"], *plan["candidates"]}
    merged = {task: recorded(args.results, task, variants) for task in plan["tasks"]}
    short = missing(plan, merged)
    if short:
        print(
            f"no verdict yet: the plan's test is over every comparison, and {len(short)} "
            f"task(s) lack seeds:\n  " + "\n  ".join(short),
            file=sys.stderr,
        )
        return 1
    complete = {task: result for task, result in merged.items() if result is not None}
    rows = comparisons(plan, complete)
    write_result(out, report(plan, path.stem, rows, complete))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
