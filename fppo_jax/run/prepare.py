"""What ``train`` and ``sweep`` both do before driving: split their keyword settings into the
run's shape (:class:`~fppo_jax.core.config.TrainConfig`), its hyperparameters and the host
:class:`~fppo_jax.run.options.Options`; resolve the task and its backend once; check all of it
before an environment is built or anything compiles; turn the compilation cache on
(:mod:`fppo_jax.run.compile_cache`)."""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Mapping
from typing import Any

from fppo_jax.core.config import TrainConfig, describe, environment_name, resolve_config
from fppo_jax.core.trainer import Trainer, make_train
from fppo_jax.envs import Environment, as_environment, choose_backend, describe_backend, make_env
from fppo_jax.run import compile_cache
from fppo_jax.run.options import Options
from fppo_jax.store.record import RunRecord


@dataclasses.dataclass(frozen=True)
class Prepared:
    """A run's (or a sweep's) settings: `config` and `options`, checked; the hyperparameter
    values given (`hyperparameters`, by name, as given: checked as they are resolved per
    variant; a sweep's may be lists of values); the registered `task` (None for an environment
    object) and the `backend` chosen (`why`: how "auto" chose it). The environment and the
    trainer are built on first use."""

    env: Any
    task: str | None
    backend: str
    why: str
    preset: str
    config: TrainConfig
    options: Options
    hyperparameters: Mapping[str, object]

    @functools.cached_property
    def environment(self) -> Environment:
        if isinstance(self.env, str):
            return make_env(self.env, self.backend)
        return as_environment(self.env)

    @functools.cached_property
    def trainer(self) -> Trainer:
        check = getattr(self.environment, "check_batch", None)  # vector environments' sizes
        if check is not None:
            check(self.config.num_envs)
            if self.options.eval_every is not None:
                check(self.options.eval_episodes)
        return make_train(self.config, self.environment)

    @property
    def name(self) -> str:
        """The environment's name, as records show it."""
        return environment_name(self.env, self.environment)

    def record(self) -> RunRecord:
        """The protocol the run trains under: its environment, backend, preset and shape
        (``train`` and ``sweep`` add their settings and seeds to it)."""
        return RunRecord(self.name, self.backend, self.preset, self.config)

    def header(self, description: str, runs: str = "") -> str:
        """The line printed before compiling: `description`, the backend, `runs` (a sweep's
        count of them) and each run's shape."""
        backend = describe_backend(self.backend, self.why)
        return f"{description}{backend}: {runs}{describe(self.config, self.preset)}"


def prepare(
    env: str | Environment | Any,
    settings: Mapping[str, object],
    hyperparameters: tuple[str, ...],
    *,
    total_steps: int | None,
    preset: str,
    backend: str,
) -> Prepared:
    """`settings` (``train``'s or ``sweep``'s keyword arguments) split and checked: the names
    in `hyperparameters` are kept for the caller to resolve per variant, the options and the
    :class:`TrainConfig` fields are checked, and any other name is refused, listing every
    valid one."""
    options, overrides = Options.split(settings)
    given = {name: overrides.pop(name) for name in list(overrides) if name in hyperparameters}
    valid = (*hyperparameters, *Options.names())
    config = resolve_config(env, total_steps, overrides, also_valid=valid, preset=preset)
    chosen, why = choose_backend(env, backend)
    task = env if isinstance(env, str) else None
    compile_cache.enable()
    return Prepared(env, task, chosen, why, preset, config, options, given)
