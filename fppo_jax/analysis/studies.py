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
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from fppo_jax.analysis.arms import Variants, names_of_tasks, resolve_arms
from fppo_jax.analysis.preregistration import Preregistered
from fppo_jax.analysis.study_files import StudyResult
from fppo_jax.analysis.study_looks import run_looks, shown_progress
from fppo_jax.analysis.study_plan import ENDPOINTS, PLAN_FILE, make_plan, upgraded
from fppo_jax.analysis.study_runs import OWN_SETTINGS, Shape, Source
from fppo_jax.analysis.study_tuned import check_tuned_protocol, tuned_settings
from fppo_jax.analysis.tune_files import PLAN_FILE as TUNE_PLAN
from fppo_jax.analysis.tune_files import read_plan
from fppo_jax.analysis.tuning import tune as tune_every_arm
from fppo_jax.core.checks import check_part, positive_int
from fppo_jax.core.config import CONFIG_FIELDS
from fppo_jax.core.objectives import union
from fppo_jax.core.resolution import resolve
from fppo_jax.core.surrogates import Surrogate
from fppo_jax.errors import InvalidInput
from fppo_jax.run.options import Options
from fppo_jax.run.stop_signals import STOP_SIGNALS, caught
from fppo_jax.stats.decidable import plan_lines
from fppo_jax.stats.rules import SequentialMannWhitney
from fppo_jax.stats.sequential import Design

# The options a plan records: evaluations make the eval endpoint, and change what runs record.
EVALUATION = ("eval_every", "eval_episodes")


def study(
    tasks: str | Sequence[str],
    candidates: Variants,
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
    tune: Mapping[str, Any] | None = None,
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
    `tune`, the arguments of :func:`~fppo_jax.tune` (``{}`` for its defaults), tunes every arm
    first, in ``output/tune`` under the study's protocol and scoring on its endpoint (``eval``:
    the evaluation return; ``final``: the training return), then studies the settings the
    tune's validation race chose, as with `tuned`: one command, one output folder.
    `total_steps`, `preset`, `backend`, `chunk` and `settings` are the sweeps'.
    """
    tasks = names_of_tasks(tasks, "a study")
    candidates, baseline = _variants(candidates, baseline)
    if tune is not None:
        shape_of_runs: Shape = {"total_steps": total_steps, "preset": preset, "backend": backend}
        everyone = [*candidates, baseline]
        tuned = _tuned_first(
            tasks, everyone, output, tune, tuned, part, endpoint, shape_of_runs, settings
        )
    design = Design(group_size, max_seeds, level, margin)
    _check_arguments(endpoint, groups, chunk, part, settings)
    if tuned is not None:
        total_steps = _steps_of_tune(tuned, total_steps)
    sources = [str(d) for d in ([reuse] if isinstance(reuse, str | Path) else reuse or [])]
    shape: Shape = {"total_steps": total_steps, "preset": preset, "backend": backend}
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
    source = Source.of(tasks, everyone, settings, shape, chunk, part, sources, chosen)
    if tuned is not None:
        check_tuned_protocol(tuned, source)
    if with_defaults:
        source = dataclasses.replace(source, defaults=source.at_defaults(everyone))
    planned: dict[str, object] = {**shape, **_planned_settings(settings)}
    plan = make_plan(
        tasks,
        candidates,
        baseline,
        SequentialMannWhitney(design),
        endpoint,
        planned,
        sources,
        chosen,
        bool(with_defaults),
    )
    # Array tasks that start together take turns to check the plan (each holds the lock briefly).
    # A stop signal stops the study before a group of seeds, or in one after the chunk in flight
    # (Source.train), as one stops a checkpointed run: its recorded groups are its checkpoint.
    apart = {TUNE_PLAN: "a tune"}
    with (
        caught(STOP_SIGNALS),
        Preregistered(output, "a study", shared=part is not None, apart_from=apart) as folder,
    ):
        plan = folder.check(plan, PLAN_FILE, _RECORDED_ONLY, upgraded)
        folder.share_out()  # the array's tasks train their shares side by side
        if shown_progress(settings):
            lines = plan_lines(design, len(tasks) * len(candidates))
            print("\n".join(f"study: {line}" for line in lines), file=sys.stderr)
        return run_looks(folder.output, plan, tasks, candidates, baseline, groups, source)


def _tuned_first(
    tasks: list[str],
    everyone: list[Surrogate],
    output: str | Path,
    arguments: Mapping[str, Any],
    tuned: str | Path | None,
    part: tuple[int, int] | None,
    endpoint: str,
    shape: Shape,
    settings: Mapping[str, Any],
) -> Path:
    """The tune of ``study(..., tune=...)``, run to its end in ``output/tune``: its directory."""
    if tuned is not None or part is not None:
        raise InvalidInput(
            "tune (--tune) tunes and studies in one call: not beside tuned (--tuned DIR), nor in "
            "parts (tune with fppo-jax tune --part, then study --tuned DIR --part)"
        )
    if endpoint not in TUNE_SCORES:
        raise InvalidInput(
            f"a study on its own tune decides on {' or '.join(TUNE_SCORES)}, where the tune "
            f"scores its trials, not {endpoint}"
        )
    taken = sorted(set(arguments) & {"score", "output", "part", *shape, *settings})
    if taken:
        raise InvalidInput(f"the study sets the tune's {', '.join(taken)} itself")
    where = Path(output) / TUNE_DIRECTORY
    shape_settings = {k: v for k, v in settings.items() if k in CONFIG_FIELDS}
    episodes = {"eval_episodes": settings["eval_episodes"]} if "eval_episodes" in settings else {}
    done = tune_every_arm(
        tasks,
        everyone,
        output=where,
        score=TUNE_SCORES[endpoint],
        progress=shown_progress(settings),
        **{**episodes, **arguments},
        **shape,
        **shape_settings,
    )
    if not done.finished:
        raise InvalidInput(f"the tune in {where} did not finish (rungs?): run this again")
    return where


def _steps_of_tune(tuned: str | Path, given: int | None) -> int | None:
    """The env steps of each run (`total_steps`) of the tune in `tuned`, as its plan records
    them, where the study gives none; one given that differs is refused by name (the other
    run-shape fields by :func:`~fppo_jax.analysis.study_tuned.check_tuned_protocol`)."""
    directory = Path(tuned)
    if directory.name == TUNE_PLAN and directory.is_file():  # the tune's plan named for it
        directory = directory.parent
    if not (directory / TUNE_PLAN).is_file():
        return given  # no tune there: tuned_settings says so
    recorded = read_plan(directory)["settings"].get("total_steps")
    steps = recorded if isinstance(recorded, int) else None  # None: the task's own
    if given is None or steps is None or given == steps:
        return steps if given is None else given
    raise InvalidInput(
        f"the tune in {directory} trained total_steps = {steps} (--steps) per run, not "
        f"{given}: a study on its settings trains as it did; leave total_steps out to take "
        "the tune's"
    )


def _check_arguments(
    endpoint: str,
    groups: int | None,
    chunk: int | None,
    part: tuple[int, int] | None,
    settings: Mapping[str, object],
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


def _planned_settings(settings: Mapping[str, object]) -> dict[str, object]:
    """What the plan records of the settings: all but how runs are driven, and the
    evaluations' where the runs are evaluated (they make the eval endpoint)."""
    evaluated = settings.get("eval_every") is not None
    recorded = {k: v for k, v in settings.items() if k not in Options.names()}
    return {**recorded, **{k: settings[k] for k in EVALUATION if evaluated and k in settings}}


# Where study(..., tune=...) tunes, in its output folder, and what the tune scores on for each
# endpoint the study may decide on.
TUNE_DIRECTORY = "tune"
TUNE_SCORES = {"eval": "eval", "final": "train"}


# A tune is known by its plan's digest: the study goes on where the tune and the study were
# copied or cloned to, as under another commit.
_RECORDED_ONLY = frozenset({"commit", "tuned.directory"})


def _variants(candidates: Variants, baseline: str | Surrogate) -> tuple[list[Surrogate], Surrogate]:
    """The candidates and the baseline resolved (a name or a surrogate each), checked."""
    arms = resolve_arms(candidates, "a study", "candidate")
    against = resolve(baseline)
    union([*arms, against])  # two different surrogates under one name are refused
    if against.name in [c.name for c in arms]:
        raise InvalidInput(f"the baseline {against.name} is also a candidate")
    return arms, against
