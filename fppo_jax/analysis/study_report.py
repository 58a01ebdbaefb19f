"""A study's ``report.md`` (:mod:`fppo_jax.analysis.studies`): its plan, status and intervals in
words; per task each comparison's decision, the seeds it used and why it stopped, its
probability of improvement and IQM difference with bootstrap intervals
(:mod:`fppo_jax.stats.statistics`), the relative effects the interval rules out and notes where
a number could mislead (:mod:`fppo_jax.analysis.study_sections`), and, where a study trained
each arm's default beside its tuned setting, what they measure (:func:`beside_defaults`).
Across the tasks (two or more): the probability of improvement averaged over them on each
endpoint and the IQM of normalised scores, with stratified intervals. Its figures beside it are
:mod:`fppo_jax.analysis.study_figures`'."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from fppo_jax.analysis.report_kit import interval_cell
from fppo_jax.analysis.study_plan import (
    BesideDefaults,
    Compared,
    DecisionRow,
    DefaultsCompared,
    Interval,
    StudyPlan,
    TuningGain,
    rule_of_plan,
)
from fppo_jax.analysis.study_sections import START, Scores, task_section
from fppo_jax.stats import statistics
from fppo_jax.store.files import write_atomically


def write_report(
    path: Path,
    plan: StudyPlan,
    rows: Sequence[DecisionRow],
    scores: dict[str, Scores],
    finished: bool,
    beside: BesideDefaults | None = None,
) -> None:
    """``report.md`` at `path`: the plan in a paragraph, then a section per task, from each
    comparison's row of ``decisions.json`` and each task's `scores` so far, and what each arm's
    default measured `beside` them (:func:`beside_defaults`), where the study trained them."""
    lines = _preamble(plan, len(rows), finished)
    for task in plan["tasks"]:
        lines += ["", f"## {task}"]
        if task not in scores:
            lines += ["", "No group recorded yet."]
            continue
        lines += task_section(scores[task], task, rows, plan)
        if beside is not None:
            task_rows = [row for row in rows if row["task"] == task]
            lines += _defaults_tables(task, beside, task_rows)
    lines += _across_tasks(plan, rows, scores)
    write_atomically(path, ("\n".join(lines) + "\n").encode())


def beside_defaults(
    plan: StudyPlan, scores: dict[str, Scores], defaults: dict[str, dict[str, np.ndarray]]
) -> BesideDefaults:
    """What each arm's default setting (a tune's trial 0), trained beside its tuned one on the
    same seeds, measures on the primary endpoint, untested: per task, each arm's tuned setting
    against its default (the gain from tuning, on the test seeds) and each candidate's default
    against the baseline's; each over the seeds both settings ran (the first ones), with the
    probability of improvement and the IQM difference and their bootstrap intervals, as the
    report gives the decided comparisons'. `defaults`: each task's default runs' scores on the
    primary endpoint, by variant, in seed order."""
    endpoint, baseline = plan["primary_endpoint"], plan["baseline"]
    gains: list[TuningGain] = []
    compared: list[DefaultsCompared] = []
    for task in plan["tasks"]:
        if task not in defaults or task not in scores:
            continue
        for arm in (*plan["candidates"], baseline):
            pair = scores[task][arm][endpoint], defaults[task][arm]
            gains.append({"task": task, "arm": arm, **_compared(*pair)})
        for candidate in plan["candidates"]:
            pair = defaults[task][candidate], defaults[task][baseline]
            compared.append(
                {"task": task, "candidate": candidate, "baseline": baseline, **_compared(*pair)}
            )
    return {
        "endpoint": endpoint,
        "tested": False,
        "tuned_against_default": gains,
        "default_against_default": compared,
    }


def _compared(x: np.ndarray, y: np.ndarray) -> Compared:
    """`x`'s runs against `y`'s over the first seeds both ran: their count, P(x > y) and the IQM
    difference, each ``[point, low, high]`` (None where no run of a side has a score)."""
    seeds = min(len(x), len(y))
    found = statistics.compare(x[:seeds], y[:seeds])
    return {
        "seeds": seeds,
        "probability_of_improvement": _recorded(found["probability_of_improvement"]),
        "iqm_difference": _recorded(found["iqm_difference"]),
    }


def _recorded(values: tuple[float, float, float]) -> Interval:
    """An interval as ``decisions.json`` records it: a list, None for each NaN."""
    return [None if np.isnan(v) else v for v in values]


def _defaults_tables(
    task: str, beside: BesideDefaults, task_rows: Sequence[DecisionRow]
) -> list[str]:
    """The task's tables of :func:`beside_defaults`: each arm's tuned setting against its
    default, and each candidate's default against the baseline's beside the decision."""
    gains = [row for row in beside["tuned_against_default"] if row["task"] == task]
    if not gains:
        return []
    baseline, endpoint = task_rows[0]["baseline"], beside["endpoint"]
    decided = {row["candidate"]: row["decision"] for row in task_rows}
    lines = [
        "",
        f"Beside the decisions, each arm's default setting (the tune's trial 0), trained on the "
        f"same seeds at the same looks: reported, not tested, outside the family whose error "
        f"the test controls. On {endpoint}, over the first seeds both settings ran, with "
        f"{statistics.CONFIDENCE:.0%} bootstrap intervals unadjusted for stopping early or for "
        "the number of comparisons. What tuning gained on the test seeds:",
        "",
        "| arm | seeds | P(tuned > default) | IQM difference, tuned − default |",
        "|---|---|---|---|",
    ]
    for gain in gains:
        cells = [gain["arm"], str(gain["seeds"])]
        cells += [_cell(gain["probability_of_improvement"], ".2f")]
        cells += [_cell(gain["iqm_difference"], ".1f")]
        lines.append("| " + " | ".join(cells) + " |")
    lines += [
        "",
        f"Each candidate's default against {baseline}'s default, beside the decision between "
        "their tuned settings:",
        "",
        f"| candidate | decision, both tuned | seeds | P(default > {baseline}'s default) | "
        "IQM difference of the defaults |",
        "|---|---|---|---|---|",
    ]
    for row in beside["default_against_default"]:
        if row["task"] == task:
            cells = [row["candidate"], decided[row["candidate"]], str(row["seeds"])]
            cells += [_cell(row["probability_of_improvement"], ".2f")]
            cells += [_cell(row["iqm_difference"], ".1f")]
            lines.append("| " + " | ".join(cells) + " |")
    return lines


def normalised_scores(plan: StudyPlan, scores: dict[str, Scores]) -> dict[str, list[np.ndarray]]:
    """Each setting's primary-endpoint scores per task on a common scale: 0 is where the task's
    runs start (the mean over all of them of their first recorded average return), 1 the
    baseline's IQM on the task. Empty unless every task with runs can be put on it: finite ends,
    the baseline's IQM above the start (below it, the scale would turn the order round)."""
    endpoint, baseline = plan["primary_endpoint"], plan["baseline"]
    variants = (*plan["candidates"], baseline)
    normalised: dict[str, list[np.ndarray]] = {v: [] for v in variants}
    for task in scores.values():
        starts = np.concatenate([task[v][START] for v in variants])
        low = float(np.nanmean(starts)) if np.isfinite(starts).any() else np.nan
        reference = task[baseline][endpoint]
        high = float(statistics.iqm(reference[np.isfinite(reference)]))
        if not (np.isfinite(low) and np.isfinite(high) and high > low):
            return {}
        for variant in variants:
            normalised[variant].append(statistics.normalise(task[variant][endpoint], low, high))
    return normalised


def _mean_improvement(
    variant: str, baseline: str, on: str, rows: Sequence[DecisionRow], scores: dict[str, Scores]
) -> str:
    """`variant`'s probability of improvement over `baseline` on endpoint `on`, averaged over
    the tasks where a decision compared the two, each over the runs that decision used ("–"
    where none did)."""
    pairs = [
        (
            scores[row["task"]][variant][on][: row["seeds"]],
            scores[row["task"]][baseline][on][: row["seeds"]],
        )
        for row in rows
        if row["candidate"] == variant and row["task"] in scores
    ]
    return interval_cell(statistics.aggregate_improvement(pairs), ".2f") if pairs else "–"


def _across_tasks(
    plan: StudyPlan, rows: Sequence[DecisionRow], scores: dict[str, Scores]
) -> list[str]:
    """Across the tasks with runs (two or more): each candidate's probability of improvement
    averaged over tasks, on each endpoint over the runs its decisions used, and each setting's
    IQM of normalised primary scores over every recorded run, with stratified bootstrap
    intervals."""
    if len(scores) < 2:
        return []
    endpoint, baseline = plan["primary_endpoint"], plan["baseline"]
    endpoints = (endpoint, *plan["secondary_endpoints"])
    normalised = normalised_scores(plan, scores)
    lines = [
        "",
        f"## Across the {len(scores)} tasks",
        "",
        "Reported, not tested (the decisions are per task): the probability of improvement "
        "averaged over the tasks, on each endpoint over the runs each decision used; and, on "
        f"the primary endpoint, {endpoint}, the IQM of normalised scores over every recorded "
        "run, where 0 is where a task's runs start (their mean first average return) and 1 is "
        f"{baseline}'s IQM on it. Intervals are stratified bootstraps: each task's runs "
        "resampled among themselves.",
        "",
        "| setting | "
        + " | ".join(f"mean P(setting > {baseline}) over tasks, {e}" for e in endpoints)
        + f" | IQM of normalised {endpoint} |",
        "|---" * (len(endpoints) + 2) + "|",
    ]
    for variant in (*plan["candidates"], baseline):
        cells = [_mean_improvement(variant, baseline, on, rows, scores) for on in endpoints]
        level = (
            interval_cell(statistics.aggregate(normalised[variant]), ".3f") if normalised else "–"
        )
        lines.append("| " + " | ".join([variant, *cells, level]) + " |")
    if not normalised:
        lines += [
            "",
            "Normalised scores: not reported, some task's baseline IQM is not above where its "
            "runs start.",
        ]
    return lines


def _preamble(plan: StudyPlan, comparisons: int, finished: bool) -> list[str]:
    """The report's title and its plan, status and intervals in words."""
    looks, rule = ", ".join(map(str, plan["looks"])), rule_of_plan(plan)
    status = (
        "Every comparison is decided or reached the maximum of seeds."
        if finished
        else "**Not finished**: some comparisons await seeds; the same command again goes on."
    )
    reused = (
        f" Runs recorded under {', '.join(plan['reuse'])} were taken instead of trained where "
        "they ran the same task, protocol and setting at a group's seeds (decisions.json names "
        "each group's and its source); they are not concurrent with runs trained here (another "
        "compiled program, another time), and the code that trained them is theirs, which the "
        "regression pins say matches this one or not. Those runs were recorded before the plan "
        "was written, so for them the plan is no preregistration: its test is one chosen after "
        "their scores could be seen."
        if plan.get("reuse")
        else ""
    )
    tuned = plan.get("tuned")
    if tuned:
        trials = tuned.get("trials")
        chosen = "the setting a tune chose for it on each task"
        if trials is not None:
            picked = ", ".join(f"{found['trial']} of {arm}" for arm, found in trials.items())
            chosen = (
                "one trial of a tune for every task, chosen across the tune's tasks on "
                f"normalised scores (trial {picked}; plan.json states the rule)"
            )
        reused += (
            f" Each arm trained at {chosen} (the tune in "
            f"{tuned['directory']}, plan digest {tuned['plan_digest'][:12]}, tuning seeds "
            f"{tuned['tuning_seeds'][0]} … {tuned['tuning_seeds'][-1]}, none of them tested "
            "here); plan.json lists the settings."
        )
    if plan.get("with_defaults"):
        reused += (
            " Beside each arm's tuned setting its default (the tune's trial 0) trained on the "
            "same seeds at the same looks (defaults/): what tuning gained on these seeds, and "
            "the defaults compared, are given under each task and in decisions.json "
            "(beside_defaults), untested."
        )
    planned = "before any run it trained" if plan.get("reuse") else "before any run"
    equivalence = (
        f" Equivalence margin {plan['margin']:g}: `equivalent` means P(candidate > "
        f"{plan['baseline']}) shown within 1/2 ± {plan['margin']:g}: its repeated confidence "
        "interval at the test's level, 1 − 2α/m while none is decided (in the reason: a normal "
        "interval, narrower than the table's bootstrap one at 1 − α/m), inside that range "
        f"(test: {rule.equivalence_words}); the "
        "chance of any false `equivalent` (a comparison whose P is at or beyond the margin) in "
        f"the family is at most {plan['level']:g}, as is that of any false `better` or `worse` "
        "where the settings score alike."
        if "margin" in plan
        else ""
    )
    return [
        f"# {', '.join(plan['candidates'])} against {plan['baseline']}",
        "",
        f"Planned in plan.json {planned} (commit {plan['commit']}). Primary endpoint: "
        f"{plan['primary_endpoint']} ({statistics.ENDPOINTS[plan['primary_endpoint']]}); "
        f"reported beside it: {', '.join([*plan['secondary_endpoints'], 'max'])}. Test: "
        f"{rule.words}; family-wise error at most {plan['level']:g} over the {comparisons} "
        f"comparison{'s' if comparisons > 1 else ''}. Seeds per setting at the looks: "
        f"{looks}.{equivalence}{reused}",
        "",
        status,
        "",
        f"Intervals are {statistics.CONFIDENCE:.0%} percentile bootstrap intervals over the runs "
        "a decision used (the first seeds, the same for both settings). They describe those "
        "runs: unlike the decision, they are not adjusted for stopping early or for the number "
        "of comparisons. The primary endpoint's probability of improvement is also given with "
        "its repeated confidence interval (Jennison and Turnbull), a percentile bootstrap at "
        "the level the look's boundary sets, 2Φ(c) − 1 for the boundary c of level α over the "
        "number of comparisons: together these hold every comparison's true value at every "
        f"look with probability at least {1 - plan['level']:.0%}, so they are adjusted for "
        "stopping early and for the comparisons made (and, being Bonferroni's, may hold ½ "
        "where Holm's procedure decided). A run that diverged or finished no episode ranks "
        "below every other in the test and is left out of the intervals.",
    ]


def _cell(values: Sequence[float | None], form: str) -> str:
    """An interval as ``decisions.json`` records it, ``[point, low, high]`` or Nones, in words."""
    point, low, high = (np.nan if v is None else v for v in values)
    return interval_cell((point, low, high), form)
