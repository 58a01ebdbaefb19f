"""Tuning every arm with the same budget: successive halving over a population of settings,
each rung of a task one compiled program.

For each task, every arm (a variant: PPO, the baseline, as much as any candidate) gets the same
`trials` settings: trial 0 is the arm's default, the others are drawn from the arm's search
space (:mod:`fppo_jax.core.search_space`) by Optuna's sampler, the same points on the axes that
every arm shares. The arms' live trials × the tuning seeds train side by side as one vmapped program
for a rung's updates; after the rung each arm keeps its best ``1/eta`` of trials, ranked on their
mean score over the seeds (never one seed), and those go on from where they stopped: a rung is a
prefix of the full run, whose learning-rate schedule spans the full budget. With `trials` = η^k
the rungs have η^k, η^(k−1), …, 1 trials, and the last one trains to the full budget. Each arm
uses the same env steps (the plan and the report give them).

Before any run the output gets ``tune.json``, the plan: the search space, trials, seeds, η and
the rungs, the budget per arm and task, the sampler and its seed, the score and the selection
rule, and the commit. Each finished rung writes ``<task>/rung-<r>/`` (its scores, and the state
its survivors go on from) and records every trial's score in Optuna's storage (a SQLite file in
the output, or a database URL that many processes share): the same call again goes on from the
last rung recorded, bit for bit; a changed plan is refused naming the change. A SLURM job
array's tasks each train a share of a rung (whole groups of its runs, in
``<task>/rung-<r>/part-<K>/``) and rank nothing; a call without a part joins the shares into
the rung trained unsplit, bit for bit, and alone tells Optuna its scores. At the end,
``results.json`` holds each arm's chosen setting per task, and ``report.md`` the tuning report
(:mod:`fppo_jax.analysis.tuning_report`); ``fppo_jax.study(..., tuned=output)`` then decides on
fresh seeds.

The protocol is Eimer, Lindauer and Raileanu's ("Hyperparameters in Reinforcement Learning and
How To Tune Them", ICML 2023): every arm tuned over the same space with the same budget, on
tuning seeds that the test never uses; successive halving is Jamieson and Talwalkar's (AISTATS
2016), as ARLBench runs it (Becktepe et al., 2024) with several seeds per trial.
"""

from __future__ import annotations

import json
import math
import sys
import warnings
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, cast

import jax

from fppo_jax.analysis.arms import Variants, names_of_tasks, resolve_arms
from fppo_jax.analysis.population import Population, Shape
from fppo_jax.analysis.preregistration import Preregistered, commit
from fppo_jax.analysis.study_plan import PLAN_FILE as STUDY_PLAN
from fppo_jax.analysis.tune_design import TuneDesign, design
from fppo_jax.analysis.tune_files import (
    PLAN_FILE,
    RESULTS_FILE,
    TuneResult,
    task_directory,
)
from fppo_jax.analysis.tune_shapes import plan_record, preparer, task_axes, with_axes
from fppo_jax.analysis.tune_storage import storage_record, tune_storage
from fppo_jax.analysis.tuning_draws import (
    draw_population,
    import_optuna,
    setting_of,
)
from fppo_jax.analysis.tuning_records import (
    RunShapeValue,
    TaskBudget,
    TunePlan,
)
from fppo_jax.analysis.tuning_report import write_report
from fppo_jax.analysis.tuning_rungs import TaskTune
from fppo_jax.core.checks import check_part, positive_int
from fppo_jax.core.config import CONFIG_FIELDS
from fppo_jax.core.objectives import identities
from fppo_jax.core.search_space import (
    SearchSpace,
    read_space_file,
    search_spaces,
)
from fppo_jax.core.surrogates import Surrogate
from fppo_jax.envs import resets_itself
from fppo_jax.errors import InvalidInput
from fppo_jax.run.prepare import Prepared, prepare
from fppo_jax.run.stop_signals import STOP_SIGNALS, caught
from fppo_jax.store.files import json_value, write_json

SAMPLERS = ("qmc", "random")


# Every trial is drawn before the first rung trains, so a tune goes on under another Optuna
# release as under another commit: both are recorded, neither compared. The storage is checked
# on its own (tune_storage), by a message that says which to give.
_RECORDED_ONLY = frozenset({"commit", "sampler.package", "storage"})


def tune(
    tasks: str | Sequence[str],
    variants: Variants,
    *,
    output: str | Path,
    trials: int = 27,
    seeds: int | Sequence[int] = 2,
    eta: int = 3,
    scheduler: str = "halving",
    budget: int | None = None,
    score: str = "eval",
    eval_episodes: int = 10,
    finalists: int = 3,
    validation_seeds: int | Sequence[int] = 10,
    race_level: float = 0.05,
    baseline: str | None = None,
    space: str | Path | Mapping[str, Any] | None = None,
    sampler: str = "qmc",
    sampler_seed: int = 0,
    storage: str | None = None,
    rungs: int | None = None,
    chunk: int | None = None,
    part: tuple[int, int] | None = None,
    total_steps: int | None = None,
    preset: str = "paper",
    backend: str = "auto",
    progress: bool = False,
    **settings: Any,
) -> TuneResult:
    """Tune every one of `variants` on each of `tasks` with the same budget (see the module).

    `trials` settings per arm and task. The search's `scheduler`: ``halving`` trains each trial
    with every one of `seeds` (a count, drawn from
    :data:`~fppo_jax.analysis.tune_design.TUNING_SEED_START` on, or the seeds),
    halved by `eta` at each rung; ``racing`` trains full runs, `seeds` (a count) fresh seeds a
    round for the trials still in, as many rounds as `budget` (full runs per arm and task, the
    validation race's included) holds, dropping a trial shown worse than the incumbent at
    `race_level`. Trials are ranked on `score`: ``eval``, the deterministic policy's mean return
    over `eval_episodes` episodes (the study's eval endpoint), or ``train``, the training
    return. Then the validation race: each arm's `finalists` and its default train the full
    budget on `validation_seeds` (a count from
    :data:`~fppo_jax.analysis.tune_design.VALIDATION_SEED_START`, or the seeds), and a finalist
    replaces the default only where a paired one-sided test, Holm over the finalists at
    `race_level`, shows it better. `space` is a space file or its content
    (:func:`~fppo_jax.core.search_space.search_spaces`); `sampler` (``qmc``: Optuna's scrambled
    Sobol sampler, or ``random``) draws the trials from `sampler_seed`; `storage` is Optuna's
    storage, a database URL or a journal file ending ``.log`` (default: a SQLite file in
    `output`; :mod:`~fppo_jax.analysis.tune_storage`). `baseline` (default: ``ppo`` if tuned,
    else the first variant) is the arm whose default the report measures the others' sampled
    settings against. `rungs` limits the rungs this call trains (the same call later goes on;
    0 trains none, but joins the shares recorded). `chunk` is the runs each compiled call
    trains (default: :func:`default_chunk`, one trial's seeds where the tasks step in JAX on a
    CPU, else each rung's runs in one call): a rung's runs, in order, train in groups of that
    many, the last filled up. ``part=(K, N)`` (with a chunk) trains the K-th of N shares of
    those groups of each task's next rung, records it in ``<task>/rung-<r>/part-<K>/`` and
    returns; a call without `part` joins the shares into the rung trained unsplit with the
    same chunk, bit for bit. `progress` prints each rung's lines on stderr, as a study's, a
    sweep's and a run's (the command line shows them unless ``--quiet``). `total_steps`,
    `preset`, `backend` and `settings` (run-shape fields of
    :class:`~fppo_jax.core.config.TrainConfig`) are every run's.
    """
    _check_places(output, space)
    tasks = names_of_tasks(tasks, "a tune")
    arms = resolve_arms(variants, "a tune")
    chosen = design(
        scheduler,
        trials,
        seeds,
        eta,
        budget,
        score,
        eval_episodes,
        finalists,
        validation_seeds,
        race_level,
    )
    _check_arguments(sampler, sampler_seed, rungs, settings)
    _checked_split(chunk, None, chosen.per_round)
    baseline = _baseline(baseline, arms)
    given = read_space_file(space) if isinstance(space, str | Path) else space
    spaces = search_spaces(arms, given)
    optuna = import_optuna()
    runs = {
        task: prepare(
            task, dict(settings), (), total_steps=total_steps, preset=preset, backend=backend
        )
        for task in tasks
    }
    if chunk is None:
        chunk = default_chunk(Path(output), runs, chosen.per_round)
    part = _checked_split(chunk, part, chosen.per_round)
    axes = {task: task_axes(run, settings, given or {}, scheduler) for task, run in runs.items()}
    task_spaces = {task: with_axes(spaces, axes[task], run) for task, run in runs.items()}
    budgets = {task: chosen.budget_of(run) for task, run in runs.items()}
    _check_budget(budget, budgets)
    shape: dict[str, RunShapeValue] = {
        "total_steps": total_steps,
        "preset": preset,
        "backend": backend,
        # The groups a rung trains in make its numbers: recorded where given, so that the
        # shares and their join are one tune (and a tune planned before it goes on).
        **({} if chunk is None else {"chunk": chunk}),
        **settings,
    }
    plan = make_plan(runs, arms, spaces, chosen, budgets, baseline, sampler, sampler_seed, shape)
    if plan_record(axes):  # a tune that searches no run shape has the plan it always had
        plan["run_shape"] = plan_record(axes)
    plan["storage"] = storage_record(plan, storage, output)
    verbosity = optuna.logging.get_verbosity()
    # Array tasks that start together take turns with the folder: each holds it while it reads
    # and writes the plan and Optuna's storage, then lets go to train its share.
    apart = {STUDY_PLAN: "a study"}
    # A stop signal stops the tune at its next safe point (TaskTune.train), as one stops a
    # checkpointed run: its recorded rungs are its checkpoint.
    with (
        caught(STOP_SIGNALS),
        Preregistered(output, "a tune", shared=part is not None, apart_from=apart) as folder,
    ):
        try:
            # Optuna's line per study made and per trial told, and its note that the Sobol
            # sampler is experimental, are not this tune's progress: quiet for the call.
            optuna.logging.set_verbosity(optuna.logging.WARNING)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
                plan = folder.check(plan, PLAN_FILE, _RECORDED_ONLY)
                store = tune_storage(optuna, storage, folder.output, plan)
                tuned = [
                    _task_tune(
                        task,
                        runs[task],
                        arms,
                        draw_population(
                            optuna,
                            store,
                            task,
                            arms,
                            task_spaces[task],
                            chosen.trials,
                            sampler,
                            sampler_seed,
                        ),
                        chosen,
                        chunk,
                        task_directory(folder.output, task),
                        (optuna, store),
                        progress,
                        preparer(task, settings, total_steps, preset, backend),
                    )
                    for task in tasks
                ]
                for each in tuned:  # what is recorded, told to Optuna; shares joined
                    each.read(join=part is None)
                folder.share_out()  # a share writes only its own files: the others go on
                left = math.inf if rungs is None else rungs
                for each in tuned:
                    left -= each.train(left, part)
        finally:
            optuna.logging.set_verbosity(verbosity)
    results = {each.task: each.results(baseline) for each in tuned if each.finished}
    finished = len(results) == len(tasks)
    if finished and part is None:
        write_json(folder.output / RESULTS_FILE, results)
        write_report(folder.output, plan, results)
    rungs_recorded = {each.task: each.scores for each in tuned}
    return TuneResult(folder.output, plan, rungs_recorded, results, finished)


def _check_places(output: object, space: object) -> None:
    """`output` a folder's path and `space` a space file's path or its content (a mapping),
    else one line naming what was given: a list's pairs, say, read as a mapping, would be an
    error far from its cause, and None as a path a TypeError."""
    if not isinstance(output, str | Path) or not str(output):
        raise InvalidInput(f"output must be a folder's path (a str or Path), got {output!r}")
    if space is not None and not isinstance(space, str | Path | Mapping):
        raise InvalidInput(
            "space must be a space file's path or a mapping of names to intervals, such as "
            f"{{'learning_rate': (1e-4, 1e-3, 'log')}}, got {space!r}"
        )


def _check_arguments(
    sampler: str, sampler_seed: int, rungs: int | None, settings: Mapping[str, object]
) -> None:
    if sampler not in SAMPLERS:
        raise InvalidInput(f"sampler must be one of {', '.join(SAMPLERS)}, got {sampler!r}")
    if (
        not isinstance(sampler_seed, int)
        or isinstance(sampler_seed, bool)
        or not (0 <= sampler_seed < 2**32)
    ):
        raise InvalidInput(f"sampler_seed must be an integer in [0, 2**32), got {sampler_seed!r}")
    if rungs is not None and (isinstance(rungs, bool) or not isinstance(rungs, int) or rungs < 0):
        raise InvalidInput(f"rungs must be a count of rungs (0 or more), got {rungs!r}")
    stray = sorted(set(settings) - set(CONFIG_FIELDS))
    if stray:
        raise InvalidInput(
            f"a tune takes run-shape settings ({', '.join(CONFIG_FIELDS)}), not "
            f"{', '.join(stray)}: the hyperparameters are its search space"
        )


def _check_budget(budget: int | None, budgets: Mapping[str, TaskBudget]) -> None:
    """A budget given is one every task's design fits in (racing's fits by its making)."""
    for task, planned in budgets.items():
        needed = planned.get("full_runs_per_arm", 0.0)
        if budget is not None and needed > budget:
            raise InvalidInput(
                f"successive halving and the validation race train {needed:g} full runs per "
                f"arm on {task}, more than the budget of {budget}: give fewer trials, fewer "
                "seeds, fewer finalists or validation seeds, or a larger budget"
            )


def _task_tune(
    task: str,
    prepared: Prepared,
    arms: list[Surrogate],
    drawn: dict[str, list[dict[str, Any]]],
    chosen: TuneDesign,
    chunk: int | None,
    directory: Path,
    optuna_storage: tuple[Any, Any],
    progress: bool,
    shaped: Callable[[Shape], Prepared],
) -> TaskTune:
    """`task`'s tune: the population of the `drawn` trials, trained as the design's scheduler
    says, scored as it says (a trial of another run shape on the task as `shaped` prepares
    it)."""
    settings = {arm: [setting_of(params) for params in trials] for arm, trials in drawn.items()}
    scheduler = chosen.scheduler_for([arm.name for arm in arms], prepared)

    def say(line: str) -> None:
        if progress:
            print(line, file=sys.stderr, flush=True)

    episodes = chosen.eval_episodes if chosen.score == "eval" else None
    population = Population(
        prepared, arms, settings, scheduler.updates_per_call, chunk, say, episodes, shaped
    )
    return TaskTune(task, population, scheduler, directory, *optuna_storage)


def default_chunk(output: Path, runs: Mapping[str, Prepared], seeds: int) -> int | None:
    """The runs each compiled call trains where none is given: for a tune planned before, the
    plan's (None: each rung's runs in one call); else, where every task steps in JAX on a CPU,
    one trial's `seeds`, so that every rung and the validation race are groups of one size,
    one program compiled once: a first tune compiles a fifth as long, and trains about a fifth
    longer, narrower groups keeping a CPU's cores less busy (``bench_tune.py``, CartPole, two
    cores); else None: an accelerator, or environments stepped on the host (native MuJoCo),
    gain most from each rung's runs in one wide call."""
    try:
        recorded = json.loads((output / PLAN_FILE).read_text())
    except FileNotFoundError:
        recorded = None
    except (OSError, ValueError):
        return None  # not a plan this tune can go on from: checking it against ours says why
    if isinstance(recorded, dict):
        planned = recorded.get("settings")
        chunk = planned.get("chunk") if isinstance(planned, dict) else None
        return chunk if isinstance(chunk, int) else None
    on_host = any(resets_itself(run.environment) for run in runs.values())
    return seeds if jax.default_backend() == "cpu" and not on_host else None


def _checked_split(chunk: int | None, part: object, seeds: int) -> tuple[int, int] | None:
    """`part` as (K, N), with `chunk` checked before any plan: a chunk of whole trials. A share
    trains whole groups, as the unsplit tune trains them, so any split is the same tune; without
    a chunk a rung's groups are its run shapes, one each (a rung of one shape is one group, which
    one share trains)."""
    if chunk is not None and positive_int("chunk", chunk) % seeds:
        raise InvalidInput(
            f"chunk (runs per compiled call) must be a multiple of the {seeds} seeds per trial, "
            f"got {chunk}: all seeds of a trial train in one group"
        )
    if part is None:
        return None
    k, n = check_part(part)
    return k, n


def _baseline(baseline: str | None, arms: list[Surrogate]) -> str:
    names = [arm.name for arm in arms]
    if baseline is None:
        return "ppo" if "ppo" in names else names[0]
    if baseline not in names:
        raise InvalidInput(f"the baseline {baseline!r} is not among the tuned variants {names}")
    return baseline


def make_plan(
    runs: dict[str, Prepared],
    arms: list[Surrogate],
    spaces: dict[str, SearchSpace],
    chosen: TuneDesign,
    budgets: dict[str, TaskBudget],
    baseline: str,
    sampler: str,
    sampler_seed: int,
    settings: dict[str, RunShapeValue],
) -> TunePlan:
    """What ``tune.json`` records, before any run."""
    from importlib.metadata import version

    fields = chosen.plan_fields()
    halving = {"eta": chosen.eta} if chosen.scheduler == "halving" else {}
    return cast(
        TunePlan,
        json_value(
            {
                "tasks": list(runs),
                "variants": [arm.name for arm in arms],
                "baseline": baseline,
                "trials": chosen.trials,
                "trial_0": "each arm's default setting",
                "seeds": chosen.seeds,
                **halving,
                "budget": budgets,
                "space": {arm: space.to_json() for arm, space in spaces.items()},
                "sampler": {
                    "name": sampler,
                    "seed": sampler_seed,
                    "package": f"optuna {version('optuna')}",
                },
                "score": fields["score"],
                "selection": fields["selection"],
                "search": fields["search"],
                "validation": fields["validation"],
                "settings": settings,
                "protocol": {task: run.record().to_json() for task, run in runs.items()},
                **identities(arms),
                "commit": commit(),
            }
        ),
    )
