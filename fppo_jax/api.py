"""``train(env, variant, alpha)``: one run, resolved and checked before compiling, then driven."""

from __future__ import annotations

from typing import Any

import jax

from fppo_jax.config import (
    HYPERPARAMETER_DEFAULTS,
    check_seed,
    resolve_hyperparameters,
)
from fppo_jax.distributed import is_main_process
from fppo_jax.driver import Plan, drive
from fppo_jax.envs import Environment
from fppo_jax.objectives import (
    BUILTINS,
    DEFAULT_VARIANT,
    EPSILON,
    hyperparameter_names,
    identities,
    resolve,
)
from fppo_jax.policy import make_policy
from fppo_jax.prepare import prepare
from fppo_jax.results import TrainResult
from fppo_jax.surrogates import Surrogate


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
    """Train one policy with `variant` on `env` and return its metrics, parameters and policy.

    `env` is a registered or namespaced name (:data:`fppo_jax.envs.TASKS`, ``gymnax/…``,
    ``gymnasium/…``), a gymnax or Brax environment, a ``gymnasium.Env`` or vector environment
    subclass, a vector environment, or an :class:`~fppo_jax.envs.Environment` (see
    :func:`~fppo_jax.envs.as_environment`). For a registered task, FPPO-LP's α and FPPO-QP's k
    default to the paper's Table 2 and `total_steps` to the paper's budget. `preset` names the
    run's shape (:data:`fppo_jax.config.PRESETS`): ``"paper"`` (the paper's protocol: 8
    environments × 256 steps) or ``"massive"`` (2048 environments × 16 steps, for a GPU).
    `backend` runs a MuJoCo task on ``"mjx"`` or in ``"native"`` MuJoCo (envpool, gym's own
    version of the task), or ``"auto"``: MJX with a GPU or TPU, native on a CPU
    (:data:`fppo_jax.envs.BACKENDS`). `settings` are :class:`TrainConfig` fields (``num_envs``,
    ``num_steps``, ``num_minibatches``, …), optimisation settings (``learning_rate``, ``gamma``,
    ``gae_lambda``, ``entropy_coef``, ``value_coef``, ``max_grad_norm``) and how the run is
    driven (:class:`~fppo_jax.options.Options`: ``progress``, ``checkpoint_dir``, ``resume``,
    ``checkpoint_every``, ``keep``, ``log_dir``, ``devices``, ``callback``, ``eval_every``,
    ``eval_episodes``, ``wandb_project``). Everything is checked before compiling. With
    ``log_dir``, the run's ``summary.txt`` is written there at the end, beside the
    ``config.json``, ``metrics.csv`` and TensorBoard files written as it trains.

    Raises :class:`TrainingDiverged` if the loss or the parameters stop being finite (the last
    good checkpoint stays on disk).
    """
    surrogate = resolve(variant)
    run = prepare(
        env,
        settings,
        total_steps=total_steps,
        preset=preset,
        backend=backend,
        hyperparameters=(
            *hyperparameter_names([*BUILTINS.values(), surrogate]),
            *HYPERPARAMETER_DEFAULTS,
        ),
    )
    hp, setting = resolve_hyperparameters(
        surrogate, run.task, epsilon=epsilon, alpha=alpha, k=k, delta=delta, **run.hyperparameters
    )
    seed = check_seed(seed)
    trainer, options = run.trainer, run.options
    record = {**setting, **run.record(seed=seed, **identities([surrogate]))}
    description = f"{surrogate.name} on {run.name}"
    header = run.header(description)
    keys, hps = jax.tree.map(lambda x: x[None], (jax.random.key(seed), hp))  # a batch of one
    plan = Plan("train", trainer, keys, hps, record, description, header)
    outcome = drive(plan, options)
    metrics, state = jax.tree.map(lambda x: x[0], (outcome.metrics, outcome.state))
    result = TrainResult(
        metrics=metrics,
        params=state.params,
        config=record,
        state=state,
        policy=make_policy(trainer, state),
        compile_seconds=outcome.compile_seconds,
        train_seconds=outcome.train_seconds,
        env=run.environment,
        resumed_from=outcome.resumed_from,
        stopped_at=outcome.stopped_at,
    )
    if options.log_dir is not None and is_main_process():
        result.write(options.log_dir)  # summary.txt, beside what the driver wrote
    return result
