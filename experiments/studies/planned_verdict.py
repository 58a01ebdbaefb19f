"""The verdict of a comparison planned in experiments/plans/: candidates against a baseline's
recorded seed-study runs, with the plan's fixed seeds, test and family.

    python experiments/studies/planned_verdict.py plans/spo-dpo.json    # results/spo-dpo.md
    python experiments/studies/planned_verdict.py plans/baseline-shape.json
    python experiments/studies/planned_verdict.py plans/spo-dpo.json \
        --results /tmp/smoke --output /tmp/v.md

Reads the plan (its baseline, candidates and tasks) and writes results/<plan's name>.md (or
--output). The baseline's runs are the seed study's, recorded under <results>/study/<task>/paper/.
The candidates' are there too (spo-dpo), or, for a plan that trains them at its own
``settings`` (baseline-shape: PPO at 1 × 2,048), in the plan's own parts, recorded by
``study.py --plan`` under <results>/<plan's name>/<task>/paper/; the baseline's runs are then
checked to have the rollout shape the plan names. The plan's seeds are 0–49 on the classic tasks
and 0–19 on MuJoCo; until every comparison has them, no verdict is written: the command names
what is missing and exits with 1, since the planned test is over the whole family.

Per comparison: Mann–Whitney's test of P(candidate > baseline) = ½ on final returns, Holm's
step-down adjustment over the family (a *Holm p* below 0.05 is a difference that survives the
number of comparisons), P(candidate > baseline) and the IQM difference with 95% percentile
bootstrap intervals, and the relative effects that interval rules out. On HalfCheetah, whose
final returns split into two clusters, each arm's share of runs in the high one.
"""

from __future__ import annotations

import json
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fppo_jax import SweepResult, merge
from fppo_jax.analysis.report_kit import interval_cell, mann_whitney_verdicts, ruled_out
from fppo_jax.envs import MUJOCO_TASKS
from fppo_jax.stats import statistics

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: shared modules

from common import (
    CLASSIC_TASKS,
    RESULTS,
    add_force_flag,
    argument_parser,
    by_variant,
    header,
    recorded_parts,
    refuse_to_replace,
    write_result,
)
from edges import EDGE_SEEDS, edge, outcome

EXPERIMENTS = Path(__file__).resolve().parents[1]
SEEDS = {**dict.fromkeys(CLASSIC_TASKS, 50), **dict.fromkeys(MUJOCO_TASKS, 20)}
SHAPE_FOLDER = "baseline_shape"  # plans/baseline-shape.json's parts, under the results
HIGH_CLUSTER = {"halfcheetah": 3000.0}  # its final returns split there (plans/baseline-shape.json)


@dataclass
class Arm:
    """One side of a comparison on one task: the scores of its runs at the plan's seeds (those
    that did not diverge), and how many runs it has there, diverged ones included."""

    final: np.ndarray
    auc: np.ndarray
    runs: int


def recorded(folder: Path, task: str, variants: set[str]) -> SweepResult | None:
    """Every part of `task` under the paper protocol in `folder` that ran one of `variants`,
    merged."""
    parts = list(recorded_parts(folder / task / "paper").values())
    parts = [p for p in parts if variants & {s["variant"] for s in p.settings}]
    return merge(parts) if parts else None


def _shape(settings: dict) -> str:
    return f" {settings['num_envs']}×{settings['num_steps']}" if "num_envs" in settings else ""


def arm_names(plan: dict) -> tuple[str, list[str]]:
    """The baseline's name and the candidates', with their rollout shapes where the plan sets
    its own: ``ppo 8×256`` against ``ppo 1×2048``."""
    own = plan.get("settings", {})
    baseline = plan["baseline"]["variant"] + (_shape(plan["baseline"]) if own else "")
    return baseline, [candidate + _shape(own) for candidate in plan["candidates"]]


def arm(result: SweepResult | None, variant: str, seeds: int) -> Arm | None:
    """`variant`'s runs in `result` at seeds 0 to `seeds` − 1, if it has any."""
    index = {} if result is None else by_variant(result)
    if result is None or variant not in index:
        return None
    planned = [i for i, r in enumerate(result.runs) if r["seed"] < seeds]
    kept = [i for i in result.setting_runs(index[variant])[0] if i in planned]
    curves = result.metrics["average_return"][kept]
    return Arm(
        final=statistics.endpoint(curves, "final"),
        auc=statistics.endpoint(curves, "auc"),
        runs=sum(result.runs[i]["setting"] == index[variant] for i in planned),
    )


def arms(plan: dict, study: Path, own: Path | None, task: str) -> dict[str, Arm | None]:
    """Each arm of `plan` on `task`, by name (:func:`arm_names`): the baseline from the seed
    study's parts in `study`, the candidates from there too, or from the plan's `own` parts."""
    baseline, candidates = arm_names(plan)
    variant = plan["baseline"]["variant"]
    studied = recorded(study, task, {variant, *plan["candidates"]})
    trained = studied if own is None else recorded(own, task, set(plan["candidates"]))
    if own is not None and studied is not None:
        recorded_shape = _shape(studied.config)
        if recorded_shape != _shape(plan["baseline"]):
            raise SystemExit(
                f"{task}: the seed study's recorded runs are{recorded_shape}, and the plan's "
                f"baseline is{_shape(plan['baseline'])}: not the baseline the plan names"
            )
    return {
        baseline: arm(studied, variant, SEEDS[task]),
        **{
            name: arm(trained, candidate, SEEDS[task])
            for name, candidate in zip(candidates, plan["candidates"], strict=True)
        },
    }


def missing(every: dict[str, dict[str, Arm | None]]) -> list[str]:
    """What the plan needs and the results do not hold yet, a line per task."""
    lines = []
    for task, by_name in every.items():
        counts = {name: 0 if a is None else a.runs for name, a in by_name.items()}
        short = [f"{name} {n} of {SEEDS[task]}" for name, n in counts.items() if n < SEEDS[task]]
        if short:
            lines.append(f"{task}: {', '.join(short)} seeds")
    return lines


def comparisons(plan: dict, every: dict[str, dict[str, Arm]]) -> list[dict]:
    """A row per (task, candidate): the test's raw and Holm-adjusted p, its verdict and the
    effects."""
    baseline, candidates = arm_names(plan)
    rows, tested = [], []
    for task, by_name in every.items():
        base = by_name[baseline]
        for candidate in candidates:
            runs = by_name[candidate]
            tested.append((runs.final, base.final))
            on_final = statistics.compare(runs.final, base.final)
            rows.append(
                {
                    "task": task,
                    "candidate": candidate,
                    "probability": on_final["probability_of_improvement"],
                    "difference": on_final["iqm_difference"],
                    "baseline_iqm": float(statistics.iqm(base.final)),
                    "candidate_iqm": statistics.interval(runs.final),
                    "area": statistics.compare(runs.auc, base.auc)["probability_of_improvement"],
                }
            )
    for row, verdict in zip(rows, mann_whitney_verdicts(tested), strict=True):
        row |= {"p": verdict.p, "holm": verdict.holm, "verdict": verdict.verdict}
    return rows


def _p(p: float) -> str:
    return f"{p:.1e}" if p < 0.001 else f"{p:.3f}"


def seed_text(tasks: list[str]) -> str:
    """The plan's seeds, for the kinds of task it has: ``seeds 0–19`` on MuJoCo only."""
    kinds = {
        "the classic tasks": [t for t in tasks if t in CLASSIC_TASKS],
        "MuJoCo": [t for t in tasks if t in MUJOCO_TASKS],
    }
    kinds = {kind: of_kind for kind, of_kind in kinds.items() if of_kind}
    if len(kinds) == 1:
        return f"seeds 0–{SEEDS[next(iter(kinds.values()))[0]] - 1}"
    return "seeds " + " and ".join(f"0–{SEEDS[t[0]] - 1} on {kind}" for kind, t in kinds.items())


def ceiling(plan: dict, rows: list[dict], every: dict[str, dict[str, Arm]]) -> list[str]:
    """A note on each *better* verdict whose candidate's IQM, interval and all, is the highest
    final return any run of the task reaches: a ceiling, where the verdict says how often runs
    end at the cap more than how well they learn."""
    baseline, _ = arm_names(plan)
    lines = []
    for task in every:
        top = max(float(np.max(a.final)) for a in every[task].values())
        capped = [
            r
            for r in rows
            if r["task"] == task
            and r["verdict"] == "better"
            and r["candidate_iqm"][1] == r["candidate_iqm"][2] == top
        ]
        if not capped:
            continue
        shares = ", ".join(
            f"{name} {int(np.sum(a.final >= top))} of {a.final.size}"
            for name, a in every[task].items()
        )
        names = " and ".join(f"{r['candidate']}'s" for r in capped)
        verdicts = "verdicts are" if len(capped) > 1 else "verdict is"
        lines += [
            "",
            f"{task}: {names} *better* {verdicts} a ceiling effect. Their IQM final return is "
            f"{top:.1f}, interval and all, the highest final return any run of the task "
            f"reaches (its cap), and {baseline}'s IQM {capped[0]['baseline_iqm']:.1f} is just "
            f"below it; runs ending at the cap: {shares}. The {verdicts.split()[0]} "
            f"{'say' if len(capped) > 1 else 'says'} that their runs end at the cap more often, "
            "not that they learn more.",
        ]
    return lines


def other_baseline(
    plan: dict, rows: list[dict], every: dict[str, dict[str, Arm]], results: Path
) -> list[str]:
    """Each *better* verdict set beside PPO at OpenAI baselines' rollout shape (1 × 2,048,
    recorded for plans/baseline-shape.json at the same seeds) where that shape was run:
    descriptive, outside the family, since the recorded baseline is this project's 8 × 256."""
    if "settings" in plan or plan["baseline"]["variant"] != "ppo":
        return []
    lines = []
    for row in rows:
        if row["verdict"] != "better":
            continue
        shaped = arm(
            recorded(results / SHAPE_FOLDER, row["task"], {"ppo"}), "ppo", SEEDS[row["task"]]
        )
        if shaped is None:
            continue
        candidate = every[row["task"]][row["candidate"]]
        probability = statistics.compare(candidate.final, shaped.final)[
            "probability_of_improvement"
        ]
        at_edge = edge(
            probability,
            lambda seed, c=candidate, s=shaped: statistics.compare(c.final, s.final, seed=seed)[
                "probability_of_improvement"
            ],
            0.5,
        )
        side = {
            "better": "above it too",
            "worse": "below it",
            "at the edge": f"at the edge of below it ({at_edge.text() if at_edge else ''})",
        }.get(outcome(probability, at_edge), "not told from it")
        shaped_iqm = interval_cell(statistics.interval(shaped.final), ".1f")
        candidate_iqm = interval_cell(row["candidate_iqm"], ".1f")
        lines += [
            "",
            f"{row['task']}: {row['candidate']}'s *better* is against the recorded baseline, "
            f"PPO at this project's 8 × 256. PPO at OpenAI baselines' 1 × 2,048 (the same "
            f"seeds, recorded for [`plans/baseline-shape.json`](../plans/baseline-shape.json)) "
            f"ends at IQM {shaped_iqm}, against {row['candidate']}'s {candidate_iqm}: "
            f"P({row['candidate']} > ppo 1×2048) = {interval_cell(probability, '.2f')}, {side}. "
            "Descriptive, not in the family.",
        ]
    return lines


def high_cluster(plan: dict, every: dict[str, dict[str, Arm]]) -> list[str]:
    """Each arm's share of runs in the high cluster of the tasks whose returns split, with the
    difference from the baseline's share and its bootstrap interval (descriptive)."""
    baseline, candidates = arm_names(plan)
    lines = []
    for task, level in HIGH_CLUSTER.items():
        if task not in every:
            continue
        high = {name: (a.final > level).astype(float) for name, a in every[task].items()}
        lines += [
            "",
            f"{task}'s final returns split into two clusters: the share of runs above "
            f"{level:,.0f} (descriptive, not in the family).",
            "",
            f"| arm | runs above {level:,.0f} | share − {baseline}'s [95% CI] |",
            "|---|---|---|",
            f"| {baseline} | {int(high[baseline].sum())} of {high[baseline].size} | – |",
        ]
        for name in candidates:
            difference = statistics.bootstrap(
                [high[name], high[baseline]], lambda x, y, axis=-1: x.mean(axis) - y.mean(axis)
            )
            lines.append(
                f"| {name} | {int(high[name].sum())} of {high[name].size} "
                f"| {interval_cell(difference, '.2f')} |"
            )
    return lines


def report(
    plan: dict, name: str, rows: list[dict], every: dict[str, dict[str, Arm]], results: Path
) -> list[str]:
    """The verdict: the plan, a row per comparison, and the notes and descriptive tables
    beside the family."""
    baseline, candidates = arm_names(plan)
    lines = [
        *header(f"{plan['question']} The planned verdict"),
        "",
        f"The plan ([`plans/{name}.json`](../plans/{name}.json), written {plan['written']}): "
        f"{' and '.join(candidates)} against {baseline}'s recorded runs on "
        f"{len(plan['tasks'])} tasks, {seed_text(plan['tasks'])}; "
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
            f"| {row['task']} | {row['candidate']} | {interval_cell(row['candidate_iqm'], '.1f')} "
            f"| {row['baseline_iqm']:.1f} | {interval_cell(row['probability'], '.2f')} "
            f"| {_p(row['p'])} | {_p(row['holm'])} | {row['verdict']} "
            f"| {interval_cell(row['difference'], '.1f')} "
            f"| {ruled_out(row['difference'], row['baseline_iqm'])} "
            f"| {interval_cell(row['area'], '.2f')} |"
        )
    lines += ceiling(plan, rows, every) + other_baseline(plan, rows, every, results)
    return lines + across_mujoco(plan, every) + high_cluster(plan, every)


def across_mujoco(plan: dict, every: dict[str, dict[str, Arm]]) -> list[str]:
    """Where the plan has several MuJoCo tasks, each candidate's P(> baseline) averaged over
    them, with a bootstrap stratified by task (secondary, not in the family)."""
    baseline, candidates = arm_names(plan)
    mujoco = [t for t in every if t in MUJOCO_TASKS]
    lines: list[str] = []
    if len(mujoco) > 1:
        lines += [
            "",
            f"Across the {len(mujoco)} MuJoCo tasks (secondary, not in the family): "
            f"P(> {baseline}) on final returns averaged over tasks, with a bootstrap that "
            "resamples each task's runs among themselves.",
            "",
            f"| candidate | mean P(> {baseline}) [95% CI] | the interval says |",
            "|---|---|---|",
        ]
        edges = []
        for candidate in candidates:
            pairs = [(every[t][candidate].final, every[t][baseline].final) for t in mujoco]
            value = statistics.aggregate_improvement(pairs)
            at_edge = edge(
                value,
                lambda seed, pairs=pairs: statistics.aggregate_improvement(pairs, seed=seed),
                0.5,
            )
            if at_edge is not None:
                edges.append(f"{candidate}: {at_edge.text()}")
            lines.append(
                f"| {candidate} | {interval_cell(value, '.2f')} | {outcome(value, at_edge)} |"
            )
        if edges:
            lines += [
                "",
                "At the edge: a bound within the bootstrap's Monte Carlo error of 0.5 (the "
                f"range of that bound over {EDGE_SEEDS} resampling seeds): " + "; ".join(edges),
            ]
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
    own = args.results / path.stem.replace("-", "_") if "settings" in plan else None
    every = {task: arms(plan, args.results / "study", own, task) for task in plan["tasks"]}
    short = missing(every)
    if short:
        print(
            f"no verdict yet: the plan's test is over every comparison, and {len(short)} "
            f"task(s) lack seeds:\n  " + "\n  ".join(short),
            file=sys.stderr,
        )
        return 1
    complete = {
        task: {name: a for name, a in by_name.items() if a is not None}
        for task, by_name in every.items()
    }
    rows = comparisons(plan, complete)
    write_result(out, report(plan, path.stem, rows, complete, args.results))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
