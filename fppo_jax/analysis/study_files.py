"""A study's folder, and the one way to read it back: ``plan.json`` (read as this version
records it, :func:`~fppo_jax.analysis.study_plan.upgraded`), ``decisions.json``, and each
task's groups of runs, ``<task>/group-<k>/`` (whole, or joined from the shares that array
tasks recorded in ``part-<K>/``), with each arm's default beside them in ``defaults/``. Every
file is held to its shape (:mod:`fppo_jax.analysis.study_plan`): a file cut short or edited is
named, never read as a ``KeyError``. :func:`load_study` is the public reader."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path
from typing import cast

from fppo_jax.analysis.arms import task_folder
from fppo_jax.analysis.reuse import runs_alone
from fppo_jax.analysis.study_plan import (
    DECISIONS_FILE,
    PLAN_FILE,
    DecisionRow,
    Decisions,
    GroupEntry,
    StudyPlan,
    upgraded,
)
from fppo_jax.analysis.study_shapes import Shape, TaskRuns, merged, shape_folder
from fppo_jax.errors import InvalidInput, MissingFile
from fppo_jax.run.merge import merge
from fppo_jax.run.results import SweepResult
from fppo_jax.store.artifact import check_shape, read_record, read_typed

# Where each arm's default setting trains beside its tuned one (with_defaults), by task and group.
DEFAULTS = "defaults"


@dataclasses.dataclass
class StudyResult:
    """What a study holds so far: its `plan` (as ``plan.json`` has it), one row per comparison
    in `decisions` (as ``decisions.json`` has them), each task's recorded runs merged into one
    sweep (`results`, by task; one per run shape, where a tune chose its arms' shapes:
    :class:`~fppo_jax.analysis.study_shapes.ShapedRuns`), whether every comparison is
    `finished`, and with ``with_defaults`` each task's runs of each arm's default setting
    (`defaults`, by task)."""

    plan: StudyPlan
    decisions: list[DecisionRow]
    results: dict[str, TaskRuns]
    finished: bool
    defaults: dict[str, TaskRuns] = dataclasses.field(default_factory=dict)


def group_folder(
    study: Path, task: str, group: int, defaults: bool = False, shape: Shape = ()
) -> Path:
    """Where group `group` (from 1) of `task` in run shape `shape` is recorded in the study in
    `study`."""
    where = study / (DEFAULTS if defaults else "") / task_folder(task) / shape_folder(shape)
    return where / f"group-{group}"


def read_plan(directory: Path) -> StudyPlan:
    """The study's plan in `directory`, in this version's form, checked."""
    what, path = f"the study's plan in {directory}", directory / PLAN_FILE
    if not path.is_file():
        raise MissingFile(f"{directory} holds no study ({PLAN_FILE} is missing)")
    plan = upgraded(read_record(path, what, 1))
    check_shape(plan, StudyPlan, path, what)
    return cast(StudyPlan, plan)  # its shape checked just above


def read_decisions(directory: Path) -> Decisions | None:
    """The study's ``decisions.json`` in `directory`, checked; None before its first look."""
    path = directory / DECISIONS_FILE
    if not path.exists():
        return None
    found: Decisions = read_typed(path, Decisions, f"the study's decisions in {directory}")
    return found


def load_study(directory: str | Path) -> StudyResult:
    """The study recorded in `directory` by :func:`~fppo_jax.study` (finished or not), every
    file checked: its plan, its decisions and each task's runs at every group recorded, those
    taken from recorded sweeps too (read from the sweeps its ``decisions.json`` names, a
    relative path from the working directory or the nearest folder above the study that holds
    it); :class:`~fppo_jax.errors.MissingFile` where it holds no study."""
    directory = Path(directory)
    plan, decisions = read_plan(directory), read_decisions(directory)
    if decisions is None:
        return StudyResult(plan, [], {}, False)
    runs: dict[tuple[str, bool], list[SweepResult]] = {
        (task, defaults): [] for defaults in (False, True) for task in plan["tasks"]
    }
    for entry in decisions["groups"]:
        key = (entry["task"], entry.get("defaults", False))
        runs[key] += _group_runs(directory, entry)
    found = {key: merged(parts) for key, parts in runs.items() if parts}
    return StudyResult(
        plan,
        decisions["comparisons"],
        {task: result for (task, defaults), result in found.items() if not defaults},
        decisions["finished"],
        {task: result for (task, defaults), result in found.items() if defaults},
    )


def _group_runs(study: Path, entry: GroupEntry) -> list[SweepResult]:
    """The runs of one group that ``decisions.json`` lists: those recorded in the study's own
    folder (whole or joined from its shares), and those taken from recorded sweeps."""
    shape = tuple(sorted(entry.get("shape", {}).items()))
    where = group_folder(study, entry["task"], entry["group"], entry.get("defaults", False), shape)
    found = []
    if (where / "sweep.json").is_file():
        found.append(SweepResult.read(where))
    elif shares := sorted(where.glob("part-*/sweep.json")):
        found.append(merge([SweepResult.read(share.parent) for share in shares]))
    elif "commit" in entry or "shares" in entry:
        raise MissingFile(f"{where} is missing: the study's decisions name its runs")
    for variant, sources in entry.get("reused", {}).items():
        found.append(_taken(study, variant, entry["seeds"], sources))
    return found


def _taken(study: Path, variant: str, seeds: Sequence[int], sources: list[str]) -> SweepResult:
    """`variant`'s runs at `seeds` from the recorded sweeps `sources`, one run a seed."""
    parts = []
    for source in sources:
        recorded = SweepResult.read(_located(study, source))
        runs = [
            run
            for run, entry in enumerate(recorded.runs)
            if recorded.settings[entry["setting"]]["variant"] == variant and entry["seed"] in seeds
        ]
        if runs:
            parts.append(runs_alone(recorded, runs))
    result = merge(parts) if parts else None
    got = sorted(run["seed"] for run in result.runs) if result is not None else []
    if got != sorted(seeds):
        raise InvalidInput(
            f"the sweeps {', '.join(sources)} do not hold one run of {variant} at each of seeds "
            f"{list(seeds)}, as the study in {study} records that they did"
        )
    assert result is not None
    return result


def _located(study: Path, source: str) -> Path:
    """`source`, a recorded sweep's directory as ``decisions.json`` names it: as it is, or
    relative to the nearest folder above the study that holds it."""
    for base in (Path.cwd(), *study.absolute().parents):
        if (base / source).is_dir():
            return base / source
    raise MissingFile(
        f"the recorded sweep {source}, whose runs the study in {study} took, is missing"
    )
