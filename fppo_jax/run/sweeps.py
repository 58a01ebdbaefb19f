# mypy: allow-redefinition
"""Sweeps: the cartesian product of hyperparameter values, times seeds, as one compiled program.

Every run is the pure ``train_fn(key, hp)`` vmapped along a run axis, so variants, α, k, δ,
ε, learning rates … and seeds all train side by side, and a bigger grid is the same program
called on more runs. Runs are split into equal groups only when they do not fit in memory, or
when `chunk` says so; the groups are the whole sweep's, and a part of a split sweep trains whole
groups of them, so that the parts merge into the unsplit sweep bit for bit.
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import math
import sys
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from fppo_jax.core.checks import check_seeds, positive_int, real_number
from fppo_jax.core.config import Hyperparameters, Setting, stack_hyperparameters
from fppo_jax.core.objectives import hyperparameter_names, identities, takers, union
from fppo_jax.core.resolution import (
    HYPERPARAMETER_DEFAULTS,
    resolve,
    resolve_hyperparameters,
    sweepable,
    table2,
)
from fppo_jax.core.surrogates import Surrogate
from fppo_jax.core.variants import BUILTINS, DEFAULT_VARIANT
from fppo_jax.envs import Environment
from fppo_jax.errors import InvalidInput
from fppo_jax.run.driver import drive
from fppo_jax.run.execution import run_keys
from fppo_jax.run.plan import Outcome, Plan, part_bounds, part_runs
from fppo_jax.run.prepare import Prepared, prepare
from fppo_jax.run.results import SweepResult, labels
from fppo_jax.store.machine import describe_machine
from fppo_jax.store.record import RunRecord
from fppo_jax.store.sweep_files import SweepRun

# The most combinations of values a grid may give: far more than a sweep trains (each of them
# times the seeds), so more is a mistyped grid, refused before its settings are built.
MAX_SETTINGS = 10_000


def expand_grid(
    grid: Mapping[str, Any] | Sequence[Mapping[str, Any]], task: str | None = None
) -> list[Setting]:
    """The distinct settings of a grid, in order: every combination of its values.

    Its variants are built-ins' names or surrogates of one's own; a setting names its variant.
    A variant-specific value (α, k, δ, a surrogate's own) applies to the variants that take it
    and is dropped for the others, so ``{"variant": ["ppo", "fppo-lp"], "alpha": [1.1, 1.3]}``
    is three settings. For a registered `task`, FPPO-LP's α and FPPO-QP's k default to the
    paper's Table 2. A list of settings instead of a grid (each a mapping with its
    ``variant`` and values, such as each arm's tuned setting) is those settings, in order.
    """
    if not isinstance(grid, Mapping):
        return _listed_settings(grid, task)
    surrogates = grid_surrogates(grid)
    specific = hyperparameter_names([*BUILTINS.values(), *surrogates.values()])
    valid = sweepable(surrogates.values())
    unknown = sorted(set(grid) - set(valid))
    if unknown:
        raise InvalidInput(f"cannot sweep {', '.join(unknown)}; sweepable: {', '.join(valid)}")
    values = {name: _as_list(name, v) for name, v in grid.items() if name != "variant"}
    combinations = math.prod(map(len, values.values()), start=len(surrogates))
    if combinations > MAX_SETTINGS:
        raise InvalidInput(
            f"the grid gives {combinations:,} combinations of values, more than {MAX_SETTINGS:,}"
            " (each trained for every seed): give its axes fewer values, or split it into sweeps"
        )
    for name in set(values) & set(specific):
        if not takers(name, surrogates):
            everyone = {**BUILTINS, **surrogates}
            raise InvalidInput(
                f"no variant of the grid ({', '.join(surrogates)}) takes {name}; "
                f"it is taken by {', '.join(takers(name, everyone))}"
            )
    settings: list[Setting] = []
    for (variant, surrogate), *combo in itertools.product(surrogates.items(), *values.values()):
        setting: Setting = {"variant": variant}
        for name, value in zip(values, combo, strict=True):
            if name not in specific or name in surrogate.defaults:
                setting[name] = real_number(name, value)
        for name, value in table2(task, variant).items():
            setting.setdefault(name, value)
        if setting not in settings:
            settings.append(setting)
    return settings


def _listed_settings(settings: Sequence[Mapping[str, Any]], task: str | None) -> list[Setting]:
    """A list of settings checked: each names its variant and only values that variant takes,
    Table 2's α or k filled in for a registered `task`; no setting twice."""
    surrogates = grid_surrogates(settings)
    listed: list[Setting] = []
    for given in settings:
        surrogate = surrogates[resolve(given["variant"]).name]
        taken = ("epsilon", *surrogate.defaults, *HYPERPARAMETER_DEFAULTS)
        stray = sorted(set(given) - {"variant", *taken})
        if stray:
            raise InvalidInput(
                f"a setting of {surrogate.name} gives {', '.join(stray)}, which it does not "
                f"take (it takes: {', '.join(taken)})"
            )
        setting: Setting = {"variant": surrogate.name}
        setting |= {k: real_number(k, v) for k, v in given.items() if k != "variant"}
        setting |= {k: v for k, v in table2(task, surrogate.name).items() if k not in setting}
        if setting in listed:
            raise InvalidInput(f"the setting {setting} is listed twice")
        listed.append(setting)
    return listed


def grid_surrogates(grid: Mapping[str, Any] | Sequence[Mapping[str, Any]]) -> dict[str, Surrogate]:
    """The surrogates a grid's variants name, by name, in the grid's order (default: FPPO-LP),
    or those of a list of settings."""
    if not isinstance(grid, Mapping):
        listed = isinstance(grid, Sequence) and not isinstance(grid, str) and bool(grid)
        if not listed or not all(isinstance(s, Mapping) and "variant" in s for s in grid):
            raise InvalidInput(
                "a grid maps names to values, such as {'alpha': [1.1, 1.3]}, and a list of "
                "settings holds mappings that each name their variant, such as "
                f"[{{'variant': 'ppo', 'learning_rate': 1e-3}}]; got {grid!r}"
            )
        listed_surrogates = [resolve(s["variant"]) for s in grid]
        union(listed_surrogates)
        return {s.name: s for s in listed_surrogates}
    given = [resolve(v) for v in _as_list("variant", grid.get("variant", [DEFAULT_VARIANT]))]
    union(given)  # two different surrogates under one name are refused
    return {s.name: s for s in given}


def _as_list(name: str, values: Any) -> list[Any]:
    scalar = isinstance(values, str | int | float) or not isinstance(values, Iterable)
    values = [values] if scalar else list(values)
    if not values:
        raise InvalidInput(f"the grid gives {name} no values")
    return values


def sweep(
    env: str | Environment | Any,
    grid: Mapping[str, Any] | Sequence[Mapping[str, Any]],
    seeds: int | Sequence[int] = 5,
    *,
    chunk: int | None = None,
    total_steps: int | None = None,
    preset: str = "paper",
    backend: str = "auto",
    data_parallel: int | None = None,
    part: tuple[int, int] | None = None,
    **settings: Any,
) -> SweepResult:
    """Train every setting of `grid` (see :func:`expand_grid`: a grid of values, or a list of
    settings) with every seed, as one program.

    `seeds` is a count (0 … n−1) or a list; run (setting, seed) starts from
    ``jax.random.key(seed)``, as ``train(..., seed=seed)`` does, and matches that run to float
    tolerance over its first updates, then drifts from it (vmapped kernels round differently).
    `preset`, `backend` and `settings` are as in :func:`~fppo_jax.train`. `chunk` is the number
    of runs per compiled call, the sweep's group size (default: as many of the sweep's runs as
    fit in half the free memory); the result records it as ``runs_per_call``. A run that
    diverges is recorded in ``SweepResult.diverged``; the others go on.

    Options apply to every run. A checkpoint holds the group of runs in training and the
    metrics of the groups done; a resumed sweep goes on from that group and update. With
    ``log_dir``, each finished group adds its runs to ``curves.csv`` and ``sweep.json`` there
    (:meth:`SweepResult.write`); ``metrics.csv`` has a ``run`` column. A callback sees one
    group at a time (metrics as [run, update]); returning ``False`` stops the sweep.

    `devices` (default: all JAX sees) share each group's runs, `data_parallel` (default 1) per
    run, splitting its environments (:mod:`fppo_jax.run.distributed`). ``part=(K, N)`` trains the
    K-th (from 1) of N shares of the whole sweep's groups of `chunk` runs, in run order
    (settings × seeds), to split a sweep over a cluster's nodes; :func:`~fppo_jax.merge` joins
    the parts, naming any missing run, into the sweep trained unsplit with the same `chunk`,
    bit for bit (XLA rounds a vmapped program by its batch size, so a run's numbers depend on
    its group's size; a split keeps each run's group, and its place in it). A split needs as
    many groups as parts: give `chunk` when the sweep's runs fit in one call.
    """
    surrogates = grid_surrogates(grid)
    names = sweepable(surrogates.values())
    run = prepare(env, settings, names, total_steps=total_steps, preset=preset, backend=backend)
    settings, hps = _settings(grid, run.hyperparameters, surrogates, run.task)
    seeds = check_seeds(seeds)
    runs = _runs(len(settings), seeds, part)
    for name, value in {"chunk": chunk, "data_parallel": data_parallel}.items():
        if value is not None:
            positive_int(name, value)
    if part is not None and chunk is not None:  # refused before anything starts
        part_runs(part, len(runs), min(chunk, len(runs)))
    record = _record(run, grid, surrogates, seeds, part)
    result_of = functools.partial(_result, settings, runs, record, part)
    log_dir = run.options.log_dir  # a finished group is written at once, lost by no later crash
    after_group = None if log_dir is None else lambda done: result_of(done).write(log_dir)
    how = {"runs_per_call": chunk, "data_parallel": data_parallel or 1, "after_group": after_group}
    plan = _plan(run, settings, runs, hps, record, share=part, **how)
    result = result_of(drive(plan, run.options))
    _warn_diverged(result)
    return result


def _record(
    run: Prepared,
    grid: Mapping[str, Any] | Sequence[Mapping[str, Any]],
    surrogates: dict[str, Surrogate],
    seeds: list[int],
    part: tuple[int, int] | None,
) -> RunRecord:
    """What the sweep's outputs and checkpoints record of it: its grid, or for a list of
    settings each axis's values in them (as a merged sweep records its parts')."""
    values = {key: _as_list(key, v) for key, v in {**_axes(grid), **run.hyperparameters}.items()}
    if "variant" in values:
        values["variant"] = list(surrogates)
    own = identities(surrogates.values()).get("surrogates", {})
    return dataclasses.replace(
        run.record(), grid=values, seeds=tuple(seeds), part=part, surrogates=own
    )


def _result(
    settings: list[Setting],
    runs: list[SweepRun],
    record: RunRecord,
    part: tuple[int, int] | None,
    outcome: Outcome,
) -> SweepResult:
    """The sweep's result (its `part`'s, if given, of the whole sweep's `runs`): its runs done
    so far, from the driver's `outcome`."""
    if part is not None:  # the share of the sweep's groups the driver trained
        runs = runs[slice(*part_runs(part, len(runs), outcome.runs_per_call))]
    return SweepResult(
        settings=settings,
        seeds=list(dict.fromkeys(run["seed"] for run in runs)),
        runs=runs[: len(outcome.diverged)],
        metrics=outcome.metrics,
        diverged=outcome.diverged,
        config=dataclasses.replace(record, runs_per_call=outcome.runs_per_call).to_json(),
        compile_seconds=outcome.compile_seconds,
        train_seconds=outcome.train_seconds,
        machines=[describe_machine()],
    )


def _plan(
    run: Prepared,
    settings: list[Setting],
    runs: list[SweepRun],
    hps: Hyperparameters,
    record: RunRecord,
    **how: Any,
) -> Plan:
    """The sweep's runs as the driver's plan, `how` it drives them (the :class:`Plan`'s
    fields)."""
    seeds = len(record.seeds or ())
    shape = f"{len(settings)} settings × {seeds} seeds = {len(settings) * seeds} runs"
    if record.part is not None:
        shape += f", part {record.part[0]} of {record.part[1]}"
    return Plan(
        "sweep",
        run.trainer,
        run_keys([run["seed"] for run in runs]),
        # Every run in the program of all the sweep's surrogates, so that a part is the whole
        # sweep's program on fewer groups (the driver takes the part's share of them).
        jax.tree.map(lambda x: x[jnp.asarray([run["setting"] for run in runs])], hps),
        record,
        f"sweep on {run.name}",
        run.header(f"sweep on {run.name}", f"{shape}; each "),
        runs=tuple({**settings[run["setting"]], "seed": run["seed"]} for run in runs),
        **how,
    )


def _axes(grid: Mapping[str, Any] | Sequence[Mapping[str, Any]]) -> Mapping[str, object]:
    """The grid's names and their values: a grid's own (a value or a list of them), or for a
    list of settings the values they give each name, in order."""
    if isinstance(grid, Mapping):
        return grid
    axes: dict[str, list[object]] = {}
    for setting in grid:
        for key, value in setting.items():
            known = axes.setdefault(key, [])
            if value not in known:
                known.append(value)
    return axes


def _runs(num_settings: int, seeds: list[int], part: tuple[int, int] | None) -> list[SweepRun]:
    """The whole sweep's runs (settings × seeds, in that order), with its `part` checked (the
    driver takes the part's share of the runs once it knows their group size)."""
    runs = [SweepRun(setting=i, seed=seed) for i in range(num_settings) for seed in seeds]
    if part is not None:
        part_bounds(part, len(runs))
    return runs


def _settings(
    grid: Mapping[str, Any] | Sequence[Mapping[str, Any]],
    fixed: Mapping[str, object],
    surrogates: dict[str, Surrogate],
    task: str | None,
) -> tuple[list[Setting], Hyperparameters]:
    """The grid's settings with the `fixed` values (the sweep's keyword arguments that name
    hyperparameters, as given: a value or a list of them each), and their hyperparameters
    stacked."""
    if "variant" in fixed:  # the grid's variants are what its surrogates were made for
        raise InvalidInput(
            "a sweep's variants are the grid's: give {'variant': ...} in the grid, not variant="
        )
    clash = sorted(set(fixed) & set(_axes(grid)))
    if clash:
        raise InvalidInput(f"{', '.join(clash)} given both in the grid and as a fixed value")
    if isinstance(grid, Mapping):
        settings = expand_grid({**grid, **fixed}, task)
    else:
        settings = expand_grid([{**setting, **fixed} for setting in grid], task)
    # expand_grid applied Table 2 to each setting: resolved as given, not again per task.
    hps = stack_hyperparameters(
        [
            resolve_hyperparameters(surrogates[str(setting["variant"])], None, **values)[0]
            for setting in settings
            for values in [{k: v for k, v in setting.items() if k != "variant"}]
        ]
    )
    return settings, hps


def _warn_diverged(result: SweepResult) -> None:
    names = labels(result.settings)
    for i in np.flatnonzero(result.diverged):
        run = result.runs[i]
        print(
            f"warning: run {i} ({names[run['setting']]}, seed {run['seed']}) diverged at update "
            f"{result.diverged[i]}; its state before that update was kept",
            file=sys.stderr,
        )
