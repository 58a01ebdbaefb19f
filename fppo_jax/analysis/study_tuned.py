"""A study on a tune's settings (``study(..., tuned=...)``): each arm's chosen setting per
task or across tasks, read from the tune and checked against the study's own protocol and
seeds."""

from __future__ import annotations

from collections.abc import Collection, Mapping
from pathlib import Path
from typing import Any

from fppo_jax.analysis.study_plan import TunedChoice
from fppo_jax.analysis.study_runs import Source
from fppo_jax.analysis.tune_files import PLAN_FILE as TUNE_PLAN
from fppo_jax.analysis.tune_files import RESULTS_FILE, TuneResult, load_tune, tune_digest
from fppo_jax.analysis.tuning_records import TrialAcrossTasks
from fppo_jax.analysis.tuning_report import across_tasks as trial_across_tasks
from fppo_jax.core.config import Setting
from fppo_jax.core.objectives import identities
from fppo_jax.core.resolution import resolve_hyperparameters, sweepable
from fppo_jax.core.surrogates import Surrogate, SurrogateIdentity
from fppo_jax.errors import InvalidInput
from fppo_jax.stats.sequential import Design
from fppo_jax.store.record import RunRecord

ACROSS_TASKS = (
    "across tasks: per arm, one trial for every task (a drawn trial is the same point on each; "
    "trial 0 is each task's default), chosen among the arm's trials that reached the deepest "
    "rung reached on every task by any of them: the best mean over the tune's tasks of its "
    "score at that rung, normalised per task by the min and max of every arm's trials scored "
    "there (a task where they all tie counts 0); ties by trial number; a trial's deepest rung "
    "on a task is the last where it scored and did not diverge "
    "(fppo_jax.analysis.tuning_report.across_tasks)"
)


def tuned_settings(
    directory: str | Path,
    tasks: list[str],
    everyone: list[Surrogate],
    design: Design,
    settings: Collection[str],
    across_tasks: bool = False,
    with_defaults: bool = False,
) -> TunedChoice:
    """What a study on a tune's chosen settings records of the tune in `directory`: where it is,
    its plan's digest, its tuning seeds and each variant's chosen setting on each task (with
    `across_tasks`, the trial chosen for all the tune's tasks, and the rule); refused if the
    tune is not finished, lacks a task or a variant, or used a seed the study would, or, with
    `with_defaults`, if a trial 0 is not the default this code trains."""
    directory = Path(directory)
    if directory.name == TUNE_PLAN and directory.is_file():  # the tune's plan named for it
        directory = directory.parent
    digest = tune_digest(directory)
    recorded = load_tune(directory)
    _check_surrogates(directory, recorded.plan.get("surrogates", {}), everyone)
    if not recorded.finished:
        raise InvalidInput(
            f"the tune in {directory} is not finished ({RESULTS_FILE} is missing): run it to "
            "the end first"
        )
    tune_plan, results = recorded.plan, recorded.results
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
    trials = _across_tasks(recorded, everyone) if across_tasks else None
    chosen: dict[str, dict[str, Setting]] = {}
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
            chosen.setdefault(task, {})[variant.name] = {**setting}
    validation = tune_plan["validation"]["seeds"] if "validation" in tune_plan else []
    overlap = (set(tune_plan["seeds"]) | set(validation)) & set(range(design.max_seeds))
    if overlap:
        raise InvalidInput(
            f"the tune in {directory} used seeds {sorted(overlap)} that this study would test "
            "on: a test needs seeds the tune never saw (tune and validate on others)"
        )
    where, protocol = str(directory.absolute()), {t: tune_plan["protocol"][t] for t in tasks}
    if trials is None:
        return {
            "directory": where,
            "plan_digest": digest,
            "tuning_seeds": tune_plan["seeds"],
            "protocol": protocol,
            "settings": chosen,
        }
    # The rule recorded only where chosen across tasks: a plan from before the option is one
    # without.
    return {
        "directory": where,
        "plan_digest": digest,
        "tuning_seeds": tune_plan["seeds"],
        "protocol": protocol,
        "selection": ACROSS_TASKS,
        "trials": trials,
        "settings": chosen,
    }


def _across_tasks(recorded: TuneResult, everyone: list[Surrogate]) -> dict[str, TrialAcrossTasks]:
    """Each variant's trial chosen for all the tune's tasks by the rule of
    :func:`~fppo_jax.analysis.tuning_report.across_tasks` (its trial, rung and mean normalised
    score), from the rungs' scores the tune recorded; refused for a tune of one task, one whose
    ``results.json`` lacks the trials' settings, and a variant no trial of which scored on
    every task."""
    directory, tuned = recorded.directory, recorded.plan["tasks"]
    if len(tuned) < 2:
        raise InvalidInput(
            f"the tune in {directory} tuned one task ({tuned[0]}): a setting chosen across "
            "tasks needs several (without across_tasks the setting is its best on that task)"
        )
    if any("trials" not in arms[v.name] for arms in recorded.results.values() for v in everyone):
        raise InvalidInput(
            f"the tune in {directory} did not record each trial's setting (its results.json "
            "is from an earlier version): run the same tune command again, which trains nothing "
            "and records them"
        )
    trials = {}
    for variant in everyone:
        found = trial_across_tasks(recorded.rungs, variant.name)
        if found is None:
            raise InvalidInput(
                f"no trial of {variant.name} scored on every task of the tune in {directory} "
                "(each diverged or finished no episode on one): no setting can be chosen across "
                "them"
            )
        trials[variant.name] = found
    return trials


def _check_surrogates(
    directory: Path, tuned: Mapping[str, SurrogateIdentity], everyone: list[Surrogate]
) -> None:
    """Refuses a surrogate of one's own that is not the one the tune tuned (another function or
    defaults under its name, or a built-in's name it had): its settings were tuned for that."""
    now = identities(everyone).get("surrogates", {})
    for variant in everyone:
        was, here = tuned.get(variant.name), now.get(variant.name)
        if _pinned(was) != _pinned(here):
            raise InvalidInput(
                f"the tune in {directory} tuned another {variant.name} than this code's "
                f"(digest {_shown(was)} then, {_shown(here)} now): its settings were tuned for "
                "that one; restore it, or tune this one"
            )


def _pinned(identity: SurrogateIdentity | None) -> object:
    """What makes a surrogate the one tuned: its function's digest and its defaults."""
    return None if identity is None else (identity["digest"], identity["hyperparameters"])


def _shown(identity: SurrogateIdentity | None) -> str:
    return "a built-in" if identity is None else repr(identity["digest"])


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


def check_tuned_protocol(directory: str | Path, source: Source) -> None:
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
