"""``train(env, variant, alpha)``: one run, resolved and checked before compiling, then driven."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax

from fppo_jax.config import (
    HYPERPARAMETER_DEFAULTS,
    check_seed,
    environment_name,
    resolve_config,
    resolve_hyperparameters,
)
from fppo_jax.driver import Callback, Options, Plan, drive
from fppo_jax.envs import Environment, as_environment
from fppo_jax.objectives import EPSILON
from fppo_jax.policy import make_policy
from fppo_jax.progress import Progress
from fppo_jax.results import TrainResult
from fppo_jax.trainer import make_train


def train(
    env: str | Environment | Any = "cartpole",
    variant: str = "fppo-lp",
    alpha: float | None = None,
    *,
    k: float | None = None,
    delta: float | None = None,
    epsilon: float = EPSILON,
    seed: int = 0,
    total_steps: int | None = None,
    preset: str = "paper",
    progress: bool | Callable[[Progress], None] = False,
    checkpoint_dir: str | Path | None = None,
    resume: bool = False,
    checkpoint_every: int | None = None,
    keep: int = 3,
    log_dir: str | Path | None = None,
    devices: int | None = None,
    callback: Callback | None = None,
    eval_every: int | None = None,
    eval_episodes: int = 10,
    wandb_project: str | None = None,
    **overrides: Any,
) -> TrainResult:
    """Train one policy with `variant` on `env` and return its metrics, parameters and policy.

    `env` is a registered name (:data:`fppo_jax.envs.TASKS`), a gymnax environment or an
    :class:`~fppo_jax.envs.Environment`. For a registered task, FPPO-LP's α and FPPO-QP's k
    default to the paper's Table 2 and `total_steps` to the paper's budget. `preset` names the
    run's shape (:data:`fppo_jax.config.PRESETS`): ``"paper"`` (SPEC §2: 8 environments × 256
    steps) or ``"massive"`` (2048 environments × 16 steps, for a GPU). `overrides` are
    :class:`TrainConfig` fields (``num_envs``, ``num_steps``, ``num_minibatches``, …) and
    optimisation settings (``learning_rate``, ``gamma``, ``gae_lambda``, ``entropy_coef``,
    ``value_coef``, ``max_grad_norm``). Everything is checked before compiling.

    `progress`: ``True`` shows a progress bar on a terminal, or prints a line per chunk of
    updates on stderr otherwise; a callable receives a :class:`Progress`; ``False`` (with no
    checkpoints and no log) runs the whole training as one compiled call.

    `checkpoint_dir`: save the full training state there every `checkpoint_every` updates
    (default: a twentieth of the run), keeping the newest `keep` (see
    :mod:`fppo_jax.checkpoint`). With ``resume=True`` the run continues from the newest intact
    checkpoint there, if any, and ends exactly as if it had never stopped; a checkpoint of a
    differently configured run is refused with the differing fields named. Without `resume`,
    a directory that already holds checkpoints is refused, so that none is overwritten.
    `log_dir`: write ``config.json`` (every setting, the versions and devices) there at once,
    then ``metrics.csv`` and TensorBoard event files as training goes.

    `devices`: how many of the devices JAX sees (default: all) share the run; its environments
    are split across them and the parameters replicated (see :mod:`fppo_jax.distributed`). In a
    multi-process run only process 0 reports progress and writes the log.

    `callback(snapshot)` is called between compiled chunks with a
    :class:`~fppo_jax.driver.Snapshot` (the update, the metrics so far, the state and its
    policy); returning ``False`` stops training there (checkpointed, if checkpoints are on),
    and the result holds the updates done. `eval_every` updates (and at the end), the
    deterministic policy plays `eval_episodes` episodes and their mean return is recorded as
    the metric ``eval_return`` (NaN between evaluations). `wandb_project` logs to Weights &
    Biases too (``pip install 'fppo-jax[wandb]'``).

    A finished run with checkpoints goes on for more steps when resumed with a larger
    `total_steps`, unless its learning rate anneals over the run (refused, with the reason).

    Raises :class:`TrainingDiverged` if the loss or the parameters stop being finite (the last
    good checkpoint stays on disk).
    """
    options = Options(
        progress,
        checkpoint_dir,
        resume,
        checkpoint_every,
        keep,
        log_dir,
        devices,
        callback,
        eval_every,
        eval_episodes,
        wandb_project,
    )
    optimisation = {
        name: overrides.pop(name) for name in HYPERPARAMETER_DEFAULTS if name in overrides
    }
    config = resolve_config(
        env, total_steps, overrides, also_valid=tuple(HYPERPARAMETER_DEFAULTS), preset=preset
    )
    task = env if isinstance(env, str) else None
    hp, settings = resolve_hyperparameters(
        variant, task, epsilon=epsilon, alpha=alpha, k=k, delta=delta, **optimisation
    )
    seed = check_seed(seed)
    environment = as_environment(env)
    name = environment_name(env, environment)
    record = {**settings, "env": name, "seed": seed, "preset": preset}
    record.update(dataclasses.asdict(config))
    trainer = make_train(config, environment)
    plan = Plan("train", trainer, jax.random.key(seed), hp, record, f"{variant} on {name}")
    outcome = drive(plan, options)
    return TrainResult(
        metrics=outcome.metrics,
        params=outcome.state.params,
        config=record,
        state=outcome.state,
        policy=make_policy(trainer, outcome.state),
        compile_seconds=outcome.compile_seconds,
        train_seconds=outcome.train_seconds,
        env=environment,
        resumed_from=outcome.resumed_from,
        stopped_at=outcome.stopped_at,
    )
