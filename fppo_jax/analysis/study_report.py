"""A study's ``report.md`` (:mod:`fppo_jax.analysis.studies`): per task each comparison's decision,
the seeds it used and why it stopped, its probability of improvement and IQM difference with
bootstrap intervals (:mod:`fppo_jax.stats.statistics`), and the relative effects the interval
rules out, on the primary endpoint (with its repeated confidence interval, adjusted for stopping
early) and then on the secondary ones, with notes where a number could mislead (a ceiling:
many runs at the task's best score; many ties on the primary endpoint; a boundary that Holm's
procedure moved from the plan's); and how soon each setting's runs reach shares of the
baseline's final IQM. Across the tasks (two or more): the probability of improvement averaged
over them on each endpoint and the IQM of normalised scores, with stratified intervals. Its
figures beside it: learning curves, probabilities of improvement and, across tasks, performance
profiles."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from fppo_jax.run.results import SweepResult
from fppo_jax.stats import statistics
from fppo_jax.stats.sequential import Design, boundaries, repeated_confidence
from fppo_jax.store.files import write_atomically

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


def write_report(
    path: Path,
    plan: dict[str, Any],
    rows: Sequence[dict[str, Any]],
    scores: dict[str, Scores],
    finished: bool,
    beside: dict[str, Any] | None = None,
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
        task_rows = [row for row in rows if row["task"] == task]
        for endpoint in (plan["primary_endpoint"], *plan["secondary_endpoints"], "max"):
            adjusted = plan if endpoint == plan["primary_endpoint"] else None
            lines += ["", *_table(scores[task], task_rows, endpoint, adjusted)]
            lines += _ceiling(scores[task], plan, endpoint)
            if adjusted is not None:
                lines += _ties(scores[task], task_rows, endpoint)
                lines += _moved_boundaries(task_rows, rows, plan)
        lines += ["", *_speed_table(scores[task], plan)]
        if beside is not None:
            lines += _defaults_tables(task, beside, task_rows)
    lines += _across_tasks(plan, rows, scores)
    write_atomically(path, ("\n".join(lines) + "\n").encode())


def beside_defaults(
    plan: dict[str, Any], scores: dict[str, Scores], defaults: dict[str, dict[str, np.ndarray]]
) -> dict[str, Any]:
    """What each arm's default setting (a tune's trial 0), trained beside its tuned one on the
    same seeds, measures on the primary endpoint, untested: per task, each arm's tuned setting
    against its default (the gain from tuning, on the test seeds) and each candidate's default
    against the baseline's; each over the seeds both settings ran (the first ones), with the
    probability of improvement and the IQM difference and their bootstrap intervals, as the
    report gives the decided comparisons'. `defaults`: each task's default runs' scores on the
    primary endpoint, by variant, in seed order."""
    endpoint, baseline = plan["primary_endpoint"], plan["baseline"]
    gains, compared = [], []
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


def _compared(x: np.ndarray, y: np.ndarray) -> dict[str, Any]:
    """`x`'s runs against `y`'s over the first seeds both ran: their count, P(x > y) and the IQM
    difference, each ``[point, low, high]`` (None where no run of a side has a score)."""
    seeds = min(len(x), len(y))
    found = statistics.compare(x[:seeds], y[:seeds])
    return {
        "seeds": seeds,
        **{name: [None if np.isnan(v) else v for v in values] for name, values in found.items()},
    }


def _defaults_tables(
    task: str, beside: dict[str, Any], task_rows: Sequence[dict[str, Any]]
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
    for row in gains:
        cells = [row["arm"], str(row["seeds"])]
        cells += [_cell(row["probability_of_improvement"], ".2f")]
        cells += [_cell(row["iqm_difference"], ".1f")]
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


def normalised_scores(
    plan: dict[str, Any], scores: dict[str, Scores]
) -> dict[str, list[np.ndarray]]:
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
    variant: str, baseline: str, on: str, rows: Sequence[dict[str, Any]], scores: dict[str, Scores]
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
    return _interval(statistics.aggregate_improvement(pairs), ".2f") if pairs else "–"


def _across_tasks(
    plan: dict[str, Any], rows: Sequence[dict[str, Any]], scores: dict[str, Scores]
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
        level = _interval(statistics.aggregate(normalised[variant]), ".3f") if normalised else "–"
        lines.append("| " + " | ".join([variant, *cells, level]) + " |")
    if not normalised:
        lines += [
            "",
            "Normalised scores: not reported, some task's baseline IQM is not above where its "
            "runs start.",
        ]
    return lines


def _preamble(plan: dict[str, Any], comparisons: int, finished: bool) -> list[str]:
    """The report's title and its plan, status and intervals in words."""
    looks = ", ".join(map(str, plan["looks"]))
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
        f"(test: {plan['equivalence_test']}); the "
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
        f"{plan['test']}; family-wise error at most {plan['level']:g} over the {comparisons} "
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


def profile_label(endpoint: str, baseline: str) -> str:
    """The x-axis label of ``profiles.png``: in words, with no symbol (τ) that a user's
    hyperparameter of that name (``tau``) could be taken for."""
    return f"threshold on the normalised {endpoint} (1 = {baseline}'s IQM on the task)"


def write_figures(
    output: Path,
    plan: dict[str, Any],
    rows: Sequence[dict[str, Any]],
    results: dict[str, SweepResult],
    scores: dict[str, Scores],
) -> list[Path]:
    """In `output`: ``curves.png``, each task's learning curves (IQM over each setting's runs
    with a 95% bootstrap band), and ``improvement.png``, each comparison's probability of
    improvement on the primary endpoint over the runs its decision used, with the report's
    unadjusted 95% interval. Returns the paths written."""
    import matplotlib.pyplot as plt  # on first use: a study that writes no figure never waits

    from fppo_jax.analysis.plots import plot_curves, plot_improvement, plot_profiles

    tasks = [task for task in plan["tasks"] if task in results]
    if not tasks:
        return []
    figure, axes = plt.subplots(
        1, len(tasks), figsize=(6 * len(tasks), 4), squeeze=False, layout="constrained"
    )
    for ax, task in zip(axes[0], tasks, strict=True):
        plot_curves(results[task], band="iqm", ax=ax)
    endpoint, improvements = plan["primary_endpoint"], {}
    for row in rows:
        if row["task"] in scores:
            seeds, task = row["seeds"], scores[row["task"]]
            candidate, reference = task[row["candidate"]][endpoint], task[row["baseline"]][endpoint]
            compared = statistics.compare(candidate[:seeds], reference[:seeds])
            name = f"{row['candidate']}, {row['task']} ({seeds} seeds)"
            improvements[name] = compared["probability_of_improvement"]
    charts = {
        "curves.png": figure,
        "improvement.png": plot_improvement(improvements, plan["baseline"]),
    }
    normalised = normalised_scores(plan, scores) if len(scores) > 1 else {}
    if normalised:
        charts["profiles.png"] = plot_profiles(
            {v: np.concatenate(x) for v, x in normalised.items()},
            xlabel=profile_label(endpoint, plan["baseline"]),
        )
    paths = []
    for name, chart in charts.items():
        paths.append(output / name)
        chart.savefig(paths[-1], dpi=90)
        plt.close(chart)
    return paths


def _table(
    scores: Scores, rows: Sequence[dict[str, Any]], endpoint: str, plan: dict[str, Any] | None
) -> list[str]:
    """A row per comparison on `endpoint`; the primary one's (given its `plan`) with the
    decision and the repeated confidence interval."""
    baseline = rows[0]["baseline"]
    if plan is not None:
        head = f"Primary endpoint, {endpoint}: tested; the decision column is the test's."
        columns = ["candidate", "decision", "seeds", "why it stopped"]
        columns.append(f"P(candidate > {baseline}), repeated CI")
        design = Design(plan["group_size"], plan["max_seeds"], plan["level"], plan.get("margin"))
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
            _interval(probability, ".2f"),
            _interval(difference, ".1f"),
            _interval(level, ".1f"),
            ruled_out(difference, level[0]),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def _repeated_interval(
    candidate: np.ndarray,
    reference: np.ndarray,
    design: Design,
    plan: dict[str, Any],
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
    return _interval(repeated["probability_of_improvement"], ".2f")


def _ceiling(scores: Scores, plan: dict[str, Any], endpoint: str) -> list[str]:
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


def _ties(scores: Scores, rows: Sequence[dict[str, Any]], endpoint: str) -> list[str]:
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
    task_rows: Sequence[dict[str, Any]], rows: Sequence[dict[str, Any]], plan: dict[str, Any]
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


def _speed_table(scores: Scores, plan: dict[str, Any]) -> list[str]:
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


def _cell(values: Sequence[float | None], form: str) -> str:
    """An interval as ``decisions.json`` records it, ``[point, low, high]`` or Nones, in words."""
    point, low, high = (np.nan if v is None else v for v in values)
    return _interval((point, low, high), form)


def _interval(values: tuple[float, float, float], form: str) -> str:
    point, low, high = values
    return "–" if np.isnan(point) else f"{point:{form}} [{low:{form}}, {high:{form}}]"


def ruled_out(difference: tuple[float, float, float], baseline_iqm: float) -> str:
    """The relative effects an IQM difference's interval excludes, as a share of the
    baseline's IQM: "a gain above 12% and a loss above 30% of the baseline's IQM"."""
    _, low, high = difference
    if not (np.isfinite(low) and np.isfinite(high)):
        return "–"
    if not np.isfinite(baseline_iqm) or baseline_iqm == 0:
        return f"a gain above {max(high, 0):.1f} and a loss above {max(-low, 0):.1f}"
    scale = abs(baseline_iqm)
    gain = "any gain" if high <= 0 else f"a gain above {high / scale:.0%}"
    loss = "any loss" if low >= 0 else f"a loss above {-low / scale:.0%}"
    return f"{gain} and {loss} of the baseline's IQM"
