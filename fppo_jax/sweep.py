"""Sweeps: the cartesian product of hyperparameter values, times seeds, as one compiled program.

Every run is the pure ``train_fn(key, hp)`` vmapped along a run axis, so variants, α, k, δ,
ε, learning rates … and seeds all train side by side, and a bigger grid is the same program
called on more runs. Runs are split into equal chunks only when they do not fit in memory.
"""

from __future__ import annotations

import csv
import dataclasses
import itertools
import json
import os
import sys
import warnings
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh

from fppo_jax.api import (
    TABLE2,
    checkpoint_every_updates,
    describe,
    env_name,
    open_checkpoints,
    resolve_config,
)
from fppo_jax.checkpoint import Checkpoints, ConfigMismatch, Restored
from fppo_jax.config import HYPERPARAMETER_DEFAULTS, Hyperparameters, hyperparameters
from fppo_jax.distributed import fetch, is_main_process, make_mesh
from fppo_jax.envs import Environment, as_environment
from fppo_jax.execution import (
    PROGRESS_LINES,
    Program,
    Progress,
    compile_program,
    execute,
    reporter,
    updates_per_call,
)
from fppo_jax.objectives import DEFAULTS as VARIANT_DEFAULTS
from fppo_jax.objectives import VARIANTS
from fppo_jax.trainer import METRICS, Trainer, TrainState, make_train

SWEEPABLE: tuple[str, ...] = ("variant", "epsilon", "alpha", "k", "delta", *HYPERPARAMETER_DEFAULTS)
_VARIANT_SPECIFIC = ("alpha", "k", "delta")
_SYMBOLS = {"alpha": "α", "k": "k", "delta": "δ", "epsilon": "ε"}


def expand_grid(grid: Mapping[str, Any], task: str | None = None) -> list[dict[str, Any]]:
    """The distinct settings of a grid, in order: every combination of its values.

    A variant-specific value (α, k, δ) applies to the variants that take it and is dropped for
    the others, so ``{"variant": ["ppo", "fppo-lp"], "alpha": [1.1, 1.3]}`` is three settings.
    For a registered `task`, FPPO-LP's α and FPPO-QP's k default to the paper's Table 2.
    """
    unknown = sorted(set(grid) - set(SWEEPABLE))
    if unknown:
        raise ValueError(f"cannot sweep {', '.join(unknown)}; sweepable: {', '.join(SWEEPABLE)}")
    values = {name: _as_list(name, v) for name, v in grid.items()}
    variants = values.pop("variant", ["fppo-lp"])
    bad = [v for v in variants if v not in VARIANTS]
    if bad:
        raise ValueError(f"unknown variant {bad[0]!r}; valid variants: {', '.join(VARIANTS)}")
    defaults = TABLE2[task] if task in TABLE2 else None
    settings: list[dict[str, Any]] = []
    for variant, *combo in itertools.product(variants, *values.values()):
        setting: dict[str, Any] = {"variant": variant}
        for name, value in zip(values, combo, strict=True):
            if name not in _VARIANT_SPECIFIC or name in VARIANT_DEFAULTS[variant]:
                setting[name] = float(value)
        if defaults and variant == "fppo-lp":
            setting.setdefault("alpha", defaults["alpha"])
        if defaults and variant == "fppo-qp":
            setting.setdefault("k", defaults["k"])
        if setting not in settings:
            settings.append(setting)
    return settings


def _as_list(name: str, values: Any) -> list:
    values = [values] if isinstance(values, str | int | float) else list(values)
    if not values:
        raise ValueError(f"the grid gives {name} no values")
    return values


def labels(settings: Sequence[Mapping[str, Any]]) -> list[str]:
    """Each setting in a few characters, e.g. ``fppo-lp α=1.3``: the variant, its own α, k or δ,
    and whatever else differs between the settings."""
    keys = dict.fromkeys(k for s in settings for k in s if k != "variant")
    varying = {k for k in keys if len({s.get(k) for s in settings}) > 1}
    shown = [k for k in keys if k in _VARIANT_SPECIFIC or k in varying]
    return [
        " ".join([str(s["variant"]), *[f"{_SYMBOLS.get(k, k)}={s[k]:g}" for k in shown if k in s]])
        for s in settings
    ]


@dataclasses.dataclass
class SweepResult:
    """Every run of a sweep: `runs[i]` is run i's setting and seed, `metrics[name][i]` its
    per-update values, `diverged[i]` the update (from 1) where it diverged, or 0."""

    settings: list[dict[str, Any]]
    seeds: list[int]
    runs: list[dict[str, Any]]
    metrics: dict[str, np.ndarray]
    diverged: np.ndarray
    config: dict[str, Any]
    compile_seconds: float
    train_seconds: float

    def setting_metrics(self, index: int) -> dict[str, np.ndarray]:
        """Metrics of setting `index`, [seed, update]."""
        rows = [i for i, run in enumerate(self.runs) if run["setting"] == index]
        return {name: values[rows] for name, values in self.metrics.items()}

    def table(self) -> str:
        """Table 1 style, one row per setting: max average return (SPEC §2) and more, Markdown."""
        lines = [
            "| setting | max average return | at env steps | final average return "
            "| in R± after update |",
            "|---|---|---|---|---|",
        ]
        for index, name in enumerate(labels(self.settings)):
            m = self.setting_metrics(index)
            best, std, at = max_average_return(m["average_return"])
            final = _nanmean(m["average_return"][:, -1]) if m["average_return"].size else np.nan
            steps = int(m["env_steps"][0, at]) if at >= 0 else 0
            lines.append(
                f"| {name} | {best:.1f} ± {std:.1f} | {steps:,} | {final:.1f} | "
                f"{np.mean(m['negative_fraction_after']):.2%} |"
            )
        return "\n".join(lines)

    def write(self, directory: str | Path) -> None:
        """`curves.csv` (one row per run and update) and `sweep.json` (everything else)."""
        directory = Path(directory)
        directory.mkdir(parents=True, exist_ok=True)
        keys = list(dict.fromkeys(k for s in self.settings for k in s))
        with open(directory / "curves.csv", "w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(["run", "seed", *keys, "update", *METRICS])
            for i, run in enumerate(self.runs):
                setting = self.settings[run["setting"]]
                head = [i, run["seed"], *[setting.get(k, "") for k in keys]]
                for u in range(self.metrics["env_steps"].shape[1]):
                    values = [self.metrics[name][i, u].item() for name in METRICS]
                    writer.writerow([*head, u + 1, *values])
        record = {
            "settings": self.settings,
            "seeds": self.seeds,
            "runs": self.runs,
            "diverged": self.diverged.tolist(),
            "config": self.config,
            "compile_seconds": self.compile_seconds,
            "train_seconds": self.train_seconds,
        }
        (directory / "sweep.json").write_text(json.dumps(record, indent=2) + "\n")

    @classmethod
    def read(cls, directory: str | Path) -> SweepResult:
        """What :meth:`write` wrote."""
        directory = Path(directory)
        for name in ("sweep.json", "curves.csv"):
            if not (directory / name).is_file():
                raise FileNotFoundError(f"{directory / name} not found: not a sweep's output")
        record = json.loads((directory / "sweep.json").read_text())
        with open(directory / "curves.csv", newline="") as f:
            rows = list(csv.DictReader(f))
        num_runs = len(record["runs"])
        num_updates = len(rows) // max(num_runs, 1)
        metrics = {
            name: np.array([float(r[name]) for r in rows]).reshape(num_runs, num_updates)
            for name in METRICS
        }
        metrics["env_steps"] = metrics["env_steps"].astype(np.int64)
        return cls(
            settings=record["settings"],
            seeds=record["seeds"],
            runs=record["runs"],
            metrics=metrics,
            diverged=np.asarray(record["diverged"]),
            config=record["config"],
            compile_seconds=record["compile_seconds"],
            train_seconds=record["train_seconds"],
        )


def max_average_return(average_return: np.ndarray) -> tuple[float, float, int]:
    """SPEC §2 on [seed, update]: the maximum over updates of the seed-mean curve, the std across
    seeds at that update, and the update's index (NaN, NaN, −1 if no episode ever finished)."""
    curve = _nanmean(average_return, axis=0)
    if not np.isfinite(curve).any():
        return np.nan, np.nan, -1
    best = int(np.nanargmax(curve))
    return float(curve[best]), float(np.nanstd(average_return[:, best])), best


def _nanmean(x: np.ndarray, axis: int | None = None) -> np.ndarray:
    with warnings.catch_warnings():
        # All-NaN slices (no episode finished yet in any seed) are meant to stay NaN.
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmean(x, axis=axis)


def sweep(
    env: str | Environment | Any,
    grid: Mapping[str, Any],
    seeds: int | Sequence[int] = 5,
    *,
    chunk: int | None = None,
    total_steps: int | None = None,
    preset: str = "paper",
    progress: bool | Callable[[Progress], None] = False,
    checkpoint_dir: str | Path | None = None,
    resume: bool = False,
    checkpoint_every: int | None = None,
    keep: int = 3,
    devices: int | None = None,
    data_parallel: int | None = None,
    **overrides: Any,
) -> SweepResult:
    """Train every setting of `grid` (see :func:`expand_grid`) with every seed, as one program.

    `seeds` is a count (0 … n−1) or a list; run (setting, seed) starts from
    ``jax.random.key(seed)``, as ``train(..., seed=seed)`` does, and matches that run.
    `preset` and `overrides` are as in :func:`~fppo_jax.train`: a preset's
    :class:`~fppo_jax.config.TrainConfig`, its fields, and fixed values of sweepable
    hyperparameters. `chunk` is the number of runs per compiled call (default: as many as fit
    in half the free memory). A run that diverges is reported and recorded in
    ``SweepResult.diverged``; the others go on.

    `checkpoint_dir`, `resume`, `checkpoint_every` and `keep` are as in
    :func:`~fppo_jax.train`: the state of the group of runs in training is saved every
    `checkpoint_every` updates, with the metrics of the groups already done, and a resumed
    sweep goes on from the group and update where it stopped (with the same runs per call).

    `devices` (default: all JAX sees) share the runs of each group, `data_parallel` of them
    (default 1) per run, splitting its environments (see :mod:`fppo_jax.distributed`); runs
    per call are rounded up to a multiple of ``devices / data_parallel``.
    """
    fixed = {name: overrides.pop(name) for name in list(overrides) if name in SWEEPABLE}
    clash = sorted(set(fixed) & set(grid))
    if clash:
        raise ValueError(f"{', '.join(clash)} given both in the grid and as a fixed value")
    config = resolve_config(env, total_steps, overrides, also_valid=SWEEPABLE, preset=preset)
    settings = expand_grid({**grid, **fixed}, env if isinstance(env, str) else None)
    hps = [hyperparameters(**setting) for setting in settings]  # checks every setting first
    seeds = list(range(seeds)) if isinstance(seeds, int) else [int(s) for s in seeds]
    if not seeds:
        raise ValueError("a sweep needs at least one seed")
    runs = [{"setting": i, "seed": seed} for i in range(len(settings)) for seed in seeds]
    if chunk is not None and chunk < 1:
        raise ValueError(f"chunk must be a positive number of runs, got {chunk}")

    environment = as_environment(env)
    name = env_name(env, environment)
    grid_values = {key: _as_list(key, v) for key, v in {**grid, **fixed}.items()}
    sweep_config = {"env": name, "grid": grid_values, "seeds": seeds, "preset": preset}
    sweep_config.update(dataclasses.asdict(config))
    if checkpoint_dir is not None and jax.process_count() > 1:
        raise ValueError("checkpoints are written by single-process runs only")
    checkpoints, record = open_checkpoints(
        checkpoint_dir, resume, checkpoint_every, keep, "sweep", sweep_config
    )
    try:
        if record is not None:
            if chunk is not None and chunk != record["runs_per_call"]:
                raise ConfigMismatch(
                    f"{checkpoints.directory} holds a sweep of {record['runs_per_call']} runs "
                    f"per compiled call, not {chunk}; resume without chunk, or with that"
                )
            chunk = record["runs_per_call"]
        trainer = make_train(config, environment)
        all_keys = jnp.stack([jax.random.key(run["seed"]) for run in runs])
        all_hps = _stack([hps[run["setting"]] for run in runs])
        mesh = make_mesh(devices, config.num_envs, 1 if data_parallel is None else data_parallel)
        across = mesh.shape["runs"] if mesh else 1  # every group splits evenly over these
        size = _multiple(min(chunk or len(runs), len(runs)), across)
        if record is not None and size != record["runs_per_call"]:
            raise ConfigMismatch(
                f"{checkpoints.directory} holds a sweep of {record['runs_per_call']} runs per "
                f"call, which does not split evenly over {across} devices; resume with devices "
                "that divide it"
            )
        if checkpoints:
            per_call = checkpoint_every_updates(checkpoint_every, config)
        else:
            per_call = updates_per_call(config.num_updates, PROGRESS_LINES if progress else 1)
        if not is_main_process():
            progress = False  # after the chunks are chosen: every process runs one program
        first = _padded(0, size, len(runs))
        restored = None
        if record is not None:
            like = jax.eval_shape(jax.vmap(trainer.init), all_keys[first], _take(all_hps, first))
            restored = checkpoints.restore(like)
        program = compile_program(trainer, all_keys[first], _take(all_hps, first), per_call, mesh)
        if chunk is None:
            program, size = _fit_in_memory(
                program, trainer, all_keys, all_hps, size, per_call, mesh, across
            )
        if progress is True:
            print(
                f"sweep on {name}: {len(settings)} settings × {len(seeds)} seeds = {len(runs)} "
                f"runs, {size} per compiled call; each {describe(config, preset)}",
                file=sys.stderr,
                flush=True,
            )
        with reporter(progress, f"sweep on {name}") as report:
            parts, diverged, seconds = _run_groups(
                program, all_keys, all_hps, len(runs), report, checkpoints, sweep_config, restored
            )
    finally:
        if checkpoints:
            checkpoints.close()
    metrics = _join(parts)
    names = labels(settings)
    for i in np.flatnonzero(diverged):
        print(
            f"warning: run {i} ({names[runs[i]['setting']]}, seed {runs[i]['seed']}) "
            f"diverged at update {diverged[i]}; its state before that update was kept",
            file=sys.stderr,
        )
    return SweepResult(
        settings=settings,
        seeds=seeds,
        runs=runs,
        metrics=metrics,
        diverged=diverged,
        config={**sweep_config, "runs_per_call": size},
        compile_seconds=program.compile_seconds,
        train_seconds=seconds,
    )


def _run_groups(
    program: Program,
    keys: jax.Array,
    hps: Hyperparameters,
    num_runs: int,
    report: Callable[[Progress], None] | None,
    checkpoints: Checkpoints | None,
    sweep_config: dict[str, Any],
    restored: Restored | None,
) -> tuple[list[dict[str, np.ndarray]], np.ndarray, float]:
    """Train the runs in groups of the program's size, from a checkpoint if one is given:
    (each group's metrics, the update each run diverged at or 0, seconds)."""
    size = program.runs
    num_updates = program.trainer.config.num_updates
    parts: list[dict[str, np.ndarray]] = []
    diverged = np.zeros(0, np.int32)
    first, start = 0, None
    if restored is not None:
        curves = restored.curves
        if "finished" in curves:
            parts.append({name: np.asarray(v) for name, v in curves["finished"].items()})
            diverged = np.asarray(curves["finished_diverged"])
        first = restored.record["group"]
        start = (restored.state, {name: np.asarray(v) for name, v in curves["current"].items()})
    seconds = 0.0
    for group in range(first, -(-num_runs // size)):
        begin = group * size
        # The last group is padded with repeats of its last run, so every call has one shape.
        index = _padded(begin, size, num_runs)
        keep = slice(0, min(size, num_runs - begin))
        if report and num_runs > size:
            print(f"runs {begin + 1}–{begin + keep.stop} of {num_runs}", file=sys.stderr)

        save = None
        if checkpoints:
            finished = {"finished": _join(parts), "finished_diverged": diverged} if parts else {}
            save = _saver(checkpoints, sweep_config, group, num_updates, finished)
        state, metrics, secs = execute(
            program,
            keys[index],
            _take(hps, index),
            start=start if group == first else None,
            report=report,
            after_chunk=save,
        )
        parts.append({name: values[keep] for name, values in metrics.items()})
        diverged = np.concatenate([diverged, fetch(state.nonfinite_update)[keep] + 1])
        seconds += secs
    return parts, diverged, seconds


def _saver(
    checkpoints: Checkpoints,
    sweep_config: dict[str, Any],
    group: int,
    num_updates: int,
    finished: dict[str, Any],
) -> Callable[[TrainState, dict[str, np.ndarray]], None]:
    """Checkpoints a group's state and metrics, with `finished`, the groups before it."""

    def save(state: TrainState, metrics: dict[str, np.ndarray]) -> None:
        update = int(np.max(state.update))
        record = {"kind": "sweep", "config": sweep_config, "group": group, "update": update}
        record["runs_per_call"] = state.update.shape[0]
        curves = {"current": metrics, **finished}
        checkpoints.save(group * num_updates + update, state, curves, record)

    return save


def _join(parts: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    return {name: np.concatenate([p[name] for p in parts]) for name in METRICS}


def _stack(hps: list[Hyperparameters]) -> Hyperparameters:
    return jax.tree.map(lambda *xs: jnp.stack(xs), *hps)


def _take(hps: Hyperparameters, index: Any) -> Hyperparameters:
    return jax.tree.map(lambda x: x[index], hps)


def _fit_in_memory(
    program: Program,
    trainer: Trainer,
    keys: jax.Array,
    hps: Hyperparameters,
    size: int,
    per_call: int,
    mesh: Mesh | None,
    across: int,
) -> tuple[Program, int]:
    """Halve the runs per call until the compiled program fits in half the free memory."""
    budget = _free_memory() / 2
    while size > across:
        analysis = program.run.memory_analysis()
        need = analysis.temp_size_in_bytes + 2 * analysis.argument_size_in_bytes
        if need <= budget:
            break
        size = _multiple((size + 1) // 2, across)
        first = _padded(0, size, keys.shape[0])
        program = compile_program(trainer, keys[first], _take(hps, first), per_call, mesh)
    return program, size


def _multiple(size: int, of: int) -> int:
    """`size` rounded up to a multiple of `of`."""
    return -(-size // of) * of


def _padded(begin: int, size: int, num_runs: int) -> np.ndarray:
    """Runs begin … begin + size − 1, the last repeated past the end, so that every group has
    one shape."""
    return np.minimum(np.arange(begin, begin + size), num_runs - 1)


def _free_memory() -> float:
    device = jax.devices()[0]
    stats = device.memory_stats() if hasattr(device, "memory_stats") else None
    if stats and "bytes_limit" in stats:
        return float(stats["bytes_limit"] - stats.get("bytes_in_use", 0))
    return float(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
