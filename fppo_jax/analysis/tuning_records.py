"""The shapes of the JSON files a tune records (:mod:`fppo_jax.analysis.tuning`): its plan,
``tune.json`` (:class:`TunePlan`); each rung's ``scores.json`` (:class:`RungScores`) and each
share's (:class:`ShareScores`); ``results.json``, per task and arm (:class:`ArmResults`); and
the trial an arm chooses for all tasks (:class:`TrialAcrossTasks`). Keys that tunes recorded
before they existed lack are ``NotRequired``; ``tests/test_tuning_records.py`` holds every
recorded tune's files to these shapes. The annotations are evaluated (no ``from __future__
import annotations``), so that ``NotRequired`` keys are known at run time too."""

from collections.abc import Sequence
from typing import Any, NotRequired, TypedDict

from fppo_jax.core.search_space import Axis
from fppo_jax.core.shape_space import ChoiceAxis, ChoiceValue
from fppo_jax.core.surrogates import SurrogateIdentity

# A run-shape setting's value, as a tune's plan records it for every run: a TrainConfig field's
# (hidden_sizes a sequence), total_steps's (None: the task's budget), the preset, the backend or
# the chunk.
RunShapeValue = int | bool | str | Sequence[int] | None


# A trial's setting as records hold it: each hyperparameter's value, and its run shape's.
TrialSetting = dict[str, ChoiceValue]


class RungPlan(TypedDict):
    """A rung in ``tune.json``: its live trials per arm, the update it ends at and the env steps
    a run has trained by then."""

    trials: int
    ends_at_update: int
    env_steps_per_run: int


class TaskBudget(TypedDict):
    """A task's budget in ``tune.json``: the env steps every arm trains (at most, for a race
    over seeds), those of one full run, halving's rungs, and the full runs per arm they make
    (tunes from before the validation race lack it)."""

    env_steps_per_arm: int
    env_steps_per_full_run: int
    rungs: NotRequired[list[RungPlan]]
    full_runs_per_arm: NotRequired[float]


class SamplerRecord(TypedDict):
    """The sampler in ``tune.json``: its name, its seed and the Optuna release that ran it."""

    name: str
    seed: int
    package: str


class StorageRecord(TypedDict):
    """Optuna's storage in ``tune.json`` (:mod:`fppo_jax.analysis.tune_storage`): its URL with
    the password masked (``optuna.db``: the file in the output), and the prefix of the tune's
    study names there."""

    url: str
    studies: str


class SearchRecord(TypedDict):
    """The search's scheduler in ``tune.json``: its name, halving's η or racing's seeds per
    round and level."""

    name: str
    eta: NotRequired[int]
    seeds_per_round: NotRequired[int]
    level: NotRequired[float]


class ValidationRecord(TypedDict):
    """The validation race in ``tune.json``: its finalists per arm, its seeds, its level and its
    test (an id and a version)."""

    finalists: int
    seeds: list[int]
    level: float
    test: dict[str, str | int]


class TunePlan(TypedDict):
    """A tune's plan, ``tune.json`` (:func:`make_plan`). Tunes from before the validation race
    lack `search` and `validation` (they searched by successive halving, with `eta`)."""

    tasks: list[str]
    variants: list[str]
    baseline: str
    trials: int
    trial_0: str
    seeds: list[int]
    eta: NotRequired[int]
    budget: dict[str, TaskBudget]
    space: dict[str, dict[str, Axis]]  # per arm, its axes by hyperparameter
    run_shape: NotRequired[dict[str, dict[str, ChoiceAxis]]]  # per task, where one is searched
    sampler: SamplerRecord
    storage: NotRequired[StorageRecord]  # tunes from before it name their studies plainly
    score: str
    selection: str
    search: NotRequired[SearchRecord]
    validation: NotRequired[ValidationRecord]
    settings: dict[str, RunShapeValue]
    protocol: dict[str, dict[str, Any]]  # per task, its run record's JSON (RunRecord.to_json)
    surrogates: NotRequired[dict[str, SurrogateIdentity]]  # own surrogates', if any
    commit: str


class TrialScore(TypedDict):
    """A trial's row in a rung's ``scores.json``: its score (the mean over the tuning seeds;
    None where a run finished no episode), each seed's, and whether a run diverged."""

    trial: int
    score: float | None
    seed_scores: list[float | None]
    diverged: bool


class RaceTest(TypedDict):
    """A test as a plan and a record name it: a stable id and its version."""

    id: str
    version: int


class RaceRecord(TypedDict):
    """What the validation race recorded of an arm (:mod:`fppo_jax.analysis.validation_race`):
    its test and level, its finalists (best first), each finalist's score in the search (its
    last rung's) beside the race, each one's one-sided p against the default and Holm-adjusted
    p, P(finalist > default) with its bootstrap interval ([point, low, high]; None where no run
    scored), the default's and each finalist's mean validation score, and the trial chosen (0:
    the default stays)."""

    test: RaceTest
    level: float
    finalists: list[int]
    search_scores: list[float | None]
    default_score: float | None
    validation_scores: list[float | None]
    p: list[float]
    adjusted: list[float]
    probability_of_improvement: list[list[float | None]]
    chosen: int


class RungEvidence(TypedDict):
    """What a rung's scores say about cutting on them (:mod:`fppo_jax.analysis.rung_evidence`):
    whether its trials tied, the one-way ANOVA's F (between- over within-trial mean square)
    and its p, and Spearman's ρ with the rung before (None where not computable)."""

    tied: bool
    variance_ratio: float | None
    p: float | None
    rank_correlation: float | None


class ArmRung(TypedDict):
    """An arm's part of a rung's ``scores.json``: its live trials' rows, and the trials that go
    on to the next rung; the validation race's rung also holds what the race decided."""

    trials: list[TrialScore]
    survivors: list[int]
    race: NotRequired[RaceRecord]
    evidence: NotRequired[RungEvidence]


class RungScores(TypedDict):
    """A rung's ``scores.json``: each arm's part, the seconds the rung trained and compiled,
    the commit of the code that recorded it and the machines its shares trained on
    (:func:`~fppo_jax.store.machine.describe_machine`; rungs recorded before these were kept
    have none)."""

    arms: dict[str, ArmRung]
    seconds: float
    compile_seconds: float
    commit: NotRequired[str]
    machines: NotRequired[list[str]]


class Chosen(TypedDict):
    """The trial chosen for an arm on a task, its score at the last rung and its setting."""

    trial: int
    score: float | None
    setting: TrialSetting


class DefaultResult(TypedDict):
    """Trial 0, the arm's default: its setting, its first rung's score, and the last rung it
    reached with its score there."""

    setting: TrialSetting
    first_rung_score: float | None
    last_rung_reached: int
    score_there: float | None


class CurvePoint(TypedDict):
    """A point of the tuning curve: the best score at `rung`, of its `trials`, against the env
    steps the arm had spent by its end."""

    rung: int
    env_steps: int
    best: float | None
    trials: int


class BaselineBeaten(TypedDict):
    """How many of the arm's `sampled` settings scored above the baseline's default on the
    first rung."""

    baseline: str
    baseline_default_score: float | None
    sampled: int
    beat: int


class Spread(TypedDict):
    """The first rung's scores over the space: quartiles, range and sample std (None where no
    trial scored; the std also for one score)."""

    min: float | None
    q1: float | None
    median: float | None
    q3: float | None
    max: float | None
    sample_std: NotRequired[float | None]  # tunes from before it lack it


class ExpectedBestPoint(TypedDict):
    """:func:`expected_best` at n = `settings`, with its band, at the env steps they cost."""

    settings: int
    env_steps: int
    expected_best: float
    low: float
    high: float


class ExpectedBestCurve(TypedDict):
    """The expected best of 1 … trials first-rung settings, from the `scored_trials`, with the
    bootstrap band's level, replicates and seed."""

    scored_trials: int
    confidence: float
    resamples: int
    seed: int
    points: list[ExpectedBestPoint]


class ArmResults(TypedDict):
    """What ``results.json`` holds of an arm on one task (see the module). Tunes from before
    `trials`, `expected_best`, `tied_rungs` and the validation `race` were recorded lack them."""

    chosen: Chosen | None  # None: every trial diverged
    default: DefaultResult
    curve: list[CurvePoint]
    env_steps: int
    beat_baseline_default: BaselineBeaten
    trials: NotRequired[list[TrialSetting]]  # each trial's setting, by number
    first_rung_spread: Spread
    expected_best: NotRequired[ExpectedBestCurve | None]  # None: no trial scored
    diverged_trials: list[int]
    tied_rungs: NotRequired[list[int]]
    race: NotRequired[RaceRecord]


class TrialAcrossTasks(TypedDict):
    """An arm's trial chosen for all of a tune's tasks (:func:`across_tasks`): the rung its
    trials were compared at and its mean normalised score there."""

    trial: int
    rung: int
    normalised_score: float


class ShareScores(TypedDict):
    """A share's ``part-<K>/scores.json``: which `part` (K, N) of the rung it is, its runs
    (arm, trial, seed, in the rung's order), each run's score (None where no episode finished)
    and whether it diverged, the seconds it trained and compiled, and the commit of the code
    that trained it and the machine it trained on (shares recorded before these were kept have
    none)."""

    part: list[int]
    runs: Sequence[Sequence[str | int]]
    scores: list[float | None]
    diverged: list[bool]
    seconds: float
    compile_seconds: float
    commit: NotRequired[str]
    machine: NotRequired[str]
