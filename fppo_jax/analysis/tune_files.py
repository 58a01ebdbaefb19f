"""A tune's folder, and the one way to read it back: ``tune.json`` (the plan), each task's
``<task>/rung-<r>/scores.json`` (and an array task's ``part-<K>/scores.json``), ``results.json``
when it is finished, ``report.md`` and Optuna's ``optuna.db``. Every file is read through
:func:`~fppo_jax.store.artifact.read_typed`, held to its shape in
:mod:`fppo_jax.analysis.tuning_records`: a file cut short or edited is named, never read as
a ``KeyError``. :func:`load_tune` is the public reader; a study on a tune's settings reads the
tune through it alone."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from fppo_jax.analysis.arms import task_folder
from fppo_jax.analysis.preregistration import plan_digest
from fppo_jax.analysis.tuning_records import ArmResults, RungScores, ShareScores, TunePlan
from fppo_jax.errors import InvalidInput
from fppo_jax.store.artifact import DamagedArtifact, read_typed

PLAN_FILE, RESULTS_FILE, REPORT_FILE, STORAGE_FILE = (
    "tune.json",
    "results.json",
    "report.md",
    "optuna.db",
)
SCORES_FILE, STATE_FILE = "scores.json", "state.npz"

# Per task, then arm: what results.json holds.
Results = dict[str, dict[str, ArmResults]]


def task_directory(directory: Path, task: str) -> Path:
    """Where a tune in `directory` records `task`'s rungs (a study's folder name for it)."""
    return directory / task_folder(task)


def rung_directory(folder: Path, rung: int) -> Path:
    """Where rung `rung` (from 0) of a task is recorded, in the task's `folder`."""
    return folder / f"rung-{rung}"


def read_plan(directory: Path) -> TunePlan:
    """The tune's plan in `directory`, checked."""
    found: TunePlan = read_typed(directory / PLAN_FILE, TunePlan, f"the tune's plan in {directory}")
    return found


def read_results(directory: Path, plan: TunePlan) -> Results:
    """A finished tune's ``results.json`` in `directory`, checked: of its shape, and holding
    every task and arm of its `plan`."""
    path = directory / RESULTS_FILE
    what = f"the tune's results in {directory}"
    found: Results = read_typed(path, Results, what)
    # Of the right shape but emptied ({}) or cut, it would read as a tune that left the task
    # out, and be refused for the wrong reason ("did not tune cartpole").
    missing = [
        f"{arm} on {task}" if task in found else task
        for task in plan["tasks"]
        for arm in (plan["variants"] if task in found else plan["variants"][:1])
        if task not in found or arm not in found[task]
    ]
    if missing:
        raise DamagedArtifact(
            f"{path} is not {what} as fppo-jax writes it: it lacks {', '.join(missing)}, which "
            f"the plan tunes; restore it, or remove it and run the tune again to write it"
        )
    return found


def read_rung(path: Path) -> RungScores:
    """A rung's ``scores.json`` at `path`, checked."""
    found: RungScores = read_typed(path, RungScores, "a rung's scores")
    return found


def read_share(path: Path) -> ShareScores:
    """A share's ``part-<K>/scores.json`` at `path`, checked."""
    found: ShareScores = read_typed(path, ShareScores, "a share's scores")
    return found


def recorded_rungs(folder: Path) -> list[RungScores]:
    """The scores of a task's rungs recorded in its `folder`, in order, up to the first rung
    not recorded."""
    found: list[RungScores] = []
    while (path := rung_directory(folder, len(found)) / SCORES_FILE).exists():
        found.append(read_rung(path))
    return found


def tune_digest(directory: Path) -> str:
    """The SHA-256 of a tune's plan, which a study on its settings records."""
    return plan_digest(Path(directory) / PLAN_FILE, "tune")


@dataclasses.dataclass
class TuneResult:
    """A tune in `directory`: its `plan` (``tune.json``), each task's recorded `rungs`
    (``scores.json``, in order), `results` (``results.json``: per task and arm, the chosen
    setting and what the rungs measured; only the finished tasks' while it runs) and whether it
    is `finished`."""

    directory: Path
    plan: TunePlan
    rungs: dict[str, list[RungScores]]
    results: Results
    finished: bool

    def chosen(self, task: str, arm: str) -> dict[str, Any]:
        """The setting chosen for `arm` on `task` (refused where every trial diverged)."""
        if task not in self.results or arm not in self.results[task]:
            raise InvalidInput(f"the tune in {self.directory} did not tune {arm} on {task}")
        chosen = self.results[task][arm]["chosen"]
        if chosen is None:
            raise InvalidInput(
                f"the tune in {self.directory} chose no setting for {arm} on {task}: every "
                "trial diverged"
            )
        return chosen["setting"]


def load_tune(directory: str | Path) -> TuneResult:
    """The tune recorded in `directory` by :func:`~fppo_jax.tune` (finished or not), every file
    checked against its shape; :class:`~fppo_jax.errors.MissingFile` where it holds no tune."""
    directory = Path(directory)
    plan = read_plan(directory)
    rungs = {task: recorded_rungs(task_directory(directory, task)) for task in plan["tasks"]}
    finished = (directory / RESULTS_FILE).is_file()
    results = read_results(directory, plan) if finished else {}
    return TuneResult(directory, plan, rungs, results, finished)
