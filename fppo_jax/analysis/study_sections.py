"""A study's ``report.md``, a task's section (:func:`task_section`): on each endpoint a row per
comparison (its decision, seeds and why it stopped on the primary endpoint, with its repeated
confidence interval), its probability of improvement and IQM difference with bootstrap
intervals and the relative effects the interval rules out; notes where a number could mislead
(a ceiling: many runs at the task's best score; many ties on the primary endpoint; a boundary
that Holm's procedure moved from the plan's); and how soon each setting's runs reach shares of
the baseline's final IQM. With the scores' keys that a study records for it."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from fppo_jax.analysis.report_kit import interval_cell, ruled_out
from fppo_jax.analysis.study_plan import DecisionRow, StudyPlan, rule_of_plan
from fppo_jax.stats import statistics
from fppo_jax.stats.sequential import Design, repeated_confidence
from fppo_jax.stats.spending import boundaries

# A task's scores: variant → endpoint (or steps_name(share)) → one per run, in seed order.
Scores = dict[str, dict[str, np.ndarray]]
# Shares of the baseline's final IQM whose env steps to reach are reported (lower is faster).
SHARES = (0.5, 0.8)
# The share of a setting's runs at the best score recorded on a task from which the report
# notes a ceiling (:func:`_ceiling`).
CEILING_SHARE = 0.25
# The share of a comparison's pairs of runs tied on the primary endpoint from which the report
# notes its ties (:func:`_ties`).
TIE_SHARE = 0.05
# The key in :data:`Scores` of each run's first recorded average return (the untrained policy's).
START = "start"


def steps_name(share: float) -> str:
    """The key of the env steps to `share` of the baseline's final IQM in :data:`Scores`."""
    return f"steps to {share:.0%}"


def task_section(
    scores: Scores, task: str, rows: Sequence[DecisionRow], plan: StudyPlan
) -> list[str]:
    """The lines of `task`'s section of ``report.md``, below its heading, from its `scores`
    so far and every comparison's row of ``decisions.json`` (`rows`, every task's: a boundary
    Holm's procedure moved is found among them)."""
    lines: list[str] = []
    task_rows = [row for row in rows if row["task"] == task]
    for endpoint in (plan["primary_endpoint"], *plan["secondary_endpoints"], "max"):
        adjusted = plan if endpoint == plan["primary_endpoint"] else None
        lines += ["", *_table(scores, task_rows, endpoint, adjusted)]
        lines += _ceiling(scores, plan, endpoint)
        if adjusted is not None:
            lines += _ties(scores, task_rows, endpoint)
            lines += _moved_boundaries(task_rows, rows, plan)
    lines += ["", *_speed_table(scores, plan)]
    return lines


def _table(
    scores: Scores, rows: Sequence[DecisionRow], endpoint: str, plan: StudyPlan | None
) -> list[str]:
    """A row per comparison on `endpoint`; the primary one's (given its `plan`) with the
    decision and the repeated confidence interval."""
    baseline = rows[0]["baseline"]
    if plan is not None:
        head = f"Primary endpoint, {endpoint}: tested; the decision column is the test's."
        columns = ["candidate", "decision", "seeds", "why it stopped"]
        columns.append(f"P(candidate > {baseline}), repeated CI")
        design = rule_of_plan(plan).design
    elif endpoint == "max":
        head = (
            "Each run's best, max: reported, not tested, and biased upward (the best of a "
            "noisy curve); the paper's statistic is its like over the seed-mean curve."
        )
        columns = ["candidate", "seeds"]
    else:
        head = f"Secondary endpoint, {endpoint}: reported, not tested."
        columns = ["candidate", "seeds"]
    columns += [
        f"P(candidate > {baseline})",
        "IQM difference",
        f"IQM of {baseline}",
        "what the interval rules out",
    ]
    lines = [head, "", "| " + " | ".join(columns) + " |", "|---" * len(columns) + "|"]
    for row in rows:
        seeds = row["seeds"]
        candidate = scores[row["candidate"]][endpoint][:seeds]
        reference = scores[baseline][endpoint][:seeds]
        compared = statistics.compare(candidate, reference)
        level = statistics.interval(reference)
        probability, difference = compared["probability_of_improvement"], compared["iqm_difference"]
        cells = [row["candidate"]]
        if plan is not None:
            cells += [row["decision"], str(seeds), row["reason"]]
            cells.append(_repeated_interval(candidate, reference, design, plan, seeds))
        else:
            cells += [str(seeds)]
        cells += [
            interval_cell(probability, ".2f"),
            interval_cell(difference, ".1f"),
            interval_cell(level, ".1f"),
            ruled_out(difference, level[0]),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def _repeated_interval(
    candidate: np.ndarray,
    reference: np.ndarray,
    design: Design,
    plan: StudyPlan,
    seeds: int,
) -> str:
    """The probability of improvement with its repeated confidence interval at the look of
    `seeds` seeds; "–" between looks, or at a look that spends no error."""
    if seeds not in design.looks:
        return "–"
    confidence = repeated_confidence(design, len(plan["comparisons"]), seeds)
    if confidence >= 1:
        return "–"
    repeated = statistics.compare(candidate, reference, confidence=confidence)
    return interval_cell(repeated["probability_of_improvement"], ".2f")


def _ceiling(scores: Scores, plan: StudyPlan, endpoint: str) -> list[str]:
    """A note where a large share (:data:`CEILING_SHARE`) of some setting's recorded runs on
    the task sit at the best score any run recorded on `endpoint`: a task's maximum return
    (CartPole's cap), where runs tie and a gain cannot show, so that what an interval rules out
    above it is not read as informative. Nothing otherwise."""
    variants = (*plan["candidates"], plan["baseline"])
    every = np.concatenate([scores[v][endpoint] for v in variants if v in scores])
    finite = every[np.isfinite(every)]
    if not finite.size:
        return []
    top = float(finite.max())
    at_top = {
        v: (int(np.sum(scores[v][endpoint] == top)), scores[v][endpoint].size)
        for v in variants
        if v in scores and scores[v][endpoint].size
    }
    if not any(count >= CEILING_SHARE * runs for count, runs in at_top.values()):
        return []
    shares = _listed(
        [
            f"{count} of {runs} runs of {v} ({count / runs:.0%})"
            for v, (count, runs) in at_top.items()
            if count
        ]
    )
    if float(finite.min()) == top:
        return [
            "",
            f"Every run scored {top:.6g} on {endpoint}: the settings do not differ at all there "
            "(a floor or a cap of the task's return), and nothing about them can be read from "
            "this endpoint.",
        ]
    return [
        "",
        f"Ceiling on {endpoint}: {shares} sit at {top:.6g}, the best any run recorded on this "
        "task, tied there: most likely the task's maximum (a cap on the return), which no gain "
        "can pass. Where many runs of both settings reach it, the interval's narrow range says "
        "that the runs tie at the cap, not that a gain is ruled out: what it 'rules out' above "
        "the cap is no evidence of how the settings would differ on a harder task.",
    ]


def _ties(scores: Scores, rows: Sequence[DecisionRow], endpoint: str) -> list[str]:
    """A note of the comparisons with many ties on `endpoint` over the runs each decision used
    (at least :data:`TIE_SHARE` of the (candidate run, baseline run) pairs with the same score),
    each tie counted ½ in the probability of improvement and the test. Nothing otherwise."""
    said = []
    for row in rows:
        seeds = row["seeds"]
        candidate = scores[row["candidate"]][endpoint][:seeds]
        reference = scores[row["baseline"]][endpoint][:seeds]
        tied = int(np.sum(candidate[:, None] == reference[None, :]))
        pairs = candidate.size * reference.size
        if pairs and tied >= TIE_SHARE * pairs:
            said.append(f"{row['candidate']}, {tied} of {pairs} pairs ({tied / pairs:.0%})")
    if not said:
        return []
    return [
        "",
        f"Ties on {endpoint}, the primary endpoint, among the pairs of runs (candidate, "
        f"{rows[0]['baseline']}) each decision used: {'; '.join(said)}. A tie counts ½ in "
        "P(candidate > baseline) and in the test: tied runs pull P towards ½ and lower the "
        "largest |z| the test can reach, so they make a decision harder, and a P near ½ "
        "partly a count of ties.",
    ]


def _moved_boundaries(
    task_rows: Sequence[DecisionRow], rows: Sequence[DecisionRow], plan: StudyPlan
) -> list[str]:
    """Where a comparison's boundary (in its reason) is not plan.json's
    ``boundaries_if_none_decided``: Holm's procedure tested it at a larger level once others
    in the family (`rows`, every task's) were decided ``better`` or ``worse``, their share of α
    passed on. The level and look are found by matching the boundary with those of α/(m − j),
    j comparisons decided; a boundary that none matches, or the plan's own, is not noted."""
    planned = plan.get("boundaries_if_none_decided")
    if not planned:
        return []
    fractions = tuple(n / plan["max_seeds"] for n in plan["looks"])
    comparisons, alpha = len(plan["comparisons"]), plan["level"]
    said = []
    for row in task_rows:
        boundary = row.get("boundary")
        if boundary is None or row["decision"] == "equivalent":
            continue
        found = [
            (done, look)
            for done in range(comparisons)
            for look, critical in enumerate(boundaries(alpha / (comparisons - done), fractions))
            if np.isclose(critical, boundary, rtol=0, atol=1e-9)
        ]
        if not found or found[0][0] == 0:
            continue
        done, look = found[0]
        others = [
            f"{other['candidate']} on {other['task']}, {other['decision']}"
            for other in rows
            if other is not row and other["decision"] in ("better", "worse")
        ]
        level = alpha / (comparisons - done)
        said.append(
            f"{row['candidate']}'s boundary, ±{boundary:.2f} at look {look + 1} "
            f"({plan['looks'][look]} seeds), is not plan.json's ±{planned[look]:.2f} "
            f"(boundaries_if_none_decided, level {alpha / comparisons:.3g} = α/{comparisons}): "
            f"Holm's procedure passed on the share of α of {done} comparison"
            f"{'s' if done > 1 else ''} decided better or worse (decided: "
            f"{'; '.join(others)}), so it was tested at level {level:.3g} = "
            f"α/{comparisons - done}, whose boundary is lower."
        )
    if not said:
        return []
    return ["", "Boundaries moved by Holm's procedure: " + " ".join(said)]


def _speed_table(scores: Scores, plan: StudyPlan) -> list[str]:
    """Env steps until a run's curve first reaches 50% and 80% of the baseline's final IQM,
    per setting over all its recorded runs: how many did, and the median (reported, not
    tested)."""
    baseline = plan["baseline"]
    if steps_name(SHARES[0]) not in scores[baseline]:
        return [f"Speed: not reported, {baseline}'s final IQM is not positive."]
    final = scores[baseline]["final"]
    target = float(statistics.iqm(final[np.isfinite(final)]))
    shares = " and ".join(f"{share:.0%} ({share * target:.1f})" for share in SHARES)
    lines = [
        f"Speed, reported, not tested: env steps until a run's average return first reaches "
        f"{shares} of {baseline}'s final IQM, over every recorded run of each setting. The "
        "median counts a run that never reaches it as slower than every run that does, so it "
        "is 'not reached' once half of them never do (the median over only the runs that "
        "reach it would be earlier).",
        "",
        "| setting | runs | "
        + " | ".join(f"reached {s:.0%} | median steps" for s in SHARES)
        + " |",
        "|---|---|" + "---|---|" * len(SHARES),
    ]
    for variant in (*plan["candidates"], baseline):
        cells = [variant, str(len(scores[variant]["final"]))]
        for share in SHARES:
            steps = scores[variant][steps_name(share)]
            median = np.median(steps)
            cells += [
                f"{int(np.isfinite(steps).sum())}",
                f"{median:,.0f}" if np.isfinite(median) else "not reached",
            ]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def _listed(items: Sequence[str]) -> str:
    """`items` in words: "a", "a and b", "a, b and c"."""
    return items[0] if len(items) == 1 else f"{', '.join(items[:-1])} and {items[-1]}"
