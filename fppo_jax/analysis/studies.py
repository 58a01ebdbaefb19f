"""A preregistered comparison that adds seeds until it can answer: candidates against a
baseline on a list of tasks, trained in groups of seeds until :mod:`fppo_jax.stats.sequential`'s
rule decides each comparison or the seeds run out.

The study's directory holds ``plan.json`` (written before any run: the preregistration of the
comparisons, the endpoints, the test and its level, the equivalence margin where one is given,
the seed schedule, the settings and the code's commit), each group of each task as one sweep
(``<task>/group-<k>/``, recorded by the sweep itself when it ends), each task's runs so far
as one sweep merged over its groups (``<task>/curves.csv`` and ``sweep.json``, after every
look), ``decisions.json`` after every look and ``report.md``
(:mod:`fppo_jax.analysis.study_report`). With ``progress=True`` the study prints on stderr its
plan's boundaries (:func:`~fppo_jax.stats.decidable.plan_lines`), each look's task and seeds,
and each decision as it is made. The same call again goes on from
the groups recorded; a study whose plan differs is refused, naming the field.

Each look trains, per task, one sweep of the next group's seeds for the candidates still
undecided, and the baseline while any of them is. Runs reused from recorded sweeps (a seed
study's parts, say) are taken instead of trained where they match the task, protocol and
setting, at every seed of the group (:mod:`fppo_jax.analysis.reuse`); ``decisions.json`` names where
each came from. A SLURM job array's tasks each train a share of the next look's groups
(``group-<k>/part-<K>/``, the shares of :func:`~fppo_jax.sweep`) and decide nothing; a call
without a part, after the array, joins the shares, decides and reports. A requeued task does
not train again the shares recorded already.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any, cast

import numpy as np

from fppo_jax.analysis.reuse import Pool, Taken, protocol_differences
from fppo_jax.analysis.study_figures import write_figures
from fppo_jax.analysis.study_report import beside_defaults, write_report
from fppo_jax.analysis.study_sections import SHARES, START, Scores, steps_name
from fppo_jax.core.checks import check_part, positive_int
from fppo_jax.core.objectives import hyperparameter_names, identities, takers, union
from fppo_jax.core.resolution import resolve, resolve_hyperparameters, sweepable
from fppo_jax.core.surrogates import Surrogate
from fppo_jax.core.variants import BUILTINS
from fppo_jax.errors import InvalidInput
from fppo_jax.run.merge import merge
from fppo_jax.run.options import Options
from fppo_jax.run.plan import part_runs
from fppo_jax.run.prepare import prepare
from fppo_jax.run.results import SweepResult
from fppo_jax.run.sweeps import expand_grid, sweep
from fppo_jax.stats import statistics
from fppo_jax.stats.decidable import plan_lines
from fppo_jax.stats.sequential import Decision, Design, decide
from fppo_jax.stats.spending import boundaries
from fppo_jax.store.files import DirectoryLock, json_value, writable_directory, write_json
from fppo_jax.store.record import RunRecord

ENDPOINTS = statistics.STUDY_ENDPOINTS  # decided on; those not chosen are reported beside it
# Reported beside the plan's endpoints, never decided on: each run's best return over training
# (the paper's statistic is its like over the seed-mean curve), biased upward.
REPORTED = "max"
# The options a plan records: evaluations make the eval endpoint, and change what runs record.
EVALUATION = ("eval_every", "eval_episodes")
# Seconds an array task waits for the others that started with it to check the plan: each
# holds the study's lock for that alone, well under a second, before it trains its share.
PART_LOCK_WAIT = 60.0

# What the study sets itself for every group's sweep.
OWN_SETTINGS = ("log_dir", "checkpoint_dir", "resume", "checkpoint_every", "keep", "callback")
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
ACROSS_TASKS = (
    "across tasks: per arm, one trial for every task (a drawn trial is the same point on each; "
    "trial 0 is each task's default), chosen among the arm's trials that reached the deepest "
    "rung reached on every task by any of them: the best mean over the tune's tasks of its "
    "score at that rung, normalised per task by the min and max of every arm's trials scored "
    "there (a task where they all tie counts 0); ties by trial number; a trial's deepest rung "
    "on a task is the last where it scored and did not diverge "
    "(fppo_jax.analysis.tuning_report.across_tasks)"
)
# Where each arm's default setting trains beside its tuned one (with_defaults), by task and group.
DEFAULTS = "defaults"


@dataclasses.dataclass
class StudyResult:
    """What a study holds so far: its `plan` (as ``plan.json`` has it), one row per comparison
    in `decisions` (as ``decisions.json`` has them), each task's recorded runs merged into one
    sweep (`results`, by task), whether every comparison is `finished`, and with
    ``with_defaults`` each task's runs of each arm's default setting (`defaults`, by task)."""

    plan: dict[str, Any]
    decisions: list[dict[str, Any]]
    results: dict[str, SweepResult]
    finished: bool
    defaults: dict[str, SweepResult] = dataclasses.field(default_factory=dict)


def study(
    tasks: str | Sequence[str],
    candidates: Any,
    baseline: str | Surrogate = "ppo",
    *,
    output: str | Path,
    max_seeds: int = 30,
    group_size: int = 5,
    level: float = 0.05,
    margin: float | None = None,
    endpoint: str = "final",
    groups: int | None = None,
    total_steps: int | None = None,
    preset: str = "paper",
    backend: str = "auto",
    chunk: int | None = None,
    reuse: str | Path | Sequence[str | Path] | None = None,
    part: tuple[int, int] | None = None,
    tuned: str | Path | None = None,
    with_defaults: bool = False,
    across_tasks: bool = False,
    **settings: Any,
) -> StudyResult:
    """Compare each of `candidates` with `baseline` on each of `tasks`, adding seeds in groups
    of `group_size` (per setting) until the rule of :mod:`fppo_jax.stats.sequential` decides each
    comparison, at family-wise error `level`, or `max_seeds` is reached (see the module).

    `level` is the test's α (not the hyperparameter ``alpha``, which `settings` may fix).
    `margin` δ, in (0, ½), lets a comparison be decided ``equivalent``: P(candidate >
    baseline) shown within ½ ± δ, the chance of a false ``equivalent`` in the family at most
    `level` (:mod:`fppo_jax.stats.sequential`); None (the default) decides only ``better`` or
    ``worse``, and the plan records no margin.
    Variants are as :func:`~fppo_jax.sweep` takes them. `endpoint` (``final``, ``auc``, or
    ``eval`` with ``eval_every``) is decided on; the others and ``max`` are reported beside it.
    `groups` limits the looks this call trains (0 writes the plan alone). `reuse` names
    directories of recorded sweeps to take runs from.
    ``part=(K, N)`` trains the K-th of N shares of the next look's groups and returns.
    `tuned`, a finished tune's directory (:func:`~fppo_jax.tune`), trains each arm at the
    setting the tune chose for it on each task; the plan records the tune's digest, and seeds
    that the tune used are refused. With `with_defaults`, each arm's default setting (the tune's
    trial 0) also trains on the same seeds at the same looks (in ``defaults/``, or taken from
    recorded runs with `reuse`), and the report and ``decisions.json`` give each arm's gain from
    tuning and the default-against-default comparisons beside the decisions, untested.
    `across_tasks` chooses one trial per arm for all the tune's tasks
    (:func:`~fppo_jax.analysis.tuning_report.across_tasks`) instead of each task's best.
    `total_steps`, `preset`, `backend`, `chunk` and `settings` are the sweeps'.
    """
    tasks = names_of_tasks(tasks)
    candidates, baseline = _variants(candidates, baseline)
    design = Design(group_size, max_seeds, level, margin)
    _check_arguments(endpoint, groups, chunk, part, settings)
    sources = [str(d) for d in ([reuse] if isinstance(reuse, str | Path) else reuse or [])]
    shape = {"total_steps": total_steps, "preset": preset, "backend": backend}
    everyone = [*candidates, baseline]
    chosen = None
    if tuned is not None:
        chosen = tuned_settings(
            tuned, tasks, everyone, design, settings, bool(across_tasks), bool(with_defaults)
        )
    elif with_defaults or across_tasks:
        raise InvalidInput(
            "with_defaults and across_tasks are options of a study on a tune's settings: give "
            "tuned (--tuned DIR)"
        )
    source = _Source.of(tasks, everyone, settings, shape, chunk, part, sources, chosen)
    if tuned is not None:
        _check_tuned_protocol(tuned, source)
    if with_defaults:
        source = dataclasses.replace(source, defaults=source.at_defaults(everyone))
    planned = {**shape, **_planned_settings(settings)}
    plan = make_plan(tasks, candidates, baseline, design, endpoint, planned, sources)
    if chosen is not None:
        plan["tuned"] = json_value(chosen)
    if with_defaults:  # recorded only where given: a plan from before the option is one without
        plan["with_defaults"] = True
    output = writable_directory(output)
    # Array tasks that start together take turns to check the plan (each holds the lock briefly).
    lock = DirectoryLock(output, "a study", wait=PART_LOCK_WAIT if part is not None else 0.0)
    try:
        plan = check_plan(output, plan)
        if part is not None:  # the array's tasks train their shares side by side
            lock.release()
        if _shown_progress(settings):
            lines = plan_lines(design, len(tasks) * len(candidates))
            print("\n".join(f"study: {line}" for line in lines), file=sys.stderr)
        return _run(output, plan, tasks, candidates, baseline, design, groups, source)
    finally:
        lock.release()


@dataclasses.dataclass(frozen=True)
class _Source:
    """Where a study's groups of runs come from: recorded sweeps in the `pool` of reused
    directories, where they match the `expected` protocol and setting, else trained (with the
    study's `settings` and `shape`; by this call, only its `part` of each group)."""

    settings: dict[str, Any]
    shape: dict[str, Any]
    specific: set[str]  # the hyperparameters that only some variants take
    part: tuple[int, int] | None
    expected: dict[str, tuple[RunRecord, dict[str, dict[str, Any]]]]
    identity: dict[str, Any]
    pool: Pool | None
    tuned: dict[str, Any] | None  # a tune's chosen settings, by task and variant
    # with_defaults: the source of each arm's default setting, trained beside its tuned one
    defaults: _Source | None = None

    @classmethod
    def of(
        cls,
        tasks: list[str],
        everyone: list[Surrogate],
        settings: dict[str, Any],
        shape: dict[str, Any],
        chunk: int | None,
        part: tuple[int, int] | None,
        reuse: list[str],
        tuned: dict[str, Any] | None = None,
    ) -> _Source:
        """The study's source of runs, every setting of every task checked and the recorded
        sweeps of `reuse` read, all before the plan is written: a mistyped directory or a
        setting refused leaves no plan behind."""
        return cls(
            settings,
            {**shape, "chunk": chunk},
            set(hyperparameter_names([*BUILTINS.values(), *everyone])),
            part,
            {
                task: _checked_settings(
                    task,
                    everyone,
                    settings,
                    shape,
                    None if tuned is None else tuned["settings"][task],
                )
                for task in tasks
            },
            identities(everyone).get("surrogates", {}),
            Pool.read(reuse) if reuse else None,
            tuned,
        )

    def train(
        self, task: str, variants: list[Surrogate], seeds: list[int], where: Path
    ) -> SweepResult:
        by_name = {s.name: s for s in variants}
        fixed = {
            name: value
            for name, value in self.settings.items()
            if name not in self.specific or takers(name, by_name)
        }
        grid: dict[str, Any] | list[dict[str, Any]] = {"variant": variants}
        if self.tuned is not None:
            chosen = self.tuned["settings"][task]
            grid = [{"variant": v, **chosen[v.name]} for v in variants]
        return sweep_group(task, grid, seeds, where, part=self.part, **self.shape, **fixed)

    def at_defaults(self, everyone: list[Surrogate]) -> _Source:
        """The like of this source for each arm's default setting: the settings a study without
        a tune trains (no hyperparameter given), so that such a study's recorded runs are
        taken from the pool."""
        expected = {
            task: (protocol, {s["variant"]: s for s in expand_grid({"variant": everyone}, task)})
            for task, (protocol, _) in self.expected.items()
        }
        return dataclasses.replace(self, expected=expected, tuned=None)

    def take(self, task: str, variant: Surrogate, seeds: list[int]) -> Taken | None:
        """`variant`'s runs on `task` at `seeds` from the recorded sweeps, if they hold them
        all under the study's protocol and setting (and evaluated, where the study evaluates:
        how often and over how many episodes, a sweep's record does not say)."""
        if self.pool is None:
            return None
        protocol, setting_of = self.expected[task]
        name = variant.name
        taken = self.pool.take(protocol, setting_of[name], self.identity.get(name), seeds)
        if taken is not None and self.settings.get("eval_every") is not None:
            return taken if "eval_return" in taken.result.metrics else None
        return taken


def _shown_progress(settings: dict[str, Any]) -> bool:
    """Whether the study prints its plan, each look's groups and each decision on stderr: where
    its sweeps show progress as lines or a bar (``progress=True``), not where a callable takes
    it."""
    shown = settings.get("progress", False)
    return isinstance(shown, bool | np.bool_) and bool(shown)


def _check_arguments(
    endpoint: str,
    groups: int | None,
    chunk: int | None,
    part: tuple[int, int] | None,
    settings: dict[str, Any],
) -> None:
    if endpoint not in ENDPOINTS:
        raise InvalidInput(f"a study decides on {', '.join(ENDPOINTS)}, got endpoint {endpoint!r}")
    if endpoint == "eval" and settings.get("eval_every") is None:
        raise InvalidInput(
            "the eval endpoint is the deterministic policy's return in evaluations: give "
            "eval_every (--eval-every) so that the study's runs are evaluated"
        )
    if groups is not None and (
        isinstance(groups, bool) or not isinstance(groups, int | np.integer) or groups < 0
    ):
        raise InvalidInput(f"groups must be a count of groups (0 or more), got {groups!r}")
    if chunk is not None:
        positive_int("chunk", chunk)
    if part is not None:  # its shape: a group's runs, which it shares, are known at its look
        check_part(part)
    if "variant" in settings:
        raise InvalidInput("a study's variants are its candidates and its baseline, not variant")
    taken = sorted(set(OWN_SETTINGS) & set(settings))
    if taken:
        raise InvalidInput(f"a study sets {', '.join(taken)} itself, for each group's sweep")


def _planned_settings(settings: dict[str, Any]) -> dict[str, Any]:
    """What the plan records of the settings: all but how runs are driven, and the
    evaluations' where the runs are evaluated (they make the eval endpoint)."""
    evaluated = settings.get("eval_every") is not None
    recorded = {k: v for k, v in settings.items() if k not in Options.names()}
    return {**recorded, **{k: settings[k] for k in EVALUATION if evaluated and k in settings}}


def _checked_settings(
    task: str,
    everyone: list[Surrogate],
    settings: dict[str, Any],
    shape: dict[str, Any],
    tuned: dict[str, dict[str, Any]] | None = None,
) -> tuple[RunRecord, dict[str, dict[str, Any]]]:
    """Every setting of `task` checked before the plan is written, as a sweep checks them; and
    what a recorded run must match to be reused: the protocol, and each variant's setting (its
    `tuned` one, where a tune chose it)."""
    run = prepare(task, dict(settings), sweepable(everyone), **shape)
    several = [k for k, v in run.hyperparameters.items() if isinstance(v, list | tuple)]
    if several:
        raise InvalidInput(
            f"a study compares one setting per variant: give {', '.join(several)} one value "
            "each (to compare values, sweep them: fppo_jax.sweep)"
        )
    by_name = {s.name: s for s in everyone}
    if tuned is None:
        grid = expand_grid({"variant": everyone, **run.hyperparameters}, task)
    else:
        grid = expand_grid([{"variant": s, **tuned[s.name]} for s in everyone], task)
    for setting in grid:
        values = {k: v for k, v in setting.items() if k != "variant"}
        resolve_hyperparameters(by_name[setting["variant"]], None, **values)
    return run.record(), {s["variant"]: s for s in grid}


def tuned_settings(
    directory: str | Path,
    tasks: list[str],
    everyone: list[Surrogate],
    design: Design,
    settings: dict[str, Any],
    across_tasks: bool = False,
    with_defaults: bool = False,
) -> dict[str, Any]:
    """What a study on a tune's chosen settings records of the tune in `directory`: where it is,
    its plan's digest, its tuning seeds and each variant's chosen setting on each task (with
    `across_tasks`, the trial chosen for all the tune's tasks, and the rule); refused if the
    tune is not finished, lacks a task or a variant, or used a seed the study would, or, with
    `with_defaults`, if a trial 0 is not the default this code trains."""
    from fppo_jax.analysis.tuning import PLAN_FILE as TUNE_PLAN
    from fppo_jax.analysis.tuning import RESULTS_FILE, plan_digest

    directory = Path(directory)
    digest = plan_digest(directory)
    results_path = directory / RESULTS_FILE
    if not results_path.exists():
        raise InvalidInput(
            f"the tune in {directory} is not finished ({RESULTS_FILE} is missing): run it to "
            "the end first"
        )
    tune_plan = json.loads((directory / TUNE_PLAN).read_text())
    results = json.loads(results_path.read_text())
    given = sorted(set(settings) & set(sweepable(everyone)))
    if given:
        raise InvalidInput(
            f"a study on a tune's settings takes each arm's from the tune: {', '.join(given)} "
            "cannot be given beside it"
        )
    for task in tasks:
        if task not in results:
            raise InvalidInput(f"the tune in {directory} did not tune {task}")
    for variant in everyone:
        if variant.name not in tune_plan["variants"]:
            raise InvalidInput(f"the tune in {directory} did not tune {variant.name}")
    trials = _across_tasks(directory, tune_plan, results, everyone) if across_tasks else None
    chosen: dict[str, dict[str, Any]] = {}
    for task in tasks:
        for variant in everyone:
            found = results[task][variant.name]
            if with_defaults:
                _check_trial_0(directory, task, variant, found["default"]["setting"])
            if trials is not None:
                setting = found["trials"][trials[variant.name]["trial"]]
            elif found["chosen"] is None:
                raise InvalidInput(
                    f"the tune in {directory} chose no setting for {variant.name} on {task}: "
                    "every trial diverged"
                )
            else:
                setting = found["chosen"]["setting"]
            chosen.setdefault(task, {})[variant.name] = setting
    overlap = sorted(set(tune_plan["seeds"]) & set(range(design.max_seeds)))
    if overlap:
        raise InvalidInput(
            f"the tune in {directory} used seeds {overlap} that this study would test on: a "
            "test needs seeds the tune never saw (tune on others)"
        )
    return {
        "directory": str(directory.absolute()),
        "plan_digest": digest,
        "tuning_seeds": tune_plan["seeds"],
        "protocol": {task: tune_plan["protocol"][task] for task in tasks},
        # recorded only where chosen across tasks: a plan from before the option is one without
        **({} if trials is None else {"selection": ACROSS_TASKS, "trials": trials}),
        "settings": chosen,
    }


def _across_tasks(
    directory: Path,
    tune_plan: dict[str, Any],
    results: dict[str, Any],
    everyone: list[Surrogate],
) -> dict[str, dict[str, Any]]:
    """Each variant's trial chosen for all the tune's tasks by the rule of
    :func:`~fppo_jax.analysis.tuning_report.across_tasks` (its trial, rung and mean normalised
    score), from the rungs' scores the tune recorded; refused for a tune of one task, one whose
    ``results.json`` lacks the trials' settings, and a variant no trial of which scored on
    every task."""
    from fppo_jax.analysis.tuning_report import across_tasks
    from fppo_jax.analysis.tuning_rungs import recorded_rungs

    tuned = tune_plan["tasks"]
    if len(tuned) < 2:
        raise InvalidInput(
            f"the tune in {directory} tuned one task ({tuned[0]}): a setting chosen across "
            "tasks needs several (without across_tasks the setting is its best on that task)"
        )
    if any("trials" not in arms[v.name] for arms in results.values() for v in everyone):
        raise InvalidInput(
            f"the tune in {directory} did not record each trial's setting (its results.json "
            "is from an earlier version): run the same tune command again, which trains nothing "
            "and records them"
        )
    rungs = {task: recorded_rungs(directory / task) for task in tuned}
    trials = {}
    for variant in everyone:
        found = across_tasks(rungs, variant.name)
        if found is None:
            raise InvalidInput(
                f"no trial of {variant.name} scored on every task of the tune in {directory} "
                "(each diverged or finished no episode on one): no setting can be chosen across "
                "them"
            )
        trials[variant.name] = found
    return trials


def _check_trial_0(directory: Path, task: str, variant: Surrogate, trial_0: dict[str, Any]) -> None:
    """Refuses a tune whose trial 0 of `variant` on `task` is not the default setting that the
    study trains beside the tuned one (defaults changed since the tune): the gain from tuning
    would be measured over another setting than the tune's."""
    tuned = resolve_hyperparameters(variant, task, **trial_0)[1]
    here = resolve_hyperparameters(variant, task)[1]
    differs = [k for k in here if tuned.get(k) != here[k]]
    if differs:
        key = differs[0]
        raise InvalidInput(
            f"the tune in {directory} tried {variant.name}'s default on {task} with {key} = "
            f"{tuned.get(key)!r}, and this code's default is {here[key]!r}: its trial 0 is not "
            "the default that with_defaults would train; tune again with this code"
        )


def _check_tuned_protocol(directory: str | Path, source: _Source) -> None:
    """The study's runs trained as the tune's were (the task's shape, backend and budget): a
    setting tuned for one protocol says little of another."""
    assert source.tuned is not None
    for task, (protocol, _) in source.expected.items():
        what = f"the tune's protocol of {task} in {directory}"
        tuned = RunRecord.from_json(source.tuned["protocol"][task], what)
        differing = tuned.differences(protocol, "in the tune", "in this study")
        if differing:
            raise InvalidInput(
                f"the tune in {directory} trained {task} under another protocol than this "
                f"study ({'; '.join(differing)}): test a tuned setting under its own protocol"
            )


def names_of_tasks(tasks: str | Sequence[str], what: str = "a study") -> list[str]:
    """`tasks`, one name or several, checked: named, and each once (`what` is whose they are)."""
    tasks = [tasks] if isinstance(tasks, str) else list(tasks)
    if not tasks or not all(isinstance(task, str) and task for task in tasks):
        raise InvalidInput(f"{what}'s tasks are named tasks (fppo-jax list), got {tasks!r}")
    if len(set(tasks)) < len(tasks):
        raise InvalidInput(f"a task is named twice among {', '.join(tasks)}")
    return tasks


def _variants(candidates: Any, baseline: str | Surrogate) -> tuple[list[Surrogate], Surrogate]:
    """The candidates and the baseline resolved (a name or a surrogate each), checked."""
    one = isinstance(candidates, str | Surrogate)
    candidates = [resolve(c) for c in ([candidates] if one else candidates)]
    baseline = resolve(baseline)
    if not candidates:
        raise InvalidInput("a study needs at least one candidate")
    union([*candidates, baseline])  # two different surrogates under one name are refused
    names = [c.name for c in candidates]
    if baseline.name in names:
        raise InvalidInput(f"the baseline {baseline.name} is also a candidate")
    if len(set(names)) < len(names):
        raise InvalidInput(f"a candidate is named twice among {', '.join(names)}")
    return candidates, baseline


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


def make_plan(
    tasks: list[str],
    candidates: list[Surrogate],
    baseline: Surrogate,
    design: Design,
    endpoint: str,
    settings: dict[str, Any],
    reuse: list[str],
) -> dict[str, Any]:
    """What ``plan.json`` records: the preregistration, decided before any run."""
    return cast(
        dict[str, Any],
        json_value(
            {
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
                    e
                    for e in ENDPOINTS
                    if e != endpoint and (e != "eval" or "eval_every" in settings)
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
                **({"reuse": reuse} if reuse else {}),
                **identities([*candidates, baseline]),
                "commit": commit(),
            }
        ),
    )


def _equivalence_plan(design: Design) -> dict[str, Any]:
    """What the plan records of the equivalence test: nothing without a margin (a plan
    recorded before margins existed is one without), else the margin and the test."""
    if design.margin is None:
        return {}
    return {"margin": design.margin, "equivalence_test": EQUIVALENCE_TEST}


def _fractions(design: Design) -> tuple[float, ...]:
    return tuple(n / design.max_seeds for n in design.looks)


def check_plan(
    output: Path,
    plan: dict[str, Any],
    what: str = "a study",
    name: str = PLAN_FILE,
    recorded_only: frozenset[str] = frozenset({"commit"}),
) -> dict[str, Any]:
    """Write `plan` as `name` in `output`, or check it against the one there: `what` (a study,
    a tune) goes on only under the plan it started with, the fields in `recorded_only` aside
    (the commit: a group records its own). Returns the plan as recorded, with the commit it was
    made at."""
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
    return cast(dict[str, Any], recorded)


def _shown(value: Any) -> str:
    return "none" if value is None else json.dumps(value)


def sweep_group(
    task: str,
    grid: dict[str, Any] | list[dict[str, Any]],
    seeds: list[int],
    where: Path,
    part: tuple[int, int] | None = None,
    **settings: Any,
) -> SweepResult:
    """One group: the settings of `grid` × `seeds` on `task` as one sweep that records itself
    in `where` (or its `part`, in ``where/part-<K>``), read back from there (as a resumed study
    reads it).
    One cut short (a killed study) is trained again; a group whose shares array tasks began is
    not trained whole over them."""
    if part is None:
        refuse_missing_shares(where)
    else:
        where = where / f"part-{part[0]}"
    if where.exists():
        shutil.rmtree(where)
    sweep(task, grid, seeds, log_dir=where, part=part, **settings)
    return SweepResult.read(where)


def recorded_group(
    where: Path, variants: list[Surrogate], seeds: list[int], part: tuple[int, int] | None = None
) -> SweepResult | None:
    """The group in `where` if it holds every run of `variants` × `seeds`, whole or joined from
    the shares that array tasks recorded in ``part-<K>/``; with `part`, that share alone, if it
    holds all its runs. None if it holds none or some of them. A group of other runs is
    refused: the plan did not make it."""
    runs = len(variants) * len(seeds)
    if part is not None:
        where = where / f"part-{part[0]}"
    found = [SweepResult.read(where)] if (where / "sweep.json").exists() else []
    shares = sorted(where.glob("part-*/sweep.json"))
    if shares:
        try:
            found.append(merge([SweepResult.read(share.parent) for share in shares]))
        except InvalidInput:  # some shares are still to come
            pass
    for result in found:  # a group trained whole and cut short may have been finished in shares
        names = [s["variant"] for s in result.settings]
        if names != [v.name for v in variants] or result.config["seeds"] != seeds:
            raise InvalidInput(
                f"{where} holds a group of {', '.join(names)} on seeds {result.config['seeds']}, "
                f"where the study's plan needs {', '.join(v.name for v in variants)} on {seeds}"
            )
        expected = runs
        if part is not None:  # the share of the group's runs, by the groups they trained in
            size = result.config.get("runs_per_call")
            if not isinstance(size, int) or size < 1:
                continue
            start, stop = part_runs(part, runs, size)
            expected = stop - start
        if len(result.runs) == expected:
            return result
    return None


def refuse_missing_shares(where: Path) -> None:
    """Raise if the group in `where`, not recorded whole, holds some of the shares that array
    tasks train (``part-<K>/``), naming what joining them says is missing: trained whole over
    them, or decided without them, the shares would be lost."""
    shares = sorted(where.glob("part-*/sweep.json"))
    if not shares:
        return
    try:
        merge([SweepResult.read(share.parent) for share in shares])
    except InvalidInput as error:
        raise InvalidInput(
            f"{where} holds shares of its runs trained by array tasks (--part), and not all of "
            f"them: {error}. Run the missing ones with --part K/N, then this again"
        ) from None


def _runs_of(result: SweepResult, variant: str) -> list[int]:
    """`variant`'s runs in `result` (indices), in seed order."""
    index = [s["variant"] for s in result.settings].index(variant)
    runs = [i for i, run in enumerate(result.runs) if run["setting"] == index]
    return sorted(runs, key=lambda i: result.runs[i]["seed"])


def run_scores(result: SweepResult, variant: str, endpoint: str) -> np.ndarray:
    """`variant`'s score per run in `result`, in seed order; a run that diverged or finished no
    episode (or, for ``eval``, no evaluation) scores −inf, below every other (a run that
    failed)."""
    runs = _runs_of(result, variant)
    metric = "eval_return" if endpoint == "eval" else "average_return"
    if metric not in result.metrics:
        raise InvalidInput(
            f"the eval endpoint needs every run's evaluations, and {variant}'s runs on "
            f"{result.config['env']} have none: runs taken from recorded sweeps (reuse) that "
            "were not evaluated cannot be scored on it"
        )
    scores = statistics.endpoint(result.metrics[metric][runs], endpoint)
    failed = (np.asarray(result.diverged)[runs] > 0) | ~np.isfinite(scores)
    return np.where(failed, -np.inf, scores)


@dataclasses.dataclass(frozen=True)
class _Group:
    """A task's group of seeds at one look, of the study's settings or (`defaults`) of each
    arm's default beside them: the `variants` still to train in `where` from `source`
    (`result`: the group recorded there already, whole) and the runs `taken` from recorded
    sweeps."""

    task: str
    look: int
    seeds: list[int]
    variants: list[Surrogate]
    where: Path
    result: SweepResult | None
    taken: dict[str, Taken]
    source: _Source
    defaults: bool

    @property
    def to_train(self) -> bool:
        return bool(self.variants) and self.result is None


def _run(
    output: Path,
    plan: dict[str, Any],
    tasks: list[str],
    candidates: list[Surrogate],
    baseline: Surrogate,
    design: Design,
    groups: int | None,
    source: _Source,
) -> StudyResult:
    """The looks: each task's next group while some comparison awaits seeds, then the rule.
    With ``source.part``, the first look whose groups are not all recorded has this share of
    them trained, and the call returns there, writing no decision."""
    recorded: dict[str, list[SweepResult]] = {task: [] for task in tasks}
    defaults: dict[str, list[SweepResult]] = {task: [] for task in tasks}  # with_defaults
    trained: list[dict[str, Any]] = []
    shown = _shown_progress(source.settings)
    endpoint = plan["primary_endpoint"]
    decisions = _decide(recorded, tasks, candidates, baseline, design, endpoint)
    for look, seeds in enumerate(design.looks):
        waiting = {key for key, d in decisions.items() if d.decision is None}
        if not waiting:
            break
        group_seeds = list(range(design.looks[look - 1] if look else 0, seeds))
        found = [
            _group(output, source, task, look, group_seeds, [*variants, baseline], beside)
            # each arm's default at the same looks, on the same seeds, as its tuned setting
            for beside in ((False, True) if source.defaults else (False,))
            for task in tasks
            # the baseline only while one of its task's candidates waits
            if (variants := [c for c in candidates if (task, c.name) in waiting])
        ]
        to_train = [group for group in found if group.to_train]
        if source.part is not None and to_train:
            for group in to_train:
                if recorded_group(group.where, group.variants, group.seeds, source.part) is None:
                    if shown:
                        _say(_training_line(group, len(design.looks), source.part))
                    group.source.train(group.task, group.variants, group.seeds, group.where)
            return StudyResult(plan, _rows(decisions, baseline), {}, False)
        for group in to_train if source.part is None else []:
            refuse_missing_shares(group.where)
        looks_trained = len({entry["group"] for entry in trained if "commit" in entry})
        if to_train and groups is not None and looks_trained >= groups:
            break
        for group in found:
            if shown:
                _say(_training_line(group, len(design.looks)))
            if entry := _gather(group, defaults if group.defaults else recorded):
                trained.append(entry)
        before = decisions
        decisions = _decide(recorded, tasks, candidates, baseline, design, endpoint)
        if shown:
            for (task, name), decision in decisions.items():
                if decision.decision is not None and before[task, name].decision is None:
                    _say(_decision_line(task, name, baseline.name, decision))
        if source.part is None:  # an array task writes no decision: the job after the array does
            _write_decisions(output, decisions, baseline, trained, plan)  # a killed one keeps them
            for where, runs in ((output, recorded), (output / DEFAULTS, defaults)):
                _write_merged(where, runs, [group.task for group in found])
    return _finish(output, plan, recorded, defaults, decisions, baseline, trained, source.part)


def _say(line: str) -> None:
    """A line of the study's progress, on stderr."""
    print(f"study: {line}", file=sys.stderr, flush=True)


def _training_line(group: _Group, looks: int, part: tuple[int, int] | None = None) -> str:
    """What a look does on a task: the seeds it trains, of which settings, and those taken."""
    seeds = f"seeds {group.seeds[0]}–{group.seeds[-1]}"
    task = f"{group.task}, defaults" if group.defaults else group.task
    said = []
    if group.to_train:
        share = "" if part is None else f" (part {part[0]} of {part[1]})"
        said.append(f"training {seeds} of {', '.join(v.name for v in group.variants)}{share}")
    elif group.variants:
        said.append(f"{seeds} of {', '.join(v.name for v in group.variants)} recorded already")
    if group.taken:
        said.append(f"{seeds} of {', '.join(group.taken)} taken from recorded sweeps")
    return f"look {group.look + 1} of {looks}, {task}: {'; '.join(said)}"


def _decision_line(task: str, candidate: str, baseline: str, decision: Decision) -> str:
    return (
        f"{task}: {candidate} against {baseline}: {decision.decision} with {decision.seeds} "
        f"seeds ({decision.reason})"
    )


def _write_merged(output: Path, recorded: dict[str, list[SweepResult]], tasks: list[str]) -> None:
    """Each of `tasks`' runs so far as one sweep, ``<task>/curves.csv`` and ``sweep.json``
    merged over its groups (:func:`~fppo_jax.merge`: one ``run`` numbering, where each group's
    restarts), beside the groups; not for a task whose runs were all taken from recorded
    sweeps (it has no directory in the study's)."""
    for task in dict.fromkeys(tasks):
        where = output / _directory_name(task)
        if recorded[task] and where.is_dir():
            merge(recorded[task]).write(where)


def _group(
    output: Path,
    source: _Source,
    task: str,
    look: int,
    seeds: list[int],
    variants: list[Surrogate],
    defaults: bool = False,
) -> _Group:
    """`task`'s group at `look` (with `defaults`, of each arm's default, in ``defaults/``): of
    `variants`, those whose runs `source` takes from recorded sweeps, and the others, to train
    in the study's own directory unless recorded there."""
    if defaults:
        source, output = cast(_Source, source.defaults), output / DEFAULTS
    taken = {v.name: t for v in variants if (t := source.take(task, v, seeds))}
    variants = [v for v in variants if v.name not in taken]
    where = output / _directory_name(task) / f"group-{look + 1}"
    result = recorded_group(where, variants, seeds) if variants else None
    differences = protocol_differences(result.config, source.expected[task][0]) if result else []
    if differences:
        raise InvalidInput(
            f"{where} was trained under another protocol than this call would train "
            f"({'; '.join(differences)}): a study's groups share one protocol. Go on on a "
            "machine that trains as this one did (a plan's backend auto is chosen by the machine)"
        )
    return _Group(task, look, seeds, variants, where, result, taken, source, defaults)


def _gather(group: _Group, recorded: dict[str, list[SweepResult]]) -> dict[str, Any] | None:
    """`group`'s runs added to `recorded`, trained first where they are not recorded; what
    ``decisions.json`` says of the group (None when it was recorded by an earlier call)."""
    said: dict[str, Any] = {}
    result = group.result
    if group.to_train:
        result = group.source.train(group.task, group.variants, group.seeds, group.where)
        said["commit"] = commit()
    if result is not None:
        recorded[group.task].append(result)
    recorded[group.task] += [t.result for t in group.taken.values()]
    if group.taken:
        said["reused"] = {name: [str(s) for s in t.sources] for name, t in group.taken.items()}
    if not said:
        return None
    of = {"defaults": True} if group.defaults else {}
    return {"task": group.task, "group": group.look + 1, **of, "seeds": group.seeds, **said}


def _finish(
    output: Path,
    plan: dict[str, Any],
    recorded: dict[str, list[SweepResult]],
    defaults: dict[str, list[SweepResult]],
    decisions: dict[tuple[str, str], Decision],
    baseline: Surrogate,
    trained: list[dict[str, Any]],
    part: tuple[int, int] | None,
) -> StudyResult:
    """The study as it stands; unless this call trained a `part`, its decisions, report and
    figures written, with the comparisons of each arm's default beside them where the plan
    trains them."""
    results = {task: merge(parts) for task, parts in recorded.items() if parts}
    at_defaults = {task: merge(parts) for task, parts in defaults.items() if parts}
    if part is not None:
        rows = _rows(decisions, baseline)
        return StudyResult(plan, rows, results, all(row["final"] for row in rows), at_defaults)
    scores = {task: _task_scores(result, plan) for task, result in results.items()}
    variants, endpoint = (*plan["candidates"], plan["baseline"]), plan["primary_endpoint"]
    beside = None
    if plan.get("with_defaults"):
        default_scores = {
            task: {v: run_scores(result, v, endpoint) for v in variants}
            for task, result in at_defaults.items()
        }
        beside = beside_defaults(plan, scores, default_scores)
    rows = _write_decisions(output, decisions, baseline, trained, plan, beside)
    finished = all(row["final"] for row in rows)
    write_report(output / REPORT_FILE, plan, rows, scores, finished, beside)
    write_figures(output, plan, rows, results, scores)
    return StudyResult(plan, rows, results, finished, at_defaults)


def _task_scores(result: SweepResult, plan: dict[str, Any]) -> Scores:
    """What the report shows of a task's runs: each variant's scores by endpoint, and its env
    steps to each share of the baseline's final IQM (``steps to 50%``; none where that IQM is
    not positive, where a share of it is no lower bar)."""
    variants = (*plan["candidates"], plan["baseline"])
    shown = ("final", plan["primary_endpoint"], *plan["secondary_endpoints"], REPORTED)
    scores = {v: {e: run_scores(result, v, e) for e in dict.fromkeys(shown)} for v in variants}
    for variant in variants:  # where each run starts: the untrained policy's first return
        curves = result.metrics["average_return"][_runs_of(result, variant)]
        scores[variant][START] = np.array([_first_finite(row) for row in curves])
    final = scores[plan["baseline"]]["final"]
    target = float(statistics.iqm(final[np.isfinite(final)]))
    if not target > 0:
        return scores
    for variant in variants:
        runs = _runs_of(result, variant)
        curves, steps = result.metrics["average_return"][runs], result.metrics["env_steps"][runs]
        for share in SHARES:
            reached = statistics.steps_to_threshold(curves, steps, share * target)
            scores[variant][steps_name(share)] = reached
    return scores


def _first_finite(curve: np.ndarray) -> float:
    finite = curve[np.isfinite(curve)]
    return float(finite[0]) if finite.size else np.nan


def _directory_name(task: str) -> str:
    """A task's directory in the study: its name, a namespace's slash made a double underscore."""
    return task.replace("/", "__")


def _decide(
    recorded: dict[str, list[SweepResult]],
    tasks: list[str],
    candidates: list[Surrogate],
    baseline: Surrogate,
    design: Design,
    endpoint: str,
) -> dict[tuple[str, str], Decision]:
    """The rule on every comparison's scores so far (seeds in order, group after group)."""
    keys = [(task, c.name) for task in tasks for c in candidates]
    scores = []
    for task, candidate in keys:
        pair = []
        for variant in (candidate, baseline.name):
            parts = [
                run_scores(group, variant, endpoint)
                for group in recorded[task]
                if variant in [s["variant"] for s in group.settings]
            ]
            pair.append(np.concatenate(parts) if parts else np.zeros(0))
        scores.append(tuple(pair))
    # each of `scores` is a (candidate, baseline) pair
    return dict(
        zip(keys, decide(cast("list[tuple[np.ndarray, np.ndarray]]", scores), design), strict=True)
    )


def _rows(decisions: dict[tuple[str, str], Decision], baseline: Surrogate) -> list[dict[str, Any]]:
    return [
        {
            "task": task,
            "candidate": candidate,
            "baseline": baseline.name,
            "decision": decision.decision or "undecided",
            "final": decision.decision is not None,
            "seeds": decision.seeds,
            "z": decision.z if np.isfinite(decision.z) else None,
            "boundary": decision.boundary if np.isfinite(decision.boundary) else None,
            "reason": decision.reason,
            # with a margin: the repeated CI of P that the equivalence test held against it
            **({} if decision.interval is None else {"interval": list(decision.interval)}),
        }
        for (task, candidate), decision in decisions.items()
    ]


def _write_decisions(
    output: Path,
    decisions: dict[tuple[str, str], Decision],
    baseline: Surrogate,
    trained: list[dict[str, Any]],
    plan: dict[str, Any],
    beside: dict[str, Any] | None = None,
) -> list[dict[str, Any]]:
    """``decisions.json``: the plan's margin where it has one, a row per comparison
    (returned), what each arm's default measured `beside` them (untested, where given), and
    every group trained with the commit it ran at, or with the recorded sweeps its runs were
    taken from, earlier calls' groups kept."""
    path = output / DECISIONS_FILE
    earlier = json.loads(path.read_text()).get("groups", []) if path.exists() else []
    by_group = {(g["task"], g["group"], g.get("defaults", False)): g for g in earlier}
    for entry in trained:  # a group trained earlier keeps its commit when runs are taken now
        key = (entry["task"], entry["group"], entry.get("defaults", False))
        by_group[key] = {**by_group.get(key, {}), **entry}
    groups = list(by_group.values())
    rows = _rows(decisions, baseline)
    record = {
        "finished": all(row["final"] for row in rows),
        **({"margin": plan["margin"]} if "margin" in plan else {}),
        "comparisons": rows,
        **({} if beside is None else {"beside_defaults": beside}),
        "groups": sorted(groups, key=lambda g: (g["group"], g.get("defaults", False), g["task"])),
    }
    write_json(path, record)
    return rows
