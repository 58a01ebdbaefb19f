"""A tune's results and ``report.md`` (:mod:`fppo_jax.analysis.tuning`): per task and arm the chosen
setting and its score, trial 0's (the default's), the tuning curve (the best score at each
rung against the env steps spent), the share of sampled settings that beat the baseline's
default (Jordan et al., "Evaluating the Performance of Reinforcement Learning Algorithms",
ICML 2020), the spread of the first rung's scores over the space (the arm's sensitivity to its
setting: quartiles, sample std and range), the trials that diverged, and Eimer et al.'s
reporting checklist (space, budget, seeds, selection, test) filled in from the plan.
``tuning_curves.png`` draws the curves. What they are read from and written to has its shape
in :mod:`fppo_jax.analysis.tuning_records`.

The band on the tuning curve is the first rung's, where every trial has trained the same
length on a setting drawn from the space: the expected best of n settings drawn from those
scores, against the env steps n first-rung trials cost (Dodge et al., "Show Your Work: Improved
Reporting of Experimental Results", EMNLP 2019), with a percentile bootstrap band that
resamples the trials (:func:`expected_best`). Later rungs hold a few trials that earlier rungs
chose, not draws from the space, so they get no band. A bootstrap band of a maximum from a few
trials is known to cover less often than it claims (Lourie, Cho and He, "Show Your Work with
Confidence: Confidence Bands for Tuning Curves", NAACL 2024), and it never reaches above the
best score seen: read it as too narrow rather than too wide."""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from fppo_jax.analysis.population import Window
from fppo_jax.analysis.tune_files import REPORT_FILE
from fppo_jax.analysis.tuning_records import (
    ArmResults,
    ArmRung,
    Chosen,
    CurvePoint,
    ExpectedBestCurve,
    RungScores,
    Spread,
    TaskBudget,
    TrialAcrossTasks,
    TrialScore,
    TunePlan,
)
from fppo_jax.analysis.validation_race import race_lines
from fppo_jax.core.checks import positive_int
from fppo_jax.errors import InvalidInput
from fppo_jax.stats.statistics import CONFIDENCE, RESAMPLES, check_confidence
from fppo_jax.store.files import write_atomically


def expected_best(
    scores: np.ndarray,
    settings: int,
    *,
    confidence: float = CONFIDENCE,
    resamples: int = RESAMPLES,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The expected best score of n settings drawn from the space, n = 1 … `settings`, from
    the N finite `scores` of settings that were drawn, with its percentile bootstrap band at
    level `confidence`: ``(point, low, high)``, each of length `settings`.

    Sorted, v₍₁₎ ≤ … ≤ v₍N₎, n settings drawn with replacement from the scores have their best
    at or below v₍ᵢ₎ with probability (i/N)ⁿ, so (Dodge et al. 2019, expected validation
    performance with the empirical distribution)

        E[best of n] = Σᵢ v₍ᵢ₎ · ((i/N)ⁿ − ((i − 1)/N)ⁿ),

    the mean of the scores at n = 1 and rising towards the best one seen. Each of `resamples`
    replicates draws N scores from `scores` with replacement and computes the same curve; the
    band at each n is those curves' percentiles at (1 ∓ `confidence`)/2. Seeded: it repeats."""
    scores = np.asarray(scores, dtype=float)
    if not scores.size or not np.isfinite(scores).all():
        raise InvalidInput(f"expected_best needs finite scores, got {scores}")
    confidence = check_confidence(confidence)
    resamples = positive_int("resamples", resamples)
    n = np.arange(1, positive_int("settings", settings) + 1)[:, None]
    i = np.arange(1, scores.size + 1)
    weights = (i / scores.size) ** n - ((i - 1) / scores.size) ** n  # [n, i]
    replicates = np.random.default_rng(seed).choice(scores, (resamples, scores.size))
    curves = np.sort(replicates, axis=-1) @ weights.T  # [replicate, n]
    tail = 100 * (1 - confidence) / 2
    low, high = np.percentile(curves, [tail, 100 - tail], axis=0)
    return weights @ np.sort(scores), low, high


def _score(rows: list[TrialScore], trial: int) -> float | None:
    found = [row for row in rows if row["trial"] == trial]
    return found[0]["score"] if found else None


def arm_results(
    arm: str,
    baseline: str,
    rungs_scores: list[RungScores],
    settings: dict[str, list[dict[str, Any]]],
    windows: Sequence[Window],
    samples_per_update: int,
) -> ArmResults:
    """What ``results.json`` holds of `arm` on one task (see the module), from its rungs'
    scores and what each rung trained (`windows`)."""
    first = rungs_scores[0]["arms"][arm]["trials"]
    finite = np.array([row["score"] for row in first if row["score"] is not None], float)
    base = _score(rungs_scores[0]["arms"][baseline]["trials"], 0)
    sampled = [row for row in first if row["trial"] != 0]
    beat = [
        row
        for row in sampled
        if row["score"] is not None and base is not None and row["score"] > base
    ]
    curve: list[CurvePoint] = []
    reached, score_there, spent = 0, _score(first, 0), 0
    for scores, window in zip(rungs_scores, windows, strict=True):
        rows = scores["arms"][arm]["trials"]
        runs = sum(run[0] == arm for run in window.runs)
        spent += runs * (window.end - window.start) * samples_per_update
        best = max((row["score"] for row in rows if row["score"] is not None), default=None)
        rung = len(curve)
        curve.append({"rung": rung, "env_steps": spent, "best": best, "trials": len(rows)})
        if _score(rows, 0) is not None:
            reached, score_there = rung, _score(rows, 0)
    last = rungs_scores[-1]["arms"][arm]
    chosen: Chosen | None = None
    if last["survivors"]:  # the one left after the last rung: the race's choice, or the search's
        trial = last["survivors"][0]
        chosen = {
            "trial": trial,
            "score": _score(last["trials"], trial),
            "setting": settings[arm][trial],
        }
    diverged = sorted(
        {row["trial"] for s in rungs_scores for row in s["arms"][arm]["trials"] if row["diverged"]}
    )
    found: ArmResults = {
        "chosen": chosen,
        "default": {
            "setting": settings[arm][0],
            "first_rung_score": _score(first, 0),
            "last_rung_reached": reached,
            "score_there": score_there,
        },
        "curve": curve,
        "env_steps": spent,
        "beat_baseline_default": {
            "baseline": baseline,
            "baseline_default_score": base,
            "sampled": len(sampled),
            "beat": len(beat),
        },
        "trials": settings[arm],  # each trial's setting, for a choice across tasks
        "first_rung_spread": _spread(finite),
        "expected_best": _expected_best_curve(finite, len(first), curve[0]["env_steps"]),
        "diverged_trials": diverged,
        "tied_rungs": [r for r, s in enumerate(rungs_scores[:-1]) if _tied(s["arms"][arm])],
    }
    if "race" in last:
        found["race"] = last["race"]
    return found


def across_tasks(rungs: dict[str, list[RungScores]], arm: str) -> TrialAcrossTasks | None:
    """`arm`'s one trial for all the tasks of `rungs` (each task's rungs' scores, as
    ``scores.json`` records them), as Patterson, Neumann, White and White ("Empirical Design in
    Reinforcement Learning", 2024) choose one setting across environments: on scores normalised
    per task, the best mean over the tasks.

    Successive halving scores only its survivors at the later rungs, so the trials compared are
    the arm's that reached, on every task, the deepest rung that any of them reached on every
    task (a trial's deepest rung on a task: the last where it scored and did not diverge); each
    is scored there, per task, by min–max normalisation over every arm's trials scored at that
    rung (0 the worst, 1 the best; a task where they all tie counts 0: it cannot tell them
    apart), and the best mean over the tasks wins, ties by trial number. Returns the trial, the
    rung and its mean normalised score; None if no trial of `arm` scored on every task."""

    def scored(rows: list[TrialScore]) -> dict[int, float]:
        """The trials of `rows` that scored and did not diverge, with their scores."""
        return {
            row["trial"]: row["score"]
            for row in rows
            if row["score"] is not None and not row["diverged"]
        }

    deepest_by_task = [
        {trial: r for r, rung in enumerate(task) for trial in scored(rung["arms"][arm]["trials"])}
        for task in rungs.values()
    ]
    everyone = {trial for deepest in deepest_by_task for trial in deepest}
    shared = {t: min(deepest.get(t, -1) for deepest in deepest_by_task) for t in everyone}
    rung = max(shared.values(), default=-1)
    if rung < 0:
        return None
    means = {}
    for trial in sorted(t for t, r in shared.items() if r == rung):
        normalised = []
        for task in rungs.values():
            every = [
                score for a in task[rung]["arms"].values() for score in scored(a["trials"]).values()
            ]
            low, high = min(every), max(every)
            own = scored(task[rung]["arms"][arm]["trials"])[trial]
            normalised.append((own - low) / (high - low) if high > low else 0.0)
        means[trial] = float(np.mean(normalised))
    best = max(means, key=lambda t: (means[t], -t))
    return {"trial": best, "rung": rung, "normalised_score": means[best]}


def _tied(rung: ArmRung) -> bool:
    """Whether a rung kept some of its trials and scored them all alike, so that the trial
    numbers chose its survivors."""
    scores = {row["score"] for row in rung["trials"] if not row["diverged"]}
    return len(rung["trials"]) > len(rung["survivors"]) and len(scores) == 1


def _spread(x: np.ndarray) -> Spread:
    """The quartiles and the sample std of scores `x` (None for the std of one score)."""
    if not x.size:
        return {
            "min": None,
            "q1": None,
            "median": None,
            "q3": None,
            "max": None,
            "sample_std": None,
        }
    low, q1, median, q3, high = map(float, np.percentile(x, [0, 25, 50, 75, 100]))
    return {
        "min": low,
        "q1": q1,
        "median": median,
        "q3": q3,
        "max": high,
        "sample_std": float(np.std(x, ddof=1)) if x.size > 1 else None,
    }


def _expected_best_curve(x: np.ndarray, trials: int, env_steps: int) -> ExpectedBestCurve | None:
    """:func:`expected_best` of the first rung's finite scores `x` for 1 … `trials` settings,
    each point at the env steps its settings cost on the first rung (`env_steps` for all
    `trials`). Trials without a score (diverged, or no episode) are not among the draws: the
    report counts them apart. None when no trial scored."""
    if not x.size:
        return None
    point, low, high = expected_best(x, trials)
    return {
        "scored_trials": int(x.size),
        "confidence": CONFIDENCE,
        "resamples": RESAMPLES,
        "seed": 0,
        "points": [
            {
                "settings": n + 1,
                "env_steps": env_steps * (n + 1) // trials,
                "expected_best": float(point[n]),
                "low": float(low[n]),
                "high": float(high[n]),
            }
            for n in range(trials)
        ],
    }


def _number(x: float | None) -> str:
    return "—" if x is None or not math.isfinite(x) else f"{x:.1f}"


def write_report(output: Path, plan: TunePlan, results: dict[str, dict[str, ArmResults]]) -> None:
    """``report.md`` and ``tuning_curves.png`` in `output`."""
    lines = [
        "# Tune",
        "",
        f"Variants {', '.join(plan['variants'])} on {', '.join(plan['tasks'])}: {plan['trials']} "
        f"trials each (trial 0 the default), {_search_text(plan)}. "
        f"Score: {plan['score']}. Selection: {plan['selection']}. Code at {plan['commit']}.",
    ]
    for task, arms in results.items():
        lines += [
            "",
            f"## {task}",
            "",
            _budget_text(plan["budget"][task]),
            "",
            "| arm | default, rung 1 | best, rung 1 | chosen trial | chosen score | "
            f"sampled settings above {plan['baseline']}'s default | diverged | env steps |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for arm, found in arms.items():
            chosen, beat = found["chosen"], found["beat_baseline_default"]
            lines.append(
                f"| {arm} | {_number(found['default']['first_rung_score'])} | "
                f"{_number(found['curve'][0]['best'])} | "
                f"{'—' if chosen is None else chosen['trial']} | "
                f"{'—' if chosen is None else _number(chosen['score'])} | "
                f"{beat['beat']} of {beat['sampled']} | {len(found['diverged_trials'])} | "
                f"{found['env_steps']:,} |"
            )
        lines += _first_rung_lines(plan["trials"], arms)
        if "validation" in plan:
            lines += race_lines(arms, len(plan["validation"]["seeds"]))
        tied = [
            f"{arm} at rung {', '.join(str(r + 1) for r in found['tied_rungs'])}"
            for arm, found in arms.items()
            if found["tied_rungs"]
        ]
        if tied:
            lines += [
                "",
                f"Tied: every trial scored alike ({'; '.join(tied)}), so the trials that went "
                "on were the first by number, not the best: a rung that short cannot tell the "
                "settings apart on this task.",
            ]
        lines += ["", "Chosen settings:", ""]
        for arm, found in arms.items():
            chosen = found["chosen"]
            shown = (
                "none (every trial diverged)"
                if chosen is None
                else ", ".join(f"{k} = {_value(v)}" for k, v in chosen["setting"].items())
            )
            lines.append(f"- {arm}: {shown}")
    lines += [
        "",
        "Scores here are on the tuning seeds, which chose the settings: they are biased upward "
        "as estimates of how well the chosen settings train. The test is a study on fresh "
        "seeds (`fppo-jax study --tuned`). A bootstrap band of a best score from a few trials "
        "covers less often than its level says, and never reaches above the best score seen "
        "(Lourie, Cho and He, NAACL 2024): read it as too narrow rather than too wide.",
        "",
        "## Checklist (Eimer, Lindauer and Raileanu, ICML 2023)",
        "",
        f"- Search space: {_space_text(plan)}.",
        f"- Budget: {plan['trials']} trials per arm and task, {_search_text(plan)}; env steps "
        "per arm: "
        + ", ".join(f"{t} {b['env_steps_per_arm']:,}" for t, b in plan["budget"].items())
        + ".",
        f"- Tuning seeds: {_seed_text(plan['seeds'])}.",
        f"- Sampler: {plan['sampler']['name']} ({plan['sampler']['package']}), seed "
        f"{plan['sampler']['seed']}.",
        f"- Selection: {plan['selection']}.",
        "- Test: on seeds disjoint from the tuning seeds (`fppo-jax study --tuned`, which "
        "refuses an overlap).",
    ]
    write_atomically(output / REPORT_FILE, ("\n".join(lines) + "\n").encode())
    _figure(output, results)


def _search_text(plan: TunePlan) -> str:
    """How the plan's search spent its budget, in words."""
    search = plan.get("search", {"name": "halving", "eta": plan.get("eta", 0)})
    seeds = f"({_seed_text(plan['seeds'])})"
    if search["name"] == "racing":
        return (
            f"racing over {len(plan['seeds'])} tuning seeds {seeds}, "
            f"{search.get('seeds_per_round')} a round for the trials still in, a trial dropped "
            f"where shown worse than the incumbent at level {search.get('level')}"
        )
    return (
        f"{len(plan['seeds'])} tuning seeds per trial {seeds}, successive halving with "
        f"η = {search.get('eta')}"
    )


def _budget_text(budget: TaskBudget) -> str:
    """A task's budget per arm, in words."""
    rungs = budget.get("rungs")
    if rungs is None:
        runs = budget.get("full_runs_per_arm", 0)
        return (
            f"Every arm had a budget of {budget['env_steps_per_arm']:,} env steps ({runs:g} full "
            "runs, the validation race's included); racing spends less where trials drop."
        )
    ends = ", ".join(f"{rung['env_steps_per_run']:,}" for rung in rungs)
    trials = " → ".join(str(r["trials"]) for r in rungs)
    return (
        f"Every arm trained {budget['env_steps_per_arm']:,} env steps ({trials} trials over "
        f"rungs ending at {ends} env steps per run"
        + (", then the validation race)." if "full_runs_per_arm" in budget else ").")
    )


def _first_rung_lines(trials: int, arms: dict[str, ArmResults]) -> list[str]:
    """The first rung's table: each arm's sensitivity (the spread of its scores over the
    space) and the expected best of `trials` settings with its band, and which bands are wide."""
    lines = [
        "",
        "The first rung, where every trial trained the same length on a setting drawn from the "
        "space: the spread of its scores is the arm's sensitivity to its setting (sample std; "
        "range, max − min), and the expected best of n settings drawn from them (Dodge et al., "
        "EMNLP 2019) is the tuning curve's start, with a 95% bootstrap band over the trials.",
        "",
        "| arm | scored trials | quartiles | sample std | range | "
        f"expected best of {trials} settings [95% band] |",
        "|---|---|---|---|---|---|",
    ]
    wide = []
    for arm, found in arms.items():
        spread, band = found["first_rung_spread"], found["expected_best"]
        low, high = spread["min"], spread["max"]
        width = None if low is None or high is None else high - low
        shown, scored = "—", 0
        if band is not None:
            first, last = band["points"][0], band["points"][-1]
            shown = f"{_number(last['expected_best'])} [{_number(last['low'])}, "
            shown += f"{_number(last['high'])}]"
            scored = band["scored_trials"]
            # Wide: the band at the full first rung is wider than all the curve rose from one
            # setting to it, so the trials cannot tell how much the search gained. (The rise is
            # never below 0 but for rounding, which must not call a zero-width band wide.)
            rise = last["expected_best"] - first["expected_best"]
            if last["high"] - last["low"] > max(rise, 0.0):
                wide.append(arm)
        lines.append(
            f"| {arm} | {scored} | {_number(spread['q1'])} / {_number(spread['median'])} / "
            f"{_number(spread['q3'])} | {_number(spread['sample_std'])} | {_number(width)} | "
            f"{shown} |"
        )
    if wide:
        lines += [
            "",
            f"Wide bands ({', '.join(wide)}): wider than the whole rise of the expected best "
            f"from one setting to {trials}, so {trials} trials do not tell how much searching "
            "this space gains.",
        ]
    return lines


def _seed_text(seeds: list[int]) -> str:
    if seeds == list(range(seeds[0], seeds[0] + len(seeds))):
        return f"{seeds[0]} … {seeds[-1]}"
    return ", ".join(map(str, seeds))


def _space_text(plan: TunePlan) -> str:
    spaces = plan["space"]
    first = next(iter(spaces.values()))
    own = {
        arm: {k: v for k, v in space.items() if k not in first or v != first[k]}
        for arm, space in spaces.items()
    }
    shared = [k for k in first if all(k in s and s[k] == first[k] for s in spaces.values())]
    parts = [f"{k} [{first[k]['low']:g}, {first[k]['high']:g}] {first[k]['scale']}" for k in shared]
    for arm, axes in own.items():
        for k, v in axes.items():
            if k not in shared:
                parts.append(f"{arm}'s {k} [{v['low']:g}, {v['high']:g}] {v['scale']}")
    for task, shape in plan.get("run_shape", {}).items():
        choices = (f"{k} {{{', '.join(map(str, v['choices']))}}}" for k, v in shape.items())
        parts.append(f"the run shape on {task}: {', '.join(choices)}")
    return "; ".join(parts)


def _value(value: object) -> str:
    """A setting's value as the report shows it (a run shape's as it is)."""
    return f"{value:.4g}" if isinstance(value, float) else str(value)


def _figure(output: Path, results: dict[str, dict[str, ArmResults]]) -> None:
    import matplotlib.pyplot as plt

    from fppo_jax.analysis.plots import plot_tuning_curves

    figure = plot_tuning_curves(results)
    figure.savefig(output / "tuning_curves.png", dpi=90)
    plt.close(figure)
