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

import dataclasses
import hashlib
import io
import json
import math
import sys
import time
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, cast

import jax
import numpy as np

from fppo_jax.analysis.studies import PART_LOCK_WAIT, check_plan, commit, names_of_tasks
from fppo_jax.analysis.tuning_report import ranked
from fppo_jax.core.checks import check_part, check_seeds, positive_int
from fppo_jax.core.config import CONFIG_FIELDS, stack_hyperparameters, with_budget
from fppo_jax.core.objectives import identities, union
from fppo_jax.core.resolution import resolve, resolve_hyperparameters
from fppo_jax.core.search_space import (
    Interval,
    SearchSpace,
    default_setting,
    read_space_file,
    search_spaces,
)
from fppo_jax.core.surrogates import Surrogate
from fppo_jax.core.trainer import TrainState
from fppo_jax.envs import resets_itself
from fppo_jax.errors import InvalidInput, MissingFile, MissingPackage, first_line, install_hint
from fppo_jax.run.driver import share_bounds
from fppo_jax.run.execution import compile_program, run_keys
from fppo_jax.run.memory import check_host_memory
from fppo_jax.run.prepare import Prepared, prepare
from fppo_jax.store.files import (
    DirectoryLock,
    json_value,
    writable_directory,
    write_atomically,
    write_json,
)

# Tuning seeds come from their own stream, far from the 0, 1, 2, … that studies and sweeps
# count from, so that a test on fresh seeds never meets them.
TUNING_SEED_START = 1_000_000
SAMPLERS = ("qmc", "random")
PLAN_FILE, RESULTS_FILE, REPORT_FILE, STORAGE_FILE = (
    "tune.json",
    "results.json",
    "report.md",
    "optuna.db",
)
SCORE = (
    "a run's training return at the end of the rung (the mean of its last 100 episodes); a "
    "trial's score is the mean over its tuning seeds; a trial with a run that finished no "
    "episode ranks below every trial with a score (ties by trial number), and one with a run "
    "that diverged stops"
)
SELECTION = "per task and arm: the trial with the best score at the last rung (the full budget)"
_STATE, _SCORES = "state.npz", "scores.json"
CALLS_A_RUNG = 10  # compiled calls the first rung is split into, at least, for progress


@dataclasses.dataclass(frozen=True)
class Rungs:
    """A successive-halving schedule: the live `trials` of each arm at each rung, the update
    each rung ends at (the last one the run's end), and the updates per compiled call."""

    trials: tuple[int, ...]
    ends: tuple[int, ...]

    @property
    def updates_per_call(self) -> int:
        """The largest divisor of the first rung's length that is at most a
        :data:`CALLS_A_RUNG`-th of it (1 for a shorter rung): every rung but the last, whose end
        the run's length stops, is then whole calls, and progress is told between them."""
        first = self.ends[0]
        return (
            max(d for d in range(1, first // CALLS_A_RUNG + 1) if first % d == 0)
            if (first >= CALLS_A_RUNG)
            else 1
        )

    def to_json(self, samples_per_update: int) -> list[dict[str, int]]:
        return [
            {"trials": n, "ends_at_update": end, "env_steps_per_run": end * samples_per_update}
            for n, end in zip(self.trials, self.ends, strict=True)
        ]

    def updates_per_arm(self, seeds: int) -> int:
        """Updates every arm trains over the rungs: its live trials × seeds × each rung's."""
        starts = (0, *self.ends[:-1])
        return seeds * sum(
            n * (end - start) for n, start, end in zip(self.trials, starts, self.ends, strict=True)
        )


def schedule(trials: int, eta: int, num_updates: int) -> Rungs:
    """The rungs of `trials` trials halved by `eta` over a run of `num_updates` updates: as
    many rungs as `eta` divides the trials down to one, rung r (from 0) keeping
    ``trials // eta**r`` of them and ending at update ``first · eta**r`` (the last at the run's
    end), ``first = num_updates // eta**(rungs − 1)``."""
    count = 1
    while eta**count <= trials:
        count += 1
    first = num_updates // eta ** (count - 1)
    if first < 1:
        raise InvalidInput(
            f"a run of {num_updates} updates is too short for {count} rungs of η = {eta} (the "
            f"first rung would be {num_updates}/{eta ** (count - 1)} of an update): give more "
            "total_steps, fewer trials or a smaller eta"
        )
    ends = (*(first * eta**r for r in range(count - 1)), num_updates)
    return Rungs(tuple(max(1, trials // eta**r) for r in range(count)), ends)


@dataclasses.dataclass
class TuneResult:
    """A tune's `plan` (as ``tune.json`` has it), `results` (as ``results.json``: per task and
    arm, the chosen setting and what the rungs measured) and whether it is `finished`."""

    plan: dict[str, Any]
    results: dict[str, dict[str, Any]]
    finished: bool
    directory: Path

    def chosen(self, task: str, arm: str) -> dict[str, Any]:
        """The setting chosen for `arm` on `task`."""
        return cast(dict[str, Any], self.results[task][arm]["chosen"]["setting"])


def tune(
    tasks: str | Sequence[str],
    variants: Any,
    *,
    output: str | Path,
    trials: int = 27,
    seeds: int | Sequence[int] = 2,
    eta: int = 3,
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
    progress: bool = True,
    **settings: Any,
) -> TuneResult:
    """Tune every one of `variants` on each of `tasks` with the same budget (see the module).

    `trials` settings per arm and task, each trained with every one of `seeds` (a count, drawn
    from :data:`TUNING_SEED_START` on, or the seeds), halved by `eta` at each rung. `space` is a
    space file or its content (:func:`~fppo_jax.core.search_space.search_spaces`); `sampler`
    (``qmc``: Optuna's scrambled Sobol sampler, or ``random``) draws the trials from
    `sampler_seed`; `storage` is Optuna's storage URL (default: a SQLite file in `output`).
    `baseline` (default: ``ppo`` if tuned, else the first variant) is the arm whose default the
    report measures the others' sampled settings against. `rungs` limits the rungs this call
    trains (the same call later goes on; 0 trains none, but joins the shares recorded).
    `chunk`, a multiple of the seeds' count, is the runs each compiled call trains (default:
    each rung's runs in one call): a rung's runs, in order, train in groups of that many.
    ``part=(K, N)`` (with `chunk`) trains the K-th of N shares of those groups of each task's
    next rung, records it in ``<task>/rung-<r>/part-<K>/`` and returns; a call without `part`
    joins the shares into the rung trained unsplit with the same `chunk`, bit for bit.
    `total_steps`, `preset`, `backend` and `settings` (run-shape fields of
    :class:`~fppo_jax.core.config.TrainConfig`) are every run's.
    """
    tasks = names_of_tasks(tasks, "a tune")
    arms = _arms(variants)
    trials = positive_int("trials", trials)
    if isinstance(eta, bool) or not isinstance(eta, int | np.integer) or eta < 2:
        raise InvalidInput(f"eta (the halving rate) must be an integer of at least 2, got {eta!r}")
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
    tuning_seeds = check_seeds(seeds, first=TUNING_SEED_START)
    part = _checked_split(chunk, part, len(tuning_seeds))
    baseline = _baseline(baseline, arms)
    given = read_space_file(space) if isinstance(space, str | Path) else space
    spaces = search_spaces(arms, given)
    optuna = _optuna()
    runs = {
        task: prepare(
            task, dict(settings), (), total_steps=total_steps, preset=preset, backend=backend
        )
        for task in tasks
    }
    schedules = {
        task: schedule(trials, int(eta), run.config.num_updates) for task, run in runs.items()
    }
    plan = make_plan(
        runs,
        arms,
        spaces,
        schedules,
        trials,
        tuning_seeds,
        int(eta),
        baseline,
        sampler,
        sampler_seed,
        {
            "total_steps": total_steps,
            "preset": preset,
            "backend": backend,
            # The groups a rung trains in make its numbers: recorded where given, so that the
            # shares and their join are one tune (and a tune planned before it goes on).
            **({} if chunk is None else {"chunk": chunk}),
            **settings,
        },
    )
    output = writable_directory(output)
    # Array tasks that start together take turns with the lock: each holds it while it reads
    # and writes the plan and Optuna's storage, then lets go to train its share.
    lock = DirectoryLock(output, "a tune", wait=PART_LOCK_WAIT if part is not None else 0.0)
    verbosity = optuna.logging.get_verbosity()
    try:
        # Optuna's line per study made and per trial told, and its note that the Sobol sampler
        # is experimental, are not this tune's progress: quiet for the call, then as found.
        optuna.logging.set_verbosity(optuna.logging.WARNING)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
            plan = check_plan(output, plan, "a tune", PLAN_FILE)
            store = _storage(optuna, storage or f"sqlite:///{(output / STORAGE_FILE).absolute()}")
            tuned = [
                _Task(
                    task,
                    runs[task],
                    arms,
                    _population(optuna, store, task, arms, spaces, trials, sampler, sampler_seed),
                    schedules[task],
                    tuning_seeds,
                    chunk,
                    output / task,
                    optuna,
                    store,
                    progress,
                )
                for task in tasks
            ]
            for each in tuned:  # what is recorded, told to Optuna; shares joined without a part
                each.read(join=part is None)
            if part is not None:  # a share writes only its own files: the others go on
                lock.release()
            left = math.inf if rungs is None else rungs
            for each in tuned:
                left -= each.train(left, part)
    finally:
        optuna.logging.set_verbosity(verbosity)
        lock.release()
    results = {each.task: each.results(baseline) for each in tuned if each.finished}
    finished = len(results) == len(tasks)
    if finished and part is None:
        from fppo_jax.analysis.tuning_report import write_report

        write_json(output / RESULTS_FILE, results)
        write_report(output, plan, results)
    return TuneResult(plan, results, finished, output)


def _checked_split(chunk: int | None, part: object, seeds: int) -> tuple[int, int] | None:
    """`part` as (K, N), with `chunk` checked before any plan: a chunk of whole trials, and a
    split only of groups that an unsplit tune with the same chunk trains alike."""
    if chunk is not None and positive_int("chunk", chunk) % seeds:
        raise InvalidInput(
            f"chunk (runs per compiled call) must be a multiple of the {seeds} seeds per trial, "
            f"got {chunk}: all seeds of a trial train in one group"
        )
    if part is None:
        return None
    k, n = check_part(part)
    if chunk is None and n > 1:
        # XLA rounds a vmapped program by its run count: a share trained as its own program
        # would differ in the last bits from the rung trained whole, and then diverge.
        raise InvalidInput(
            f"part {k} of {n} needs chunk (--chunk), the runs per compiled call, the same for "
            "every share and the join: a rung's runs train in groups of that many and a share "
            "trains whole groups, so that the joined rung is the one trained unsplit, bit for "
            "bit"
        )
    return k, n


def _arms(variants: Any) -> list[Surrogate]:
    one = isinstance(variants, str | Surrogate)
    arms = [resolve(v) for v in ([variants] if one else list(variants))]
    if not arms:
        raise InvalidInput("a tune needs at least one variant")
    union(arms)  # two different surrogates under one name are refused
    names = [arm.name for arm in arms]
    if len(set(names)) < len(names):
        raise InvalidInput(f"a variant is named twice among {', '.join(names)}")
    return arms


def _baseline(baseline: str | None, arms: list[Surrogate]) -> str:
    names = [arm.name for arm in arms]
    if baseline is None:
        return "ppo" if "ppo" in names else names[0]
    if baseline not in names:
        raise InvalidInput(f"the baseline {baseline!r} is not among the tuned variants {names}")
    return baseline


def _storage(optuna: Any, url: str) -> Any:
    """Optuna's storage at `url`, opened (a SQLite file is made if need be)."""
    try:
        return optuna.storages.RDBStorage(url)
    except Exception as error:  # SQLAlchemy's and the database driver's own errors
        raise InvalidInput(f"cannot open Optuna's storage {url}: {first_line(error)}") from None


def _optuna() -> Any:
    try:
        import optuna
    except ImportError:
        raise MissingPackage(f"tuning needs Optuna: {install_hint('tune')}") from None
    return optuna


def make_plan(
    runs: dict[str, Prepared],
    arms: list[Surrogate],
    spaces: dict[str, SearchSpace],
    schedules: dict[str, Rungs],
    trials: int,
    seeds: list[int],
    eta: int,
    baseline: str,
    sampler: str,
    sampler_seed: int,
    settings: dict[str, Any],
) -> dict[str, Any]:
    """What ``tune.json`` records, before any run."""
    from importlib.metadata import version

    budget = {}
    for task, run in runs.items():
        samples = run.config.samples_per_update
        updates = schedules[task].updates_per_arm(len(seeds))
        budget[task] = {
            "env_steps_per_arm": updates * samples,
            "env_steps_per_full_run": run.config.num_updates * samples,
            "rungs": schedules[task].to_json(samples),
        }
    return cast(
        dict[str, Any],
        json_value(
            {
                "tasks": list(runs),
                "variants": [arm.name for arm in arms],
                "baseline": baseline,
                "trials": trials,
                "trial_0": "each arm's default setting",
                "seeds": seeds,
                "eta": eta,
                "budget": budget,
                "space": {arm: space.to_json() for arm, space in spaces.items()},
                "sampler": {
                    "name": sampler,
                    "seed": sampler_seed,
                    "package": f"optuna {version('optuna')}",
                },
                "score": SCORE,
                "selection": SELECTION,
                "settings": settings,
                "protocol": {task: run.record() for task, run in runs.items()},
                **identities(arms),
                "commit": commit(),
            }
        ),
    )


def _population(
    optuna: Any,
    storage: Any,
    task: str,
    arms: list[Surrogate],
    spaces: dict[str, SearchSpace],
    trials: int,
    sampler: str,
    seed: int,
) -> dict[str, list[dict[str, float]]]:
    """Each arm's trials on `task`, as settings: trial 0 its default, the others drawn.

    The draws are one Optuna study (``<task>/draws``) over the shared axes and every arm's own
    (``<arm>.<name>``), so that the arms share their points on the shared axes; each draw is
    told ``PRUNED`` (drawn, not scored: Optuna's samplers learn a space from trials that
    ended). Each arm's trials are then a study of their own (``<task>/<arm>``) that the rungs
    report their scores to. A study cut short while it was being drawn is drawn again from its
    seed: the same points."""
    draws = _draws(optuna, storage, task, arms, spaces, trials, sampler, seed)
    population = {}
    for arm in arms:
        axes = spaces[arm.name].axes
        name = f"{task}/{arm.name}"
        study = _complete_study(optuna, storage, name, trials)
        if study is None:
            study = optuna.create_study(study_name=name, storage=storage, direction="maximize")
            for draw in draws:
                shared = spaces[arm.name].shared
                study.enqueue_trial(
                    {
                        _param(k, axis): draw[_param(k if k in shared else f"{arm.name}.{k}", axis)]
                        for k, axis in axes.items()
                    }
                )
                trial = study.ask()
                for key, axis in axes.items():
                    _suggest(trial, key, axis)
        population[arm.name] = [
            dict(t.params) for t in sorted(study.get_trials(deepcopy=False), key=lambda t: t.number)
        ]
    return population


def _draws(
    optuna: Any,
    storage: Any,
    task: str,
    arms: list[Surrogate],
    spaces: dict[str, SearchSpace],
    trials: int,
    sampler: str,
    seed: int,
) -> list[dict[str, float]]:
    axes = dict(next(iter(spaces.values())).shared)
    defaults = {k: default_setting(arms[0], task)[k] for k in axes}
    for arm in arms:
        own = default_setting(arm, task)
        for key, axis in spaces[arm.name].own.items():
            axes[f"{arm.name}.{key}"] = axis
            defaults[f"{arm.name}.{key}"] = own[key]
    first = {_param(k, axis): _internal(defaults[k], axis) for k, axis in axes.items()}
    name = f"{task}/draws"
    study = _complete_study(optuna, storage, name, trials)
    if study is None:
        drawn = (
            optuna.samplers.QMCSampler(scramble=True, seed=seed)
            if sampler == "qmc"
            else optuna.samplers.RandomSampler(seed=seed)
        )
        study = optuna.create_study(study_name=name, storage=storage, sampler=drawn)
        study.set_user_attr("role", "the points each arm's trials take; scores are in theirs")
        study.enqueue_trial(first)
        for _ in range(trials):
            trial = study.ask()
            for key, axis in axes.items():
                _suggest(trial, key, axis)
            study.tell(trial, state=optuna.trial.TrialState.PRUNED)
    done = sorted(study.get_trials(deepcopy=False), key=lambda t: t.number)
    return [dict(t.params) for t in done]


def _complete_study(optuna: Any, storage: Any, name: str, trials: int) -> Any:
    """Study `name`, if it holds its `trials` trials (each with its parameters); one cut short
    is deleted, to be made again."""
    try:
        study = optuna.load_study(study_name=name, storage=storage)
    except KeyError:
        return None
    held = study.get_trials(deepcopy=False)
    waiting = optuna.trial.TrialState.WAITING
    if len(held) == trials and all(t.state != waiting and t.params for t in held):
        return study
    optuna.delete_study(study_name=name, storage=storage)
    return None


def _param(name: str, axis: Interval) -> str:
    """What Optuna calls axis `name`: on a log1m scale it draws ``1-<name>``, log-uniformly."""
    return f"1-{name}" if axis.scale == "log1m" else name


def _internal(value: float, axis: Interval) -> float:
    return 1 - value if axis.scale == "log1m" else value


def _suggest(trial: Any, name: str, axis: Interval) -> None:
    """`trial`'s value of `name` on `axis`, drawn (or taken, if enqueued) and recorded."""
    if axis.scale == "log1m":
        trial.suggest_float(_param(name, axis), 1 - axis.high, 1 - axis.low, log=True)
    else:
        trial.suggest_float(name, axis.low, axis.high, log=axis.scale == "log")


def setting_of(params: Mapping[str, float]) -> dict[str, float]:
    """A trial's parameters as a setting (``1-gamma`` drawn is γ)."""
    return {
        (key[2:] if key.startswith("1-") else key): (1 - value if key.startswith("1-") else value)
        for key, value in params.items()
    }


@dataclasses.dataclass
class _Share:
    """What a share of a rung trained: its `runs` (arm, trial, seed, in the rung's order), each
    run's score at the rung's end (NaN where no episode finished) and whether it diverged, the
    leaves of its state (as :func:`_save_leaves` writes them; none at the last rung, which no
    rung goes on from), and the seconds it trained and compiled."""

    runs: list[tuple[str, int, int]]
    last: np.ndarray
    diverged: np.ndarray
    leaves: list[np.ndarray]
    seconds: float
    compile_seconds: float


class _Task:
    """One task's population, rung by rung."""

    def __init__(
        self,
        task: str,
        prepared: Prepared,
        arms: list[Surrogate],
        population: dict[str, list[dict[str, float]]],
        rungs: Rungs,
        seeds: list[int],
        chunk: int | None,
        directory: Path,
        optuna: Any,
        storage: Any,
        progress: bool,
    ):
        self.task, self.prepared, self.arms = task, prepared, arms
        self.rungs, self.seeds, self.chunk = rungs, seeds, chunk
        self.settings = {arm: [setting_of(p) for p in params] for arm, params in population.items()}
        self.directory, self.optuna, self.storage, self.progress = (
            directory,
            optuna,
            storage,
            progress,
        )
        self.live = {arm.name: list(range(len(self.settings[arm.name]))) for arm in arms}
        self.scores: list[dict[str, Any]] = []  # each recorded rung's

    @property
    def finished(self) -> bool:
        return len(self.scores) == len(self.rungs.trials)

    def read(self, join: bool) -> None:
        """Takes the rungs recorded, and where `join`, the rungs whose shares array tasks
        recorded, joined (a rung with some of its shares missing is refused)."""
        self.directory.mkdir(exist_ok=True)
        while not self.finished:
            where = self._where(len(self.scores))
            if (where / _SCORES).exists():
                self._recorded(json.loads((where / _SCORES).read_text()))
            elif join and any(where.glob(f"part-*/{_SCORES}")):
                self._record(self._read_shares())
            else:
                return

    def train(self, allowed: float, part: tuple[int, int] | None) -> int:
        """Trains up to `allowed` rungs after those read, each as its one share; with `part`,
        that share of the next rung alone, recorded for the join. Returns how many rungs it
        trained (or trained a share of)."""
        if part is not None:
            if self.finished or allowed < 1:
                return 0
            self._train_part(part)
            return 1
        trained = 0
        while not self.finished and trained < allowed:
            self._record([self._share((1, 1))])
            trained += 1
        return trained

    def _where(self, rung: int) -> Path:
        return self.directory / f"rung-{rung}"

    def _order(self) -> list[tuple[str, int, int]]:
        """The next rung's runs: each arm's live trials × the seeds, in that order."""
        return [
            (arm, t, seed)
            for arm, trials in self.live.items()
            for t in trials
            for seed in self.seeds
        ]

    def _groups(self, runs: int) -> tuple[int, int]:
        """The size and the count of the groups that a rung of `runs` runs trains in: `chunk`
        runs each (all of them if it has fewer), as the unsplit tune and its shares alike."""
        size = min(self.chunk or runs, runs)
        return size, -(-runs // size)

    def _recorded(self, scores: dict[str, Any]) -> None:
        """A rung's scores: told to Optuna (again, if a kill came between), and its survivors
        made the live trials."""
        rung = len(self.scores)
        self.scores.append(scores)
        last = rung == len(self.rungs.trials) - 1
        for arm in self.live:
            study = self.optuna.load_study(study_name=f"{self.task}/{arm}", storage=self.storage)
            by_number = {t.number: t for t in study.get_trials(deepcopy=False)}
            arms = scores["arms"]
            for trial, score in zip(self.live[arm], arms[arm]["trials"], strict=True):
                frozen = by_number[trial]
                step = self.rungs.ends[rung]
                if frozen.state.is_finished():
                    continue
                value = math.nan if score["score"] is None else score["score"]
                if step not in frozen.intermediate_values:
                    self.optuna.trial.Trial(study, frozen._trial_id).report(value, step)
                states = self.optuna.trial.TrialState
                if score["diverged"]:
                    study.tell(trial, state=states.FAIL)
                elif last and score["score"] is None:
                    study.tell(trial, state=states.FAIL)  # no episode finished: no score
                elif last and trial in arms[arm]["survivors"]:
                    study.tell(trial, value)
                elif trial not in arms[arm]["survivors"]:
                    study.tell(trial, state=states.PRUNED)
            self.live[arm] = list(arms[arm]["survivors"])

    def _record(self, shares: list[_Share]) -> None:
        """Records the next rung from its `shares`, in order: its scores, ranked, and the state
        its survivors go on from; then tells Optuna (the join alone writes to it)."""
        rung, order = len(self.scores), self._order()
        assert [run for share in shares for run in share.runs] == order
        last = np.concatenate([share.last for share in shares])
        diverged = np.concatenate([share.diverged for share in shares])
        arms = self._scores(order, last, diverged, rung)
        where = self._where(rung)
        where.mkdir(exist_ok=True)
        if rung + 1 < len(self.rungs.trials):
            keep = [i for i, (arm, t, _) in enumerate(order) if t in arms[arm]["survivors"]]
            leaves = zip(*(share.leaves for share in shares), strict=True)
            _save_leaves(where / _STATE, [np.concatenate(leaf)[keep] for leaf in leaves])
        seconds = sum(share.seconds for share in shares)
        compile_seconds = sum(share.compile_seconds for share in shares)
        scores = {"arms": arms, "seconds": seconds, "compile_seconds": compile_seconds}
        write_json(where / _SCORES, scores)
        self._recorded(scores)
        best = ", ".join(
            f"{arm} {found[0]['score']:.1f}"
            if found and found[0]["score"] is not None
            else f"{arm} —"
            for arm, found in ((arm, ranked(v["trials"])) for arm, v in arms.items())
        )
        self._say(f"{self.task}: rung {rung + 1} done in {seconds:.1f} s; best: {best}")

    def _train_part(self, part: tuple[int, int]) -> None:
        """Trains `part`'s share of the next rung and records it in ``part-<K>/`` for the join
        (its runs' scores and state), unless it is recorded already."""
        rung, (k, n) = len(self.scores), part
        where = self._where(rung) / f"part-{k}"
        said = f"{self.task}: rung {rung + 1} of {len(self.rungs.trials)}, part {k} of {n}"
        if (where / _SCORES).exists():
            self._say(f"{said}: recorded already (a call without a part joins the rung's parts)")
            return
        share = self._share(part)
        if not share.runs:
            runs = len(self._order())
            size, groups = self._groups(runs)
            self._say(
                f"{said}: nothing to train, the rung's {runs} runs make {groups} group"
                f"{'s' * (groups > 1)} of {size}, fewer than the parts"
            )
            return
        where.mkdir(parents=True, exist_ok=True)
        if share.leaves:
            _save_leaves(where / _STATE, share.leaves)
        recorded = {
            "part": [k, n],
            "runs": share.runs,
            "scores": [float(v) if math.isfinite(v) else None for v in share.last],
            "diverged": share.diverged.tolist(),
            "seconds": share.seconds,
            "compile_seconds": share.compile_seconds,
        }
        write_json(where / _SCORES, recorded)  # last: a share with its scores is whole
        self._say(f"{said}: {len(share.runs)} runs recorded in {share.seconds:.1f} s")

    def _read_shares(self) -> list[_Share]:
        """The next rung's shares that array tasks recorded, every one that has runs to train,
        each checked to hold its runs; a missing one is refused by name."""
        rung, order = len(self.scores), self._order()
        where = self._where(rung)
        found = {}
        for path in where.glob(f"part-*/{_SCORES}"):
            recorded = json.loads(path.read_text())
            found[tuple(recorded["part"])] = recorded
        splits = sorted({n for _, n in found})
        if len(splits) > 1:
            raise InvalidInput(
                f"{where} holds shares of splits into {' and '.join(map(str, splits))} parts: "
                "remove those of the split not carried through, then run this again"
            )
        n = splits[0]
        size, groups = self._groups(len(order))
        shares = []
        for k in range(1, n + 1):
            first, stop = share_bounds((k, n), groups)
            runs = order[first * size : stop * size]
            if not runs:
                continue  # a share past the rung's groups: nothing to train, nothing recorded
            if (k, n) not in found:
                raise InvalidInput(
                    f"{self.task}: rung {rung + 1} is split into {n} parts and part {k} is "
                    f"missing ({where}/part-{k}): train it with --part {k}/{n} (part=({k}, {n})), "
                    "then run this again"
                )
            recorded = found[k, n]
            later = rung + 1 < len(self.rungs.trials)
            leaves = _read_leaves(where / f"part-{k}" / _STATE) if later else []
            if [tuple(run) for run in recorded["runs"]] != runs or any(
                len(leaf) != len(runs) for leaf in leaves
            ):
                raise InvalidInput(
                    f"{where}/part-{k} does not hold part {k} of {n} of this rung: remove it and "
                    f"train it again with --part {k}/{n}"
                )
            last = [math.nan if v is None else v for v in recorded["scores"]]
            shares.append(
                _Share(
                    runs,
                    np.asarray(last, float),
                    np.asarray(recorded["diverged"], bool),
                    leaves,
                    recorded["seconds"],
                    recorded["compile_seconds"],
                )
            )
        self._say(
            f"{self.task}: rung {rung + 1}: joining its parts ({len(shares)} of {n} had runs to "
            "train)"
        )
        return shares

    def _share(self, part: tuple[int, int]) -> _Share:
        """Trains `part`'s share of the next rung: whole groups of the rung's runs (:meth:`_groups`;
        the last one filled up with the rung's last run), each a call of one program."""
        rung, order = len(self.scores), self._order()
        size, groups = self._groups(len(order))
        first, stop = share_bounds(part, groups)
        runs = order[first * size : stop * size]
        if not runs:
            return _Share([], np.zeros(0), np.zeros(0, bool), [], 0.0, 0.0)
        rungs, trainer = self.rungs, self.prepared.trainer
        start = 0 if rung == 0 else rungs.ends[rung - 1]
        live = ", ".join(f"{len(t)} {arm}" for arm, t in self.live.items())
        split = "" if part == (1, 1) else f", part {part[0]} of {part[1]}"
        grouped = "" if groups == 1 else f" in groups of {size}, {len(runs)} of them here"
        self._say(
            f"{self.task}: rung {rung + 1} of {len(rungs.trials)}{split}: trials {live} × "
            f"{len(self.seeds)} seeds = {len(order)} runs{grouped}, updates {start + 1}–"
            f"{rungs.ends[rung]} of {trainer.config.num_updates}; compiling…"
        )
        check_host_memory(trainer, size)
        began, program = time.perf_counter(), None
        lasts, diverged, leaves = [], [], []
        for group in range(first, stop):
            # Every group has one shape, so one program: the rung's last run fills up its last.
            index = np.minimum(np.arange(group * size, (group + 1) * size), len(order) - 1)
            keys, hps = self._inputs([order[i] for i in index])
            if program is None:
                program = compile_program(trainer, keys, hps, jax.vmap, rungs.updates_per_call)
                self._say(
                    f"{self.task}: rung {rung + 1} compiled in {program.compile_seconds:.1f} s"
                )
            said = f"{self.task}: rung {rung + 1}" + (
                f", group {group + 1} of {groups}" if groups > 1 else ""
            )
            state, last = self._train(program, keys, hps, index, len(order), rung, said)
            kept = slice(0, len(order) - group * size)  # the group's own runs, not the fill
            lasts.append(last[kept])
            diverged.append(fetch_diverged(state)[kept])
            if rung + 1 < len(rungs.trials):  # the last rung's state goes on nowhere
                leaves.append([_plain(leaf)[kept] for leaf in jax.tree.leaves(state)])
        assert program is not None
        return _Share(
            runs,
            np.concatenate(lasts),
            np.concatenate(diverged),
            [np.concatenate(leaf) for leaf in zip(*leaves, strict=True)],
            time.perf_counter() - began - program.compile_seconds,
            program.compile_seconds,
        )

    def _inputs(self, runs: list[tuple[str, int, int]]) -> tuple[jax.Array, Any]:
        """The keys and the stacked hyperparameters of `runs` (arm, trial, seed)."""
        surrogates = {arm.name: arm for arm in self.arms}
        hps = stack_hyperparameters(
            [
                resolve_hyperparameters(surrogates[arm], None, **self.settings[arm][trial])[0]
                for arm, trial, _ in runs
            ]
        )
        return run_keys([seed for _, _, seed in runs]), hps

    def _train(
        self,
        program: Any,
        keys: jax.Array,
        hps: Any,
        index: np.ndarray,
        runs: int,
        rung: int,
        said: str,
    ) -> tuple[TrainState, np.ndarray]:
        """The runs `index` of the rung's `runs` (their `keys` and `hps`) trained by `program`
        through `rung`, from the recorded state of the rung before: their state and each
        run's score (`said` names them in progress lines)."""
        rungs, trainer = self.rungs, self.prepared.trainer
        start = 0 if rung == 0 else rungs.ends[rung - 1]
        if rung == 0:
            state = program.init(keys, hps)
        else:
            like = jax.eval_shape(jax.vmap(trainer.init), keys, hps)
            state = _load_state(self._where(rung - 1) / _STATE, like, index, runs)
            if resets_itself(trainer.env):  # their state lived outside JAX, in another batch
                state = jax.jit(jax.vmap(trainer.restart_envs))(state)
        budgeted = with_budget(hps, trainer.config.num_updates)
        last = np.full(len(index), np.nan)
        calls = -(-(rungs.ends[rung] - start) // rungs.updates_per_call)
        began = time.perf_counter()
        for call in range(calls):
            state, metrics = program.run(state, budgeted)
            returns, steps = jax.device_get((metrics.average_return, metrics.env_steps))
            ran = steps[0] >= 0
            if ran.any():
                last = returns[:, ran][:, -1]
            if (call + 1) % -(-calls // CALLS_A_RUNG) == 0 and call + 1 < calls:
                done = min(start + (call + 1) * rungs.updates_per_call, rungs.ends[rung])
                rate = (done - start) * trainer.config.samples_per_update * len(index)
                self._say(
                    f"{said}: update {done} of {rungs.ends[rung]}, "
                    f"{rate / (time.perf_counter() - began):,.0f} env steps/s"
                )
        return state, last

    def _scores(
        self,
        order: list[tuple[str, int, int]],
        last: np.ndarray | None,
        diverged: np.ndarray,
        rung: int,
    ) -> dict[str, Any]:
        """Each arm's live trials' scores at the end of `rung`, and those that go on."""
        scores: dict[str, Any] = {}
        going_on = self.rungs.trials[min(rung + 1, len(self.rungs.trials) - 1)]
        for arm, trials in self.live.items():
            rows: list[dict[str, Any]] = []
            for trial in trials:
                runs = [i for i, (a, t, _) in enumerate(order) if a == arm and t == trial]
                values = np.asarray(last)[runs].astype(float)
                bad = bool(diverged[runs].any())
                mean = float(np.mean(values))
                rows.append(
                    {
                        "trial": trial,
                        "score": mean if math.isfinite(mean) else None,
                        "seed_scores": [float(v) if math.isfinite(v) else None for v in values],
                        "diverged": bad,
                    }
                )
            scores[arm] = {
                "trials": rows,
                "survivors": sorted(r["trial"] for r in ranked(rows)[:going_on]),
            }
        return scores

    def results(self, baseline: str) -> dict[str, Any]:
        """Per arm: the chosen setting, trial 0's and the rungs' scores, the steps used."""
        from fppo_jax.analysis.tuning_report import arm_results

        return {
            arm.name: arm_results(
                arm.name,
                baseline,
                self.scores,
                self.settings,
                self.rungs,
                len(self.seeds),
                self.prepared.config.samples_per_update,
            )
            for arm in self.arms
        }

    def _say(self, line: str) -> None:
        if self.progress:
            print(line, file=sys.stderr, flush=True)


def fetch_diverged(state: TrainState) -> np.ndarray:
    """Whether each run's loss or parameters stopped being finite."""
    return np.asarray(jax.device_get(state.nonfinite_update)) >= 0


def _save_leaves(path: Path, leaves: list[np.ndarray]) -> None:
    """A state's leaves (:func:`_plain`: keys as their data), atomically, in order."""
    path.parent.mkdir(parents=True, exist_ok=True)
    buffer = io.BytesIO()
    np.savez(buffer, *leaves)
    write_atomically(path, buffer.getvalue())


def _read_leaves(path: Path) -> list[np.ndarray]:
    """The leaves that :func:`_save_leaves` wrote in `path`."""
    if not path.exists():
        raise MissingFile(f"{path} is missing: remove its rung (or part) to train it again")
    try:
        with np.load(path) as saved:
            return [saved[f"arr_{i}"] for i in range(len(saved.files))]
    except Exception as error:  # a damaged or foreign file: NumPy's and zipfile's errors
        raise InvalidInput(
            f"cannot read {path}: {error}; remove its rung to train it again"
        ) from None


def _load_state(path: Path, like: Any, index: np.ndarray, runs: int) -> TrainState:
    """Runs `index` of the `runs` runs whose state `path` holds, checked against `like`
    (theirs), on the device."""
    leaves, treedef = jax.tree.flatten(like)
    arrays = _read_leaves(path)
    restored = []
    for saved, leaf in zip(arrays, leaves, strict=False):
        array: Any = saved[index] if len(saved) == runs else saved  # the check below refuses it
        if jax.numpy.issubdtype(leaf.dtype, jax.dtypes.prng_key):
            array = jax.random.wrap_key_data(array)
        if array.shape != leaf.shape:
            break
        restored.append(array)
    if len(arrays) != len(leaves) or len(restored) != len(leaves):
        raise InvalidInput(f"{path} does not hold this tune's state; remove its rung")
    return cast(TrainState, jax.device_put(jax.tree.unflatten(treedef, restored)))


def _plain(leaf: Any) -> np.ndarray:
    if jax.numpy.issubdtype(leaf.dtype, jax.dtypes.prng_key):
        leaf = jax.random.key_data(leaf)
    return np.asarray(jax.device_get(leaf))


def plan_digest(directory: Path) -> str:
    """The SHA-256 of a tune's ``tune.json``, which a study on its settings records."""
    path = Path(directory) / PLAN_FILE
    if not path.exists():
        raise MissingFile(f"{directory} holds no tune ({PLAN_FILE} is missing)")
    return hashlib.sha256(path.read_bytes()).hexdigest()
