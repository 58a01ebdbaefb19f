"""``train(env, variant, alpha)``: one run, resolved and checked before compiling, then driven."""

from __future__ import annotations

import dataclasses
from typing import Any

from fppo_jax.core.checks import check_seed
from fppo_jax.core.objectives import hyperparameter_names, identities
from fppo_jax.core.policy import make_policy
from fppo_jax.core.resolution import HYPERPARAMETER_DEFAULTS, resolve, resolve_hyperparameters
from fppo_jax.core.surrogates import Surrogate
from fppo_jax.core.variants import BUILTINS, DEFAULT_VARIANT, EPSILON
from fppo_jax.envs import Environment
from fppo_jax.run.distributed import is_main_process
from fppo_jax.run.driver import drive
from fppo_jax.run.execution import batch_of_one_on_device, first_run, first_run_on_device, run_keys
from fppo_jax.run.plan import Outcome, Plan
from fppo_jax.run.prepare import Prepared, prepare
from fppo_jax.run.train_result import TrainResult
from fppo_jax.store.record import RunRecord


def train(
    env: str | Environment | Any = "cartpole",
    variant: str | Surrogate = DEFAULT_VARIANT,
    alpha: float | None = None,
    *,
    k: float | None = None,
    delta: float | None = None,
    epsilon: float = EPSILON,
    seed: int = 0,
    total_steps: int | None = None,
    preset: str = "paper",
    backend: str = "auto",
    **settings: Any,
) -> TrainResult:
    """Train one policy with `variant` on `env`; return its metrics, parameters and policy.

    `env` is a registered or namespaced name (:data:`fppo_jax.envs.TASKS`, ``gymnax/…``,
    ``gymnasium/…``) or an environment object (the kinds :func:`~fppo_jax.envs.as_environment`
    takes). On a registered task, α and k default to the paper's Table 2 and `total_steps` to
    its budget. `preset` is the run's shape (:data:`fppo_jax.core.config.PRESETS`: ``"paper"``, 8
    environments × 256 steps; ``"massive"``, 2048 × 16, for a GPU). `backend` runs a MuJoCo task
    on ``"mjx"``, in ``"native"`` MuJoCo (envpool), or ``"auto"``: MJX on a GPU or TPU, else
    native. `settings` are :class:`TrainConfig` fields, optimisation settings
    (``learning_rate``, ``gamma``, …) and :class:`~fppo_jax.run.options.Options` (progress,
    checkpoints, logs, devices, callback, evaluation), all checked before compiling. With
    ``log_dir``, the run's ``summary.txt`` is written there at the end.

    Raises :class:`TrainingDiverged` if the loss or the parameters stop being finite (the last
    good checkpoint stays on disk).
    """
    surrogate = resolve(variant)
    names = (*hyperparameter_names([*BUILTINS.values(), surrogate]), *HYPERPARAMETER_DEFAULTS)
    run = prepare(env, settings, names, total_steps=total_steps, preset=preset, backend=backend)
    hp, setting = resolve_hyperparameters(
        surrogate, run.task, epsilon=epsilon, alpha=alpha, k=k, delta=delta, **run.hyperparameters
    )
    seed = check_seed(seed)
    own = identities([surrogate]).get("surrogates", {})
    record = dataclasses.replace(run.record(), setting=setting, seed=seed, surrogates=own)
    description = f"{surrogate.name} on {run.name}"
    keys, hps = run_keys([seed]), batch_of_one_on_device(hp)
    plan = Plan("train", run.trainer, keys, hps, record, description, run.header(description))
    return _result(run, record, drive(plan, run.options))


def _result(run: Prepared, record: RunRecord, outcome: Outcome) -> TrainResult:
    """The run's result, its ``summary.txt`` written beside what the driver wrote in ``log_dir``."""
    metrics, state = first_run(outcome.metrics), first_run_on_device(outcome.state)
    result = TrainResult(
        metrics=metrics,
        params=state.params,
        config=record.to_json(),
        state=state,
        policy=make_policy(run.trainer, state),
        compile_seconds=outcome.compile_seconds,
        train_seconds=outcome.train_seconds,
        env=run.environment,
        resumed_from=outcome.resumed_from,
        stopped_at=outcome.stopped_at,
    )
    if run.options.log_dir is not None and is_main_process():
        result.write(run.options.log_dir)
    return result
