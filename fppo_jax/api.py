"""``train(env, variant, alpha)``: one run, checked before compiling, with progress and results."""

from __future__ import annotations

import dataclasses
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from fppo_jax.config import (
    HYPERPARAMETER_DEFAULTS,
    Hyperparameters,
    TrainConfig,
    hyperparameters,
    preset_config,
)
from fppo_jax.envs import TASKS, Box, Environment, as_environment
from fppo_jax.execution import PROGRESS_LINES, Progress, compile_program, execute, print_progress
from fppo_jax.objectives import DEFAULTS as VARIANT_DEFAULTS
from fppo_jax.objectives import VARIANTS
from fppo_jax.trainer import Trainer, TrainState, make_train

CONFIG_FIELDS = tuple(field.name for field in dataclasses.fields(TrainConfig))


class TrainingDiverged(FloatingPointError):
    """The loss or the parameters became NaN or infinite."""

    def __init__(self, update: int, env_steps: int):
        """`update` counts from 1, as the progress lines do."""
        self.update, self.env_steps = update, env_steps
        super().__init__(
            f"training diverged at update {update} (after {env_steps:,} env steps): the loss or "
            "the parameters became NaN or infinite. The state before that update was kept. "
            "Lower the learning rate, or check the environment's observations and rewards."
        )


@dataclasses.dataclass
class TrainResult:
    """The outcome of :func:`train`.

    `metrics` maps each name of :data:`fppo_jax.trainer.METRICS` to one value per update.
    `policy(obs, key=None)` acts on raw observations (one or a batch): the most likely action
    without a key, a sample with one.
    """

    metrics: dict[str, np.ndarray]
    params: dict
    config: dict[str, Any]
    state: TrainState
    policy: Callable[..., jax.Array]
    compile_seconds: float
    train_seconds: float
    env: Environment

    def render(self, path: str | Path, *, seed: int = 0, max_steps: int = 1000) -> Path:
        """Save one episode of the trained policy (the most likely actions) on a MuJoCo task
        as a ``.png`` image strip or a ``.gif``; see :mod:`fppo_jax.render`."""
        from fppo_jax.render import render_policy

        return render_policy(self.env, self.policy, path, seed=seed, max_steps=max_steps)

    def summary(self) -> str:
        """A few lines: the run, its speed, its returns and its escape-speed diagnostic."""
        m, c = self.metrics, self.config
        steps = int(m["env_steps"][-1])
        returns = m["average_return"]
        settings = ", ".join(f"{k} = {c[k]:g}" for k in ("alpha", "k", "delta") if k in c)
        settings = ", ".join(filter(None, [settings, f"epsilon = {c['epsilon']:g}"]))
        samples = c["num_envs"] * c["num_steps"]
        speed = steps / max(self.train_seconds, 1e-9)
        lines = [
            f"{c['variant']} on {c['env']} ({settings}), seed {c['seed']}",
            f"  updates   {len(returns)} × {samples:,} samples = {steps:,} env steps "
            f"(preset {c.get('preset', 'paper')})",
            f"  time      compile {self.compile_seconds:.1f} s, train {self.train_seconds:.1f} s "
            f"({speed:,.0f} env steps/s)",
        ]
        if np.isfinite(returns).any():
            best = int(np.nanargmax(returns))
            lines.append(
                f"  return    final {returns[-1]:.1f}, max {returns[best]:.1f} at "
                f"{int(m['env_steps'][best]):,} steps (mean of the last 100 episodes)"
            )
        else:
            lines.append("  return    no episode finished")
        lines += [
            f"  escape    in R+ ∪ R- after the update: {np.mean(m['negative_fraction_after']):.2%}"
            f" of samples (first epoch: {np.mean(m['negative_fraction_before']):.2%}), mean "
            f"distance past the bound {np.mean(m['negative_distance_after']):.3f}",
            f"  last      policy loss {m['policy_loss'][-1]:.4f}, value loss "
            f"{m['value_loss'][-1]:.4f}, entropy {m['entropy'][-1]:.3f}, approx KL "
            f"{m['approx_kl'][-1]:.4f}, clip fraction {m['clip_fraction'][-1]:.3f}",
        ]
        return "\n".join(lines)


def train(
    env: str | Environment | Any = "cartpole",
    variant: str = "fppo-lp",
    alpha: float | None = None,
    *,
    k: float | None = None,
    delta: float | None = None,
    epsilon: float = 0.2,
    seed: int = 0,
    total_steps: int | None = None,
    preset: str = "paper",
    progress: bool | Callable[[Progress], None] = False,
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

    `progress`: ``True`` prints a line per chunk of updates on stderr; a callable receives a
    :class:`Progress`; ``False`` runs the whole training as one compiled call.
    Raises :class:`TrainingDiverged` if the loss or the parameters stop being finite.
    """
    config, hp, settings = _resolve(
        env, variant, alpha, k, delta, epsilon, total_steps, preset, overrides
    )
    environment = as_environment(env)
    trainer = make_train(config, environment)
    report = print_progress if progress is True else (progress or None)
    if progress is True:
        print(
            f"{variant} on {env_name(env, environment)}: {describe(config, preset)}; compiling…",
            file=sys.stderr,
            flush=True,
        )
    key = jax.random.key(seed)
    program = compile_program(trainer, key, hp, chunks=PROGRESS_LINES if report else 1)

    def check(state: TrainState) -> None:
        index = int(state.nonfinite_update)
        if index >= 0:
            raise TrainingDiverged(index + 1, (index + 1) * config.samples_per_update)

    state, metrics, train_seconds = execute(program, key, hp, report, check)
    return TrainResult(
        metrics=metrics,
        params=state.params,
        config={
            **settings,
            "env": env_name(env, environment),
            "seed": seed,
            "preset": preset,
            **dataclasses.asdict(config),
        },
        state=state,
        policy=make_policy(trainer, state),
        compile_seconds=program.compile_seconds,
        train_seconds=train_seconds,
        env=environment,
    )


def _resolve(
    env: Any,
    variant: str,
    alpha: float | None,
    k: float | None,
    delta: float | None,
    epsilon: float,
    total_steps: int | None,
    preset: str,
    overrides: dict[str, Any],
) -> tuple[TrainConfig, Hyperparameters, dict[str, Any]]:
    """Defaults from the task table, then every check, before anything is compiled."""
    if variant not in VARIANTS:
        raise ValueError(f"unknown variant {variant!r}; valid variants: {', '.join(VARIANTS)}")
    optimisation = {
        name: overrides.pop(name) for name in HYPERPARAMETER_DEFAULTS if name in overrides
    }
    config = resolve_config(
        env, total_steps, overrides, also_valid=tuple(HYPERPARAMETER_DEFAULTS), preset=preset
    )
    task = TASKS.get(env) if isinstance(env, str) else None
    if task and variant == "fppo-lp" and alpha is None:
        alpha = task.fppo_lp_alpha
    if task and variant == "fppo-qp" and k is None:
        k = task.fppo_qp_k
    hp = hyperparameters(variant, epsilon=epsilon, alpha=alpha, k=k, delta=delta, **optimisation)
    o = hp.objective
    settings: dict[str, Any] = {"variant": variant, "epsilon": _as_float(o.epsilon)}
    settings.update({name: _as_float(getattr(o, name)) for name in VARIANT_DEFAULTS[variant]})
    settings.update({name: _as_float(getattr(hp, name)) for name in HYPERPARAMETER_DEFAULTS})
    return config, hp, settings


def resolve_config(
    env: Any,
    total_steps: int | None,
    overrides: dict[str, Any],
    also_valid: tuple[str, ...] = (),
    preset: str = "paper",
) -> TrainConfig:
    """The checked TrainConfig of `preset` and `overrides`, with the task's step budget by
    default."""
    if isinstance(env, str) and env not in TASKS:
        raise ValueError(f"unknown environment {env!r}; registered: {', '.join(TASKS)}")
    unknown = sorted(set(overrides) - set(CONFIG_FIELDS))
    if unknown:
        raise ValueError(
            f"unknown setting {', '.join(unknown)}; valid: "
            + ", ".join([*CONFIG_FIELDS, *also_valid])
        )
    values = dict(overrides)
    if total_steps is not None:
        values["total_steps"] = total_steps
    elif "total_steps" not in values:
        task = TASKS.get(env) if isinstance(env, str) else None
        values["total_steps"] = task.total_steps if task else TrainConfig.total_steps
    return preset_config(preset, **values)


def _as_float(x: jax.Array) -> float:
    # The shortest decimal that round-trips the float32, so that 1.3 is reported as 1.3.
    return float(str(np.asarray(x)[()]))


def describe(config: TrainConfig, preset: str | None = None) -> str:
    """One run's length and shape, in words."""
    prefix = "" if preset is None else f"preset {preset}, "
    return f"{prefix}{config.num_updates} updates × {describe_update(config)}"


def describe_update(config: TrainConfig) -> str:
    """One update's shape, in words."""
    return (
        f"{config.samples_per_update:,} samples ({config.num_envs} envs × {config.num_steps} "
        f"steps), {config.num_minibatches} minibatches × {config.num_epochs} epochs"
    )


def env_name(env: Any, environment: Environment) -> str:
    return env if isinstance(env, str) else type(getattr(environment, "env", environment)).__name__


def make_policy(trainer: Trainer, state: TrainState) -> Callable[..., jax.Array]:
    """An action function of raw observations: the mode without a key, a sample with one;
    continuous actions are clipped to the action bounds, as in training."""
    space = trainer.env.action_space

    def act(obs: jax.Array, key: jax.Array | None) -> jax.Array:
        obs = trainer.network_input(state.obs_stats, jnp.asarray(obs, jnp.float32))
        dist = trainer.networks.distribution(state.params, obs)
        action = dist.mode() if key is None else dist.sample(key)
        if isinstance(space, Box):
            action = jnp.clip(action, jnp.asarray(space.low), jnp.asarray(space.high))
        return action

    mode = jax.jit(lambda obs: act(obs, None))
    sample = jax.jit(act)

    def policy(obs: jax.Array, key: jax.Array | None = None) -> jax.Array:
        return mode(obs) if key is None else sample(obs, key)

    return policy
