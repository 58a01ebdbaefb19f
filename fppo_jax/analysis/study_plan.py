"""A study's plan: what ``plan.json`` preregisters before any run (the comparisons, the
endpoints, the test in words, the seed schedule, the settings and the commit), which
:mod:`fppo_jax.analysis.preregistration` holds a study to. With the shapes of the JSON a
study records: ``plan.json``'s (:class:`StudyPlan`) and ``decisions.json``'s
(:class:`Decisions`, a row per comparison a :class:`DecisionRow`). The annotations are
evaluated (no ``from __future__ import annotations``), so that ``NotRequired`` keys are known at
run time too."""

from collections.abc import Mapping
from typing import NotRequired, TypedDict, cast

from fppo_jax.analysis.preregistration import commit
from fppo_jax.core.objectives import identities
from fppo_jax.core.shape_space import ChoiceValue
from fppo_jax.core.surrogates import Surrogate
from fppo_jax.errors import InvalidInput
from fppo_jax.stats import statistics
from fppo_jax.stats.rules import (
    DecisionRule,
    RuleRecord,
    SequentialMannWhitney,
    record_of,
    rule_of,
)
from fppo_jax.stats.sequential import Design
from fppo_jax.stats.spending import boundaries
from fppo_jax.store.files import json_value

ENDPOINTS = statistics.STUDY_ENDPOINTS  # decided on; those not chosen are reported beside it


# What plans recorded of their rule before they named it by id: its words (and, with a margin,
# the equivalence test's), which upgraded() reads as the rule's record.
WORDS = SequentialMannWhitney(Design(margin=0.2))
LEGACY_WORDS = {"test": WORDS.words, "equivalence_test": WORDS.equivalence_words}


PLAN_FILE, DECISIONS_FILE, REPORT_FILE = "plan.json", "decisions.json", "report.md"


class Comparison(TypedDict):
    """One comparison the plan makes: `candidate` against `baseline` on `task`."""

    task: str
    candidate: str
    baseline: str


class TunedChoice(TypedDict):
    """What a study on a tune's settings records of the tune (``plan.json``'s ``tuned``,
    :func:`~fppo_jax.analysis.study_tuned.tuned_settings`): where it is, its plan's digest, its
    tuning seeds, each task's protocol (a :class:`~fppo_jax.store.record.RunRecord`'s JSON) and
    each variant's chosen setting on each task (without the variant); chosen across tasks,
    also the rule in words and each variant's trial (its trial, rung and mean normalised
    score, :func:`~fppo_jax.analysis.tuning_report.across_tasks`)."""

    directory: str
    plan_digest: str
    tuning_seeds: list[int]
    protocol: Mapping[str, Mapping[str, object]]  # by task
    selection: NotRequired[str]
    trials: NotRequired[Mapping[str, Mapping[str, object]]]  # by variant
    # By task, then variant: its hyperparameters and, where the tune searched the run's shape,
    # its run-shape values (some of them booleans, which a Setting's values are not).
    settings: dict[str, dict[str, dict[str, ChoiceValue]]]


class StudyPlan(TypedDict):
    """``plan.json``: the preregistration (:func:`make_plan`), as
    :func:`~fppo_jax.analysis.preregistration.check_plan` holds a study to it. The keys a plan
    lacks where it was recorded before they existed, or where the study has none: the
    equivalence margin and its test, the directories of recorded sweeps to `reuse`, the
    `surrogates` of one's own (each one's identity,
    :meth:`~fppo_jax.core.surrogates.Surrogate.identity`), the `tuned` settings and whether
    each arm's default trains beside them (`with_defaults`). Its `settings`: the run shape
    (``total_steps``, ``preset``, ``backend``) and the sweeps' other keyword arguments that
    make runs differ (hyperparameters, run-shape fields, evaluations), as JSON, by name."""

    tasks: list[str]
    baseline: str
    candidates: list[str]
    comparisons: list[Comparison]
    primary_endpoint: str
    secondary_endpoints: list[str]
    rule: RuleRecord
    level: float
    margin: NotRequired[float]
    group_size: int
    max_seeds: int
    looks: list[int]
    boundaries_if_none_decided: list[float]
    settings: dict[str, object]
    reuse: NotRequired[list[str]]
    surrogates: NotRequired[Mapping[str, Mapping[str, object]]]
    commit: str
    tuned: NotRequired[TunedChoice]
    with_defaults: NotRequired[bool]


class DecisionRow(TypedDict):
    """One comparison's row of ``decisions.json`` (and of
    :attr:`~fppo_jax.analysis.study_files.StudyResult.decisions`): its `decision` (``better``,
    ``worse``, ``equivalent``, or ``undecided`` while it awaits seeds or where the seeds ran
    out), whether it is `final`, the `seeds` per setting it used, its latest statistic `z` and
    the `boundary` held against it (None before any look), why it stopped in words, and with a
    margin the repeated confidence `interval` of P(candidate > baseline) that the equivalence
    test held against ½ ± δ."""

    task: str
    candidate: str
    baseline: str
    decision: str
    final: bool
    seeds: int
    z: float | None
    boundary: float | None
    reason: str
    interval: NotRequired[list[float]]


class GroupEntry(TypedDict):
    """What ``decisions.json`` says of one group of a task's seeds: the `commit` it trained at,
    or, trained in shares by array tasks, the commit of each share (`shares`, ``""`` for one
    that recorded none), or the recorded sweeps its runs were taken from, by variant
    (`reused`), or these together; `defaults` where it is of each arm's default setting
    (with_defaults); `shape` where its arms train in a run shape a tune chose."""

    task: str
    group: int
    defaults: NotRequired[bool]
    shape: NotRequired[dict[str, ChoiceValue]]  # a run shape a tune chose for some arms
    seeds: list[int]
    commit: NotRequired[str]
    shares: NotRequired[list[str]]
    reused: NotRequired[dict[str, list[str]]]


# An interval as decisions.json records it: [point, low, high], None where no run has a score.
Interval = list[float | None]


class Compared(TypedDict):
    """One setting's runs against another's over the first `seeds` both ran, untested."""

    seeds: int
    probability_of_improvement: Interval
    iqm_difference: Interval


class TuningGain(Compared):
    """An `arm`'s tuned setting against its default on `task`: what tuning gained."""

    task: str
    arm: str


class DefaultsCompared(Compared):
    """A `candidate`'s default against the `baseline`'s default on `task`."""

    task: str
    candidate: str
    baseline: str


class BesideDefaults(TypedDict):
    """What each arm's default measures beside the decisions on the primary `endpoint`, never
    `tested` (:func:`~fppo_jax.analysis.study_report.beside_defaults`)."""

    endpoint: str
    tested: bool
    tuned_against_default: list[TuningGain]
    default_against_default: list[DefaultsCompared]


class Decisions(TypedDict):
    """``decisions.json``: whether every comparison is `finished`, the plan's margin where it
    has one, a row per comparison, what each arm's default measured beside them (with_defaults)
    and every group recorded."""

    finished: bool
    margin: NotRequired[float]
    comparisons: list[DecisionRow]
    beside_defaults: NotRequired[BesideDefaults]
    groups: list[GroupEntry]


class _Optional(TypedDict, total=False):
    """The keys of :class:`StudyPlan` that only some plans have, as :func:`make_plan` spreads
    each in its place."""

    margin: float
    reuse: list[str]
    surrogates: Mapping[str, Mapping[str, object]]
    tuned: TunedChoice
    with_defaults: bool


def make_plan(
    tasks: list[str],
    candidates: list[Surrogate],
    baseline: Surrogate,
    rule: DecisionRule,
    endpoint: str,
    settings: dict[str, object],
    reuse: list[str],
    tuned: TunedChoice | None = None,
    with_defaults: bool = False,
) -> StudyPlan:
    """What ``plan.json`` records: the preregistration, decided before any run (as JSON: what
    :func:`~fppo_jax.analysis.preregistration.check_plan` compares with the file's). What only
    some plans record is left out where the study has none: a plan from before it existed is
    one without."""
    design = rule.design
    own = identities([*candidates, baseline]).get("surrogates")
    reused: _Optional = {"reuse": reuse} if reuse else {}
    surrogates: _Optional = {"surrogates": own} if own else {}
    on_tune: _Optional = {} if tuned is None else {"tuned": tuned}
    if with_defaults:
        on_tune["with_defaults"] = True
    plan: StudyPlan = {
        "tasks": tasks,
        "baseline": baseline.name,
        "candidates": [c.name for c in candidates],
        "comparisons": [
            {"task": task, "candidate": c.name, "baseline": baseline.name}
            for task in tasks
            for c in candidates
        ],
        "primary_endpoint": endpoint,
        "secondary_endpoints": [
            e for e in ENDPOINTS if e != endpoint and (e != "eval" or "eval_every" in settings)
        ],
        "rule": record_of(rule),
        "level": design.level,
        **_equivalence_plan(design),
        "group_size": design.group_size,
        "max_seeds": design.max_seeds,
        "looks": list(design.looks),
        "boundaries_if_none_decided": list(
            boundaries(design.level / (len(tasks) * len(candidates)), _fractions(design))
        ),
        "settings": settings,
        **reused,
        **surrogates,
        "commit": commit(),
        **on_tune,
    }
    return cast(StudyPlan, json_value(plan))


def _equivalence_plan(design: Design) -> _Optional:
    """What the plan records of the equivalence test: nothing without a margin (a plan
    recorded before margins existed is one without), else the margin."""
    return {} if design.margin is None else {"margin": design.margin}


def upgraded(plan: dict[str, object]) -> dict[str, object]:
    """`plan` as this code records it, where it was recorded naming its rule in words (the
    rule's record in place of the words, the keys in their order); refused, naming it, if the
    words are not the rule's."""
    if "test" not in plan:
        return plan
    for key, words in LEGACY_WORDS.items():
        if key in plan and plan[key] != words:
            raise InvalidInput(
                f"the plan names its rule ({key}) in words this fppo-jax does not know: "
                f"{plan[key]!r}; decide it with the fppo-jax that planned it"
            )
    rule = record_of(WORDS)
    return {
        ("rule" if key == "test" else key): (rule if key == "test" else value)
        for key, value in plan.items()
        if key != "equivalence_test"
    }


def rule_of_plan(plan: StudyPlan) -> DecisionRule:
    """The rule `plan` decides by, under its design."""
    design = Design(plan["group_size"], plan["max_seeds"], plan["level"], plan.get("margin"))
    return rule_of(plan["rule"], design)


def _fractions(design: Design) -> tuple[float, ...]:
    return tuple(n / design.max_seeds for n in design.looks)
