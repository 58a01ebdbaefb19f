"""A study's plan: what ``plan.json`` preregisters before any run (the comparisons, the
endpoints, the test in words, the seed schedule, the settings and the commit), and the check
that a study, or a tune, goes on only under the plan it started with. With the shapes of the
JSON a study records: ``plan.json``'s (:class:`StudyPlan`) and ``decisions.json``'s
(:class:`Decisions`, a row per comparison a :class:`DecisionRow`). The annotations are
evaluated (no ``from __future__ import annotations``), so that ``NotRequired`` keys are known at
run time too."""

import json
import subprocess
from collections.abc import Mapping
from pathlib import Path
from typing import NotRequired, TypedDict, TypeVar, cast

from fppo_jax.core.config import Setting
from fppo_jax.core.objectives import identities
from fppo_jax.core.surrogates import Surrogate
from fppo_jax.errors import InvalidInput
from fppo_jax.stats import statistics
from fppo_jax.stats.sequential import Design
from fppo_jax.stats.spending import boundaries
from fppo_jax.store.files import json_value, write_json

ENDPOINTS = statistics.STUDY_ENDPOINTS  # decided on; those not chosen are reported beside it


# The rule in words, which a plan records and a resumed study is held to; they name no module,
# whose place may change while the rule does not (experiments/convert_plans.py converted the
# plans recorded when they named one).
TEST = (
    "two-sided group-sequential Mann–Whitney test of P(candidate > baseline) = 1/2, "
    "Lan–DeMets O'Brien–Fleming-type alpha-spending over the looks, Holm's procedure across "
    "the comparisons"
)


EQUIVALENCE_TEST = (
    "equivalent when P(candidate > baseline) is within 1/2 ± margin: two one-sided "
    "group-sequential tests (the repeated confidence interval of P, placement standard error, "
    "inside the margin), Lan–DeMets O'Brien–Fleming-type one-sided alpha-spending, Holm's "
    "procedure across the comparisons"
)


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
    settings: dict[str, dict[str, Setting]]  # by task, then variant


class StudyPlan(TypedDict):
    """``plan.json``: the preregistration (:func:`make_plan`), as :func:`check_plan` holds a
    study to it. The keys a plan lacks where it was recorded before they existed, or where the
    study has none: the equivalence margin and its test, the directories of recorded sweeps to
    `reuse`, the `surrogates` of one's own (each one's identity,
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
    test: str
    level: float
    margin: NotRequired[float]
    equivalence_test: NotRequired[str]
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
    :attr:`~fppo_jax.analysis.study_looks.StudyResult.decisions`): its `decision` (``better``,
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
    (with_defaults)."""

    task: str
    group: int
    defaults: NotRequired[bool]
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


# Any plan check_plan holds to: a study's, a tune's, as JSON.
Plan = TypeVar("Plan", bound=Mapping[str, object])


def commit() -> str:
    """The commit of the code that runs (``git rev-parse HEAD`` in the package's directory), or
    ``unknown`` outside a git checkout."""
    try:
        done = subprocess.run(
            ["git", "rev-parse", "HEAD"],
            cwd=Path(__file__).resolve().parent,
            capture_output=True,
            text=True,
            check=True,
            timeout=30,
        )
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return done.stdout.strip() or "unknown"


class _Optional(TypedDict, total=False):
    """The keys of :class:`StudyPlan` that only some plans have, as :func:`make_plan` spreads
    each in its place."""

    margin: float
    equivalence_test: str
    reuse: list[str]
    surrogates: Mapping[str, Mapping[str, object]]
    tuned: TunedChoice
    with_defaults: bool


def make_plan(
    tasks: list[str],
    candidates: list[Surrogate],
    baseline: Surrogate,
    design: Design,
    endpoint: str,
    settings: dict[str, object],
    reuse: list[str],
    tuned: TunedChoice | None = None,
    with_defaults: bool = False,
) -> StudyPlan:
    """What ``plan.json`` records: the preregistration, decided before any run (as JSON: what
    :func:`check_plan` compares with the file's). What only some plans record is left out where
    the study has none: a plan from before it existed is one without."""
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
        "test": TEST,
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
    recorded before margins existed is one without), else the margin and the test."""
    if design.margin is None:
        return {}
    return {"margin": design.margin, "equivalence_test": EQUIVALENCE_TEST}


def _fractions(design: Design) -> tuple[float, ...]:
    return tuple(n / design.max_seeds for n in design.looks)


def check_plan(
    output: Path,
    plan: Plan,
    what: str = "a study",
    name: str = PLAN_FILE,
    recorded_only: frozenset[str] = frozenset({"commit"}),
) -> Plan:
    """Write `plan` as `name` in `output`, or check it against the one there: `what` (a study,
    a tune) goes on only under the plan it started with, the fields in `recorded_only` aside
    (the commit: a group records its own). Returns the plan as recorded, with the commit it was
    made at (of `plan`'s shape: the file's fields are compared with it, one by one)."""
    path = output / name
    if not path.exists():
        write_json(path, plan)
        return plan
    try:
        recorded = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as error:
        raise InvalidInput(f"cannot read the plan {path}: {error}") from None
    for field in dict.fromkeys([*recorded, *plan]):
        was, now = recorded.get(field), plan.get(field)
        if field in recorded_only or was == now:
            continue
        if isinstance(was, dict) and isinstance(now, dict):
            keys = [
                k
                for k in dict.fromkeys([*was, *now])
                if was.get(k) != now.get(k) and f"{field}.{k}" not in recorded_only
            ]
            if not keys:
                continue
            field, was, now = f"{field}.{keys[0]}", was.get(keys[0]), now.get(keys[0])
        raise InvalidInput(
            f"{output} holds {what} planned with {field} = {_shown(was)}, not {_shown(now)}: "
            f"{what} goes on only under its plan (start another in a new directory)"
        )
    return cast(Plan, recorded)


def _shown(value: object) -> str:
    return "none" if value is None else json.dumps(value)
