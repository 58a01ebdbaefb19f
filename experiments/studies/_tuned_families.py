"""The tuned plan's families (experiments/plans/tuned.json's ``study.family``) decided as the
plan names them, for ``tuned_verdict.py``: each family's comparisons gathered from the recorded
studies that ran its tasks, and the library's sequential rule
(:func:`fppo_jax.stats.sequential.decide`) replayed over the family as one, look by look, on
the runs those studies recorded. A comparison has only the seeds its study ran, so one that its
study stopped at a look gets no later look in the family. Each study's comparisons are decided
alone beside it, and must give the study's recorded decisions (else the replay is refused: it
would not be the rule the studies ran). Nothing is trained.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import sys
from pathlib import Path

import fppo_jax
from fppo_jax import MissingFile, StudyResult
from fppo_jax.analysis.study_runs import run_scores
from fppo_jax.stats.sequential import Decision, Design, decide

# A decision reached, in the plan's words; "undecided" is the last look's, None awaits seeds.
DECIDED = ("better", "worse", "equivalent")
FAMILY_NAMES = {"classic": "classic", "mujoco": "MuJoCo"}
STANDINGS = ("stands", "not reached", "awaits seeds", "differs")  # :func:`standing`'s answers


def called(name: str) -> str:
    """A family of the plan, as a sentence names it: "the plan's MuJoCo family"."""
    return f"the plan's {FAMILY_NAMES.get(name, name)} family"


def listed(names: list[str]) -> str:
    """`names` as a sentence lists them: "a", "a and b", "a, b and c"."""
    return names[0] if len(names) == 1 else f"{', '.join(names[:-1])} and {names[-1]}"


@functools.cache
def recorded_study(study: Path) -> StudyResult:
    """The study recorded in `study` (:func:`fppo_jax.load_study`: its plan, its decisions
    and each task's runs they used), read once per write-up."""
    return fppo_jax.load_study(study)


class FamilyNotAssembled(ValueError):
    """The recorded studies do not hold every comparison of a family the plan names."""


@dataclasses.dataclass(frozen=True)
class Replayed:
    """One comparison of a planned family: its `task` and `candidate`, its `row` in its
    study's ``decisions.json``, and the rule's decision over that study's comparisons
    (`alone`: what the study decided) and over the plan's whole family (`planned`)."""

    task: str
    candidate: str
    row: dict
    alone: Decision
    planned: Decision


@dataclasses.dataclass(frozen=True)
class Family:
    """A family of comparisons the plan names (`name`, its `tasks`), decided as one by the
    `design` its studies share on the endpoint `endpoint`: the `studies` that ran it, by task,
    and each comparison `replayed`, in the plan's order of tasks and the studies' of
    candidates."""

    name: str
    tasks: list[str]
    design: Design
    endpoint: str
    studies: dict[str, Path]
    replayed: list[Replayed]

    @property
    def split(self) -> bool:
        """Whether the family ran as several studies, each a family of its own."""
        return len(set(self.studies.values())) > 1


def planned_families(plan: dict) -> dict[str, list[str]]:
    """The families `plan` (tuned.json as read) names, each with its tasks."""
    return {name: list(family["tasks"]) for name, family in plan["families"].items()}


def family_studies(results: Path, name: str, tasks: list[str]) -> dict[str, Path]:
    """The recorded study that ran each of `tasks` (``tuned/<name>/study*/`` with its
    decisions); refused unless each task is in exactly one."""
    where = results / "tuned" / name
    studies: dict[str, list[Path]] = {task: [] for task in tasks}
    for folder in sorted(where.glob("study*")):
        try:
            study = recorded_study(folder)
        except MissingFile:  # no plan.json: not a study
            continue
        ran = study.plan["tasks"]
        if not set(ran) <= set(tasks):  # its levels would be shared with another family's
            raise FamilyNotAssembled(
                f"{folder} ran {listed(sorted(set(ran) - set(tasks)))}, outside "
                f"{called(name)} ({listed(tasks)})"
            )
        if study.decisions:  # it decided a look
            for task in ran:
                studies[task].append(folder)
    missing = [task for task in tasks if not studies[task]]
    if missing:
        raise FamilyNotAssembled(
            f"{called(name)} ({listed(tasks)}) cannot be decided as one: "
            f"{listed(missing)} {'has' if len(missing) == 1 else 'have'} no study with its "
            f"decisions under {where}/ (a study*/ folder with plan.json and decisions.json)"
        )
    twice = [task for task in tasks if len(studies[task]) > 1]
    if twice:
        raise FamilyNotAssembled(
            f"{called(name)} cannot be decided as one: {listed(twice)} ran in more "
            f"than one study under {where}/"
        )
    return {task: studies[task][0] for task in tasks}


def shared_design(name: str, studies: list[Path]) -> tuple[Design, dict]:
    """The design and the comparisons' terms (endpoint, baseline, candidates) that every study
    of a family shares; refused where two differ, since the family has one rule."""
    plans = [recorded_study(study).plan for study in studies]
    keys = ("group_size", "max_seeds", "level", "margin", "primary_endpoint", "baseline")
    terms = [{key: plan.get(key) for key in (*keys, "candidates")} for plan in plans]
    differing = [key for key in terms[0] if any(t[key] != terms[0][key] for t in terms)]
    if differing:
        raise FamilyNotAssembled(
            f"{called(name)} cannot be decided as one: its studies differ in {', '.join(differing)}"
        )
    first = terms[0]
    design = Design(first["group_size"], first["max_seeds"], first["level"], first["margin"])
    return design, first


def decide_family(results: Path, name: str, tasks: list[str]) -> Family:
    """The family `name` of the plan decided as one by the library's rule on the runs its
    studies recorded, each study's comparisons decided alone beside it; refused where the
    studies alone do not give their recorded decisions (then the replay is not their rule)."""
    studies = family_studies(results, name, tasks)
    design, terms = shared_design(name, sorted(set(studies.values())))
    endpoint, baseline = terms["primary_endpoint"], terms["baseline"]
    keys = [(task, candidate) for task in tasks for candidate in terms["candidates"]]
    runs = {task: recorded_study(study).results[task] for task, study in studies.items()}
    scores = {
        (task, candidate): (
            run_scores(runs[task], candidate, endpoint),
            run_scores(runs[task], baseline, endpoint),
        )
        for task, candidate in keys
    }
    planned = dict(zip(keys, decide([scores[key] for key in keys], design), strict=True))
    alone: dict[tuple[str, str], Decision] = {}
    for study in dict.fromkeys(studies.values()):
        own = [key for key in keys if studies[key[0]] == study]
        alone |= dict(zip(own, decide([scores[key] for key in own], design), strict=True))
    replayed = [
        Replayed(*key, recorded_row(studies[key[0]], *key), alone[key], planned[key])
        for key in keys
    ]
    for one in replayed:
        if not same_as_recorded(one.alone, one.row):
            row, alone = one.row, one.alone
            sys.exit(
                f"{studies[one.task]}: the rule replayed on its runs does not give its recorded "
                f"decision of {one.task} {one.candidate} ({row['decision']} at {row['seeds']} "
                f"seeds, z = {row['z']!r} against {row['boundary']!r}, interval "
                f"{row.get('interval')}) but {alone.decision or 'undecided'} at {alone.seeds} "
                f"seeds, z = {alone.z!r} against {alone.boundary!r}, interval {alone.interval}: "
                "the replay would not be the rule the study ran"
            )
    return Family(name, tasks, design, endpoint, studies, replayed)


def recorded_row(study: Path, task: str, candidate: str) -> dict:
    """`candidate`'s comparison on `task` as `study`'s ``decisions.json`` records it."""
    rows = recorded_study(study).decisions
    return next(r for r in rows if r["task"] == task and r["candidate"] == candidate)


def same_as_recorded(decision: Decision, row: dict) -> bool:
    """Whether `decision` is the recorded `row`: its decision and whether final, its seeds, z,
    boundary and repeated interval (to rounding)."""

    def close(a: float | None, b: float | None) -> bool:
        return (a is None) == (b is None) and (a is None or math.isclose(a, b, rel_tol=1e-9))

    interval = row.get("interval") or [None, None]
    return (
        (decision.decision or "undecided") == row["decision"]
        and (decision.decision is not None) == row["final"]
        and decision.seeds == row["seeds"]
        and close(decision.z if math.isfinite(decision.z) else None, row["z"])
        and close(decision.boundary if math.isfinite(decision.boundary) else None, row["boundary"])
        and all(
            close(a, b) for a, b in zip(decision.interval or [None, None], interval, strict=True)
        )
    )


def signed(value: float) -> str:
    return f"{value:.2f}".replace("-", "−")


def evidence(decision: Decision, kind: str, margin: float | None) -> str:
    """What a decision of `kind` is held to: z against its boundary for better or worse, P's
    repeated confidence interval against ½ ± `margin` for equivalent, both for undecided."""
    said = []
    if kind != "equivalent" and math.isfinite(decision.z):
        said.append(f"z = {signed(decision.z)} against ±{decision.boundary:.2f}")
    if kind not in ("better", "worse") and decision.interval and margin is not None:
        low, high = decision.interval
        inside = 0.5 - margin <= low and high <= 0.5 + margin
        said.append(
            f"P's repeated CI [{low:.2f}, {high:.2f}] {'within' if inside else 'not within'} "
            f"[{0.5 - margin:g}, {0.5 + margin:g}]"
        )
    return ", ".join(said)


def standing(one: Replayed) -> str:
    """What the plan's family makes of a comparison's decision in its own study: ``stands``
    (the same decision at the same seeds), ``not reached`` (undecided at the seeds its study
    ran), ``awaits seeds`` (its study is not finished), or ``differs``."""
    alone, planned = one.alone, one.planned
    if planned.decision == alone.decision and planned.seeds == alone.seeds:
        return "stands" if planned.decision is not None else "awaits seeds"
    if planned.decision is None and alone.decision is not None:
        return "not reached"
    return "differs"


def alone_cell(one: Replayed, margin: float | None) -> str:
    """A comparison's decision in its own study, with what it was held to."""
    decision = one.alone
    if decision.decision is None:
        return f"awaits seeds ({decision.seeds} so far)"
    held = evidence(decision, decision.decision, margin)
    return f"{decision.decision} at {decision.seeds} seeds: {held}"


def planned_cell(one: Replayed, margin: float | None) -> str:
    """What the plan's family makes of it, with what its own decision is held to there."""
    decision, status = one.planned, standing(one)
    held = evidence(decision, one.alone.decision or "undecided", margin)
    if status == "stands":
        return f"stands: {held}"
    if status == "not reached":
        return f"not reached: undecided at the {decision.seeds} seeds run, {held}"
    if status == "awaits seeds":
        return f"awaits seeds ({decision.seeds} so far)"
    return f"{decision.decision or 'undecided'} at {decision.seeds} seeds: {held}"


def families_lines(results: Path, plan: dict, families: dict[str, Family | str]) -> list[str]:
    """The plan's families: what each holds and what it controls, how it is decided here, and
    each one's decisions where its tasks ran as studies of their own (a family refused: why)."""
    candidates = len(plan["arms"]) - 1
    named = [
        f"the {FAMILY_NAMES.get(name, name)} tasks' {candidates * len(tasks)} comparisons "
        f"({candidates} candidates against tuned PPO on {listed(tasks)})"
        for name, tasks in planned_families(plan).items()
    ]
    lines = [
        "## The plan's families",
        "",
        f"The plan names {len(named)} families, each at level {plan['study']['level']} "
        f"(`study.family` in [tuned.json](../plans/tuned.json)): {listed(named)}. The decisions "
        "in this write-up are those families', each decided by the library's rule "
        "(`fppo_jax.stats.sequential.decide`: the group-sequential Mann–Whitney test with "
        "Lan–DeMets O'Brien–Fleming-type spending, Holm's procedure across the family, and "
        "equivalence when P's repeated confidence interval lies within 0.5 ± the margin), "
        "replayed look by look on the runs the studies recorded; nothing is trained.",
        "",
        "Each family controls two kinds of error, each at its level: a wrong better or worse "
        "(a comparison decided better or worse where neither arm tends to score higher) and a "
        "wrong equivalent (decided equivalent where P(candidate > PPO) is at least the margin "
        "from 0.5). The two concern different comparisons, so a family at level 0.05 may err "
        "one way or the other with probability up to 0.10.",
        "",
    ]
    for name, family in families.items():
        lines += [f"### The {FAMILY_NAMES.get(name, name)} family", ""]
        if isinstance(family, str):
            lines += [f"Not decided here: {family}.", ""]
        else:
            lines += family_lines(results, family)
    return lines


def family_lines(results: Path, family: Family) -> list[str]:
    """How `family` ran and what it decides: where one study ran it whole, that the replay
    gives its recorded decisions; where each task ran as a study of its own, each comparison
    decided in its study and in the plan's family at the seeds run."""
    studies = list(dict.fromkeys(family.studies.values()))
    links = [
        f"[{study.relative_to(results)}/]({study.relative_to(results)}/report.md)"
        for study in studies
    ]
    count, level = len(family.replayed), family.design.level
    if not family.split:
        return [
            f"{links[0]} ran this family as one study, its {count} comparisons at level "
            f"{level}. Replayed look by look, the rule gives each of its recorded decisions "
            "exactly (the decision, its seeds, z, boundary and repeated interval), so the "
            "decisions in its table below are the family's.",
            "",
        ]
    own = count // len(studies)
    return [
        f"Each of its tasks ran as a study of its own ({', '.join(links)}), each deciding its "
        f"{own} comparisons as a family at level {level}: a split the plan does not make, and "
        f"no amendment to the plan records it. A study of {own} tests each comparison at a "
        f"larger share of the level than the plan's family of {count} gives it. Replayed as "
        "its own family, each study gives its recorded decisions exactly (the decision, its "
        "seeds, z, boundary and repeated interval): the replay is the rule the studies ran. "
        f"Replayed as the plan's family (Holm's procedure over the {count}, at the same looks: "
        f"{listed([str(n) for n in family.design.looks])} seeds per arm), a comparison has "
        "only the seeds its study ran: one its study stopped at a look gets no later look, and "
        "what the family has not decided by then is undecided at the seeds run.",
        "",
        f"| task | candidate | its task's study, a family of {own} | the plan's family of "
        f"{count}, at the seeds run |",
        "|---|---|---|---|",
        *(
            f"| {one.task} | {one.candidate} | {alone_cell(one, family.design.margin)} | "
            f"{planned_cell(one, family.design.margin)} |"
            for one in family.replayed
        ),
        "",
        *standing_summary(family),
    ]


def standing_summary(family: Family) -> list[str]:
    """How many of the studies' decisions stand in the plan's family, and which do not."""
    decided = [one for one in family.replayed if one.alone.decision in DECIDED]
    by = {status: [one for one in decided if standing(one) == status] for status in STANDINGS}
    said = (
        f"Of the {len(decided)} decisions the studies reached, {len(by['stands'])} stand in "
        "the plan's family"
    )
    if lost := by["not reached"]:
        named = [f"{one.task} {one.candidate} {one.alone.decision}" for one in lost]
        said += (
            f" and {len(lost)} {'is' if len(lost) == 1 else 'are'} not reached "
            f"({listed(named)}): {'it is' if len(lost) == 1 else 'each is'} undecided at the "
            "seeds its study ran"
        )
    if changed := by["differs"]:
        said += f"; {len(changed)} the plan's family decides otherwise (the table says how)"
    left = [one for one in family.replayed if one.alone.decision == "undecided"]
    if kept := [one for one in left if standing(one) == "stands"]:
        said += f". The {len(kept)} comparisons the studies left undecided stay undecided"
    return [
        f"{said}. Each task's table below gives the plan's family's decision, and its study's "
        "own where it differs.",
        "",
    ]
