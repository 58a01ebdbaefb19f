"""FPPO's dose-response, as planned in experiments/plans/dose-response.json: does more pull
(FPPO-LP's α, FPPO-QP's k) give more return, and is there a dose at which FPPO beats PPO?

    python experiments/studies/dose_response.py     # results/dose_response.md and its figure
    python experiments/studies/dose_response.py \
        --results /tmp/smoke --tasks cartpole --output /tmp/d.md

Reads the parts ``study.py --plan plans/dose-response.json`` recorded under
<results>/dose_response/<task>/paper/, merges each task's, and writes the report and, in the
report's folder, dose_response/dose_response.png (IQM final return against the dose, with 95%
bootstrap bands). Until every setting of every task has the plan's seeds, it names what is missing,
writes nothing and exits with 1: the planned test is over the whole family.

What the plan fixed before its runs, computed here:
- the controls: α = 1 and k = 0 are PPO's objective, so each of their runs is checked against
  the same seed's PPO run of the sweep (identical curves expected), and the seed study's
  recorded PPO runs are set beside them (another program may round differently);
- the test, per task and variant: Spearman's ρ between dose and final return over the
  variant's runs (its control included), two-sided, p from 10,000 seeded permutations of the
  doses, Holm's adjustment over the family of trends, family-wise error 0.05;
- per dose, described (not a family): P(dose run > PPO run) and the IQM difference from PPO on
  the final return, the escape share (negative_fraction_after averaged over updates), the
  area under the curve, and the env steps to reach 50% and 80% of the sweep's PPO IQM final
  return; the same trend, with an interval, for the escape share and the steps.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from fppo_jax import SweepResult, merge
from fppo_jax.analysis.report_kit import NO_DIFFERENCE, holm_verdicts, interval_cell, ruled_out
from fppo_jax.core.resolution import SYMBOLS
from fppo_jax.run.results import labels
from fppo_jax.stats import statistics

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: shared modules

from _dose_controls import controls, controls_lines, doses, setting_index
from common import (
    RESULTS,
    add_force_flag,
    argument_parser,
    header,
    recorded_parts,
    refuse_to_replace,
    write_result,
)
from edges import edge, edge_note

EXPERIMENTS = Path(__file__).resolve().parents[1]
PLAN = EXPERIMENTS / "plans" / "dose-response.json"
FOLDER = "dose_response"  # study.py's folder of the plan's parts
SEEDS = 10
THRESHOLDS = (0.5, 0.8)  # of the sweep's PPO IQM final return
TREND_NAMES = {
    "final": "final return",
    "escape": "escape share",
    "auc": "area under the curve",
    0.5: "steps to 50% of PPO",
    0.8: "steps to 80% of PPO",
}
PERMUTATIONS = 10_000  # statistics.trend_test's
P_DECIMALS = 2  # what the permutation p's Monte Carlo error (0.003 to 0.005 here) allows
DPI = 80


def plan_parts(results: Path, task: str) -> list[SweepResult]:
    """Each part of `task` recorded for the plan: a sweep compiled and run on its own."""
    return list(recorded_parts(results / FOLDER / task / "paper").values())


def missing(plan: dict, merged: dict[str, SweepResult | None]) -> list[str]:
    """What the plan needs and the parts do not hold yet, a line per task."""
    lines = []
    for task, result in merged.items():
        if result is None:
            lines.append(f"{task}: not started")
            continue
        short = []
        wanted = [("ppo", None, None)] + [
            (variant, name, dose)
            for variant, (name, values) in doses(plan).items()
            for dose in values
        ]
        for variant, name, dose in wanted:
            try:
                count = result.setting_run_count(setting_index(result, variant, name, dose))
            except KeyError:
                count = 0
            if count < SEEDS:
                dosed = "" if name is None else f" {SYMBOLS.get(name, name)}={dose:g}"
                short.append(f"{variant}{dosed} {count}")
        if short:
            lines.append(f"{task}: {', '.join(short)} of {SEEDS} seeds")
    return lines


def run_scores(result: SweepResult, index: int) -> dict[str, np.ndarray]:
    """Setting `index`'s runs that did not diverge, by score: the final return, the area under
    the curve and the escape share."""
    metrics = result.setting_metrics(index)
    return {
        "final": statistics.endpoint(metrics["average_return"], "final"),
        "auc": statistics.endpoint(metrics["average_return"], "auc"),
        "escape": np.nanmean(metrics["negative_fraction_after"], axis=1),
    }


def steps_to(result: SweepResult, index: int, threshold: float) -> np.ndarray:
    """Each run's env steps to `threshold`; a run that never reaches it counts as slower than
    any that does (twice the run's length: ranks, not values, enter the trend)."""
    metrics = result.setting_metrics(index)
    steps = statistics.steps_to_threshold(
        metrics["average_return"], metrics["env_steps"], threshold
    )
    return np.where(np.isinf(steps), 2 * metrics["env_steps"][:, -1], steps)


def analyse(plan: dict, result: SweepResult) -> dict:
    """One task's trends and per-dose effects."""
    ppo_index = setting_index(result, "ppo", None, None)
    ppo = run_scores(result, ppo_index)
    ppo_iqm = float(statistics.iqm(ppo["final"]))
    levels = {share: share * ppo_iqm for share in THRESHOLDS}
    ppo.update({share: steps_to(result, ppo_index, level) for share, level in levels.items()})
    variants = {}
    for variant, (name, values) in doses(plan).items():
        runs = []
        for dose in values:
            index = setting_index(result, variant, name, dose)
            scores = run_scores(result, index)
            scores.update({share: steps_to(result, index, lv) for share, lv in levels.items()})
            runs.append(scores)
        trend = {
            score: statistics.dose_trend(values, [r[score] for r in runs])
            for score in ("final", "escape", "auc", *THRESHOLDS)
        }
        edges = {
            score: edge(
                interval,
                lambda seed, score=score, values=values, runs=runs: statistics.dose_trend(
                    values, [r[score] for r in runs], seed=seed
                ),
                0.0,
            )
            for score, interval in trend.items()
        }
        variants[variant] = {
            "name": name,
            "doses": values,
            "runs": runs,
            "trend": trend,
            "edges": edges,
            "p": statistics.trend_test(
                values, [r["final"] for r in runs], permutations=PERMUTATIONS
            ),
        }
    return {"ppo": ppo, "ppo_iqm": ppo_iqm, "levels": levels, "variants": variants}


def reached(steps: np.ndarray, total: float) -> str:
    """How many runs reach a threshold, and the median env steps of those that do."""
    hit = steps[steps <= total]
    return f"{hit.size}/{steps.size}" + (f", median {np.median(hit):,.0f}" if hit.size else "")


# The verdict on a trend of final return with the dose, by Holm's p and the sign of ρ.
READINGS = {
    "better": "more pull, more return",
    "worse": "more pull, less return",
    NO_DIFFERENCE: "no trend measurable",
}


def report(
    plan: dict,
    tasks: dict[str, dict],
    results: dict[str, SweepResult],
    checks: dict,
    parts: dict[str, list[SweepResult]],
) -> list[str]:
    """The report: the plan, its controls (`checks`, by task) and how its runs were compiled
    (`parts`), the planned test of the trends, the other trends, and each dose against PPO."""
    lines = [
        *header(f"{plan['question']} The planned dose-response"),
        "",
        f"The plan ([`plans/dose-response.json`](../plans/dose-response.json), written "
        f"{plan['written']}): {plan['test']}. Endpoint: {plan['primary_endpoint']}. Intervals "
        "are 95% percentile bootstraps (2,000 resamples, seeded), resampling each dose's runs "
        "among themselves; P(X > Y) counts ties as ½. Runs that diverged are left out and "
        "counted below.",
        "",
        *controls_lines(plan, checks, parts),
    ]
    rows = trend_rows(tasks)
    lines += planned_trends(rows) + other_trends(rows)
    for task, outcome in tasks.items():
        lines += doses_against_ppo(task, outcome, results[task])
    return lines


def trend_rows(tasks: dict[str, dict]) -> list[dict]:
    """A row per task and dosed variant, with the planned test's Holm p over the family of
    trends and its reading."""
    rows = [
        {"task": task, "variant": variant, **analysis}
        for task, outcome in tasks.items()
        for variant, analysis in outcome["variants"].items()
    ]
    trends = holm_verdicts(
        [row["p"] for row in rows], [row["trend"]["final"][0] for row in rows], no_effect=0.0
    )
    for row, trend in zip(rows, trends, strict=True):
        row["holm"], row["reading"] = trend.holm, READINGS[trend.verdict]
    return rows


def planned_trends(rows: list[dict]) -> list[str]:
    """The planned test: each trend of final return with the dose, its permutation p and
    Holm's p, and its reading."""
    errors = [permutation_error(row["p"]) for row in rows]
    lines = [
        "## The planned test: the trend of final return with the dose",
        "",
        f"The permutation p is a Monte Carlo estimate: its standard error, "
        f"√(p(1 − p)/{PERMUTATIONS:,}), is {min(errors):.3f} to {max(errors):.3f} here, so p "
        f"and Holm's p are printed to {P_DECIMALS} decimals.",
        "",
        "| task | variant | doses | Spearman ρ, final [95% CI] | permutation p | Holm p "
        "| reading |",
        "|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        lines.append(
            f"| {row['task']} | {row['variant']} | {SYMBOLS.get(row['name'], row['name'])} ∈ "
            f"{{{', '.join(f'{d:g}' for d in row['doses'])}}} "
            f"| {interval_cell(row['trend']['final'], '.2f')} | {row['p']:.{P_DECIMALS}f} "
            f"| {row['holm']:.{P_DECIMALS}f} | {row['reading']} |"
        )
    return lines + edge_note(
        [
            f"{row['task']} {row['variant']}, final: {row['edges']['final'].text()}"
            for row in rows
            if row["edges"]["final"] is not None
        ],
        "0",
    )


def other_trends(rows: list[dict]) -> list[str]:
    """The trends described, not tested: of the escape share, the area under the curve and
    the steps to each threshold."""
    lines = [
        "",
        "## The other trends (described, not tested)",
        "",
        "Spearman ρ [95% CI] with the dose. The escape share is the share of the batch left in "
        "R+ ∪ R− after the update, averaged over updates (lower: more escape); steps to a "
        "threshold are ranked with a run that never reaches it as the slowest.",
        "",
        "| task | variant | escape share | area under the curve | steps to 50% of PPO "
        "| steps to 80% of PPO |",
        "|---|---|---|---|---|---|",
    ]
    for row in rows:
        trend = row["trend"]
        cells = [interval_cell(trend[s], ".2f") for s in ("escape", "auc", *THRESHOLDS)]
        lines.append(f"| {row['task']} | {row['variant']} | {' | '.join(cells)} |")
    return lines + edge_note(
        [
            f"{row['task']} {row['variant']}, {TREND_NAMES[score]}: {at_edge.text()}"
            for row in rows
            for score, at_edge in row["edges"].items()
            if score != "final" and at_edge is not None
        ],
        "0",
    )


def doses_against_ppo(task: str, outcome: dict, result: SweepResult) -> list[str]:
    """`task`'s section: PPO's runs, then a row per dose against them (described)."""
    ppo = outcome["ppo"]
    total = float(result.metrics["env_steps"][0, -1])
    level = ", ".join(f"{s:.0%}: {v:,.1f}" for s, v in outcome["levels"].items())
    ppo_final = interval_cell(statistics.interval(ppo["final"]), ".1f")
    lines = [
        "",
        f"## {task}: each dose against PPO",
        "",
        f"PPO's IQM final return {ppo_final} over "
        f"{ppo['final'].size} runs; thresholds {level}. Reaching a threshold: runs that do, "
        "and their median env steps.",
        "",
        "| setting | runs | IQM final [95% CI] | P(> PPO), final [95% CI] "
        "| Δ IQM final [95% CI] | the interval rules out | P(> PPO), AUC [95% CI] "
        "| IQM escape share [95% CI] | reach 50% | reach 80% |",
        "|---|---|---|---|---|---|---|---|---|---|",
        f"| ppo | {ppo['final'].size} | {ppo_final} "
        f"| – | – | – | – | {interval_cell(statistics.interval(ppo['escape']), '.3f')} "
        f"| {reached(ppo[0.5], total)} | {reached(ppo[0.8], total)} |",
    ]
    names = dict(zip(map(_key, result.settings), labels(result.settings), strict=True))
    edges: list[str] = []
    for variant, analysis in outcome["variants"].items():
        for dose, runs in zip(analysis["doses"], analysis["runs"], strict=True):
            label = names[_key({"variant": variant, analysis["name"]: dose})]
            lines.append(dose_row(label, runs, outcome, total, edges))
    diverged = int(np.count_nonzero(result.diverged))
    return [
        *lines,
        *edge_note(edges, "0.5"),
        "",
        f"Runs that diverged and are left out: {diverged}.",
    ]


def dose_row(label: str, runs: dict, outcome: dict, total: float, edges: list[str]) -> str:
    """One dose's row against PPO's runs (`outcome`'s), its intervals at the edge of 0.5 added
    to `edges`."""
    ppo = outcome["ppo"]
    on_final = statistics.compare(runs["final"], ppo["final"])
    on_area = statistics.compare(runs["auc"], ppo["auc"])
    for score, key, on in (("final", "final", on_final), ("AUC", "auc", on_area)):
        at_edge = edge(
            on["probability_of_improvement"],
            lambda seed, key=key: statistics.compare(runs[key], ppo[key], seed=seed)[
                "probability_of_improvement"
            ],
            0.5,
        )
        if at_edge is not None:
            edges.append(f"{label}'s P(> PPO), {score}: {at_edge.text()}")
    return (
        f"| {label} | {runs['final'].size} "
        f"| {interval_cell(statistics.interval(runs['final']), '.1f')} "
        f"| {interval_cell(on_final['probability_of_improvement'], '.2f')} "
        f"| {interval_cell(on_final['iqm_difference'], '.1f')} "
        f"| {ruled_out(on_final['iqm_difference'], outcome['ppo_iqm'])} "
        f"| {interval_cell(on_area['probability_of_improvement'], '.2f')} "
        f"| {interval_cell(statistics.interval(runs['escape']), '.3f')} "
        f"| {reached(runs[0.5], total)} | {reached(runs[0.8], total)} |"
    )


def permutation_error(p: float) -> float:
    """The Monte Carlo standard error of a permutation p from :data:`PERMUTATIONS` draws."""
    return float(np.sqrt(p * (1 - p) / PERMUTATIONS))


def _key(setting: dict) -> tuple:
    return tuple(sorted(setting.items()))


def draw(tasks: dict[str, dict], path: Path) -> None:
    """IQM final return against the dose, a panel per task and variant, with 95% bootstrap
    bands; PPO's IQM and band across each panel."""
    variants = list(next(iter(tasks.values()))["variants"])
    figure, axes = plt.subplots(
        len(variants), len(tasks), figsize=(4 * len(tasks), 3 * len(variants)), squeeze=False
    )
    for column, (task, outcome) in enumerate(tasks.items()):
        ppo = statistics.interval(outcome["ppo"]["final"])
        for row, variant in enumerate(variants):
            analysis, ax = outcome["variants"][variant], axes[row][column]
            values = np.array([statistics.interval(r["final"]) for r in analysis["runs"]])
            ax.axhspan(ppo[1], ppo[2], color="grey", alpha=0.2)
            ax.axhline(ppo[0], color="grey", label="PPO (IQM, 95% CI)")
            ax.fill_between(analysis["doses"], values[:, 1], values[:, 2], alpha=0.3)
            ax.plot(analysis["doses"], values[:, 0], marker="o", label=variant)
            ax.set_xlabel(SYMBOLS.get(analysis["name"], analysis["name"]))
            ax.set_ylabel("IQM final return")
            ax.set_title(f"{task}: {variant}")
            ax.legend(fontsize="small")
    figure.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=DPI)
    plt.close(figure)


def main() -> int:
    parser = argument_parser(__doc__)
    parser.add_argument("--results", type=Path, default=RESULTS, help="where the parts are")
    parser.add_argument("--tasks", nargs="+", help="default: the plan's (Hopper and Walker2d)")
    parser.add_argument(
        "--output", type=Path, help="the report (default: results/dose_response.md)"
    )
    add_force_flag(parser)
    args = parser.parse_args()
    plan = json.loads(PLAN.read_text())
    out = args.output or args.results / f"{FOLDER}.md"
    figure = out.parent / FOLDER / f"{FOLDER}.png"
    refuse_to_replace([out, figure], args.force, elsewhere="--results DIR or --output FILE")
    by_task = {task: plan_parts(args.results, task) for task in args.tasks or plan["tasks"]}
    merged = {task: merge(of_task) if of_task else None for task, of_task in by_task.items()}
    short = missing(plan, merged)
    if short:
        print(
            f"no report yet: the plan's test is over every trend, and {len(short)} task(s) "
            "lack runs:\n  " + "\n  ".join(short),
            file=sys.stderr,
        )
        return 1
    results = {task: result for task, result in merged.items() if result is not None}
    tasks = {task: analyse(plan, result) for task, result in results.items()}
    checks = {}
    for task, result in results.items():
        parts = list(recorded_parts(args.results / "study" / task / "paper").values())
        parts = [p for p in parts if any(s["variant"] == "ppo" for s in p.settings)]
        checks[task] = controls(result, merge(parts) if parts else None, plan)
    compiled = {task: of_task for task, of_task in by_task.items() if task in results}
    write_result(out, report(plan, tasks, results, checks, compiled))
    draw(tasks, figure)
    print(f"wrote {out} and {figure}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
