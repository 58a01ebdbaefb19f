"""What a training run is made of: static shapes and structure, and traced hyperparameters.

:class:`TrainConfig` fixes array shapes and program structure; changing it recompiles.
:class:`Hyperparameters` is a pytree of arrays passed into the compiled program, so seeds and
hyperparameters (variants included) can be vmapped without recompiling.
Defaults follow the paper's protocol, OpenAI baselines' ppo2 (SPEC §2).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import jax
import jax.numpy as jnp

from fppo_jax.objectives import Objective, objective


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """Static settings. Samples per update = `num_envs` × `num_steps`."""

    total_steps: int = 100_000
    num_envs: int = 8
    num_steps: int = 256
    num_minibatches: int = 32
    num_epochs: int = 10
    hidden_sizes: tuple[int, ...] = (64, 64)
    normalize_observations: bool = True
    normalize_rewards: bool = True
    clip_value_loss: bool = True
    anneal_learning_rate: bool = False
    # Reset states drawn per environment per rollout. None: one per step, so every episode
    # starts from a fresh draw. A small pool (MuJoCo with thousands of environments, where a
    # reset costs a fifth of a step) is cycled by environments that end several episodes in
    # one rollout.
    resets_per_rollout: int | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "hidden_sizes", tuple(int(h) for h in self.hidden_sizes))
        for name in ("total_steps", "num_envs", "num_steps", "num_minibatches", "num_epochs"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be a positive integer, got {value!r}")
        pool = self.resets_per_rollout
        if pool is not None and (isinstance(pool, bool) or not isinstance(pool, int) or pool < 1):
            raise ValueError(f"resets_per_rollout must be a positive integer or None, got {pool!r}")
        if not self.hidden_sizes or min(self.hidden_sizes) < 1:
            raise ValueError(f"hidden_sizes must be positive layer widths, got {self.hidden_sizes}")
        if self.samples_per_update % self.num_minibatches:
            raise ValueError(
                f"num_minibatches ({self.num_minibatches}) must divide the samples per update "
                f"(num_envs × num_steps = {self.samples_per_update})"
            )
        if self.total_steps < self.samples_per_update:
            raise ValueError(
                f"total_steps ({self.total_steps}) is less than one update's samples "
                f"(num_envs × num_steps = {self.samples_per_update})"
            )

    @property
    def samples_per_update(self) -> int:
        return self.num_envs * self.num_steps

    @property
    def minibatch_size(self) -> int:
        return self.samples_per_update // self.num_minibatches

    @property
    def num_updates(self) -> int:
        """Whole updates that fit in `total_steps` (the budget is never exceeded)."""
        return self.total_steps // self.samples_per_update


PRESETS: dict[str, dict[str, Any]] = {
    # SPEC §2, baselines' ppo2: 2048 samples per update from 8 environments × 256 steps.
    "paper": {"num_envs": 8, "num_steps": 256, "num_minibatches": 32, "num_epochs": 10},
    # Thousands of environments in lockstep with short unrolls and large minibatches (as Brax
    # and MuJoCo Playground train), for throughput on a GPU: 32,768 samples per update, one
    # gradient step per 512 of them. Meant for budgets of several million steps.
    "massive": {
        "num_envs": 2048,
        "num_steps": 16,
        "num_minibatches": 16,
        "num_epochs": 4,
        "resets_per_rollout": 1,
    },
}


def preset_config(preset: str, **overrides: Any) -> TrainConfig:
    """The :class:`TrainConfig` of preset `preset` ("paper" or "massive"), with `overrides`."""
    if preset not in PRESETS:
        raise ValueError(f"unknown preset {preset!r}; valid presets: {', '.join(PRESETS)}")
    return TrainConfig(**{**PRESETS[preset], **overrides})


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Hyperparameters:
    """Traced settings. The surrogate's own (variant, ε, α, k, δ) live in `objective`."""

    objective: Objective
    learning_rate: jax.Array
    gamma: jax.Array
    gae_lambda: jax.Array
    entropy_coef: jax.Array
    value_coef: jax.Array
    max_grad_norm: jax.Array


HYPERPARAMETER_DEFAULTS: dict[str, float] = {
    "learning_rate": 3e-4,
    "gamma": 0.99,
    "gae_lambda": 0.95,
    "entropy_coef": 0.0,
    "value_coef": 0.5,
    "max_grad_norm": 0.5,
}

_RANGES: dict[str, tuple[str, object]] = {
    "learning_rate": ("> 0", lambda x: x > 0),
    "gamma": ("in (0, 1]", lambda x: 0 < x <= 1),
    "gae_lambda": ("in [0, 1]", lambda x: 0 <= x <= 1),
    "entropy_coef": (">= 0", lambda x: x >= 0),
    "value_coef": (">= 0", lambda x: x >= 0),
    "max_grad_norm": ("> 0", lambda x: x > 0),
}


def hyperparameters(
    variant: str = "ppo",
    *,
    epsilon: float = 0.2,
    alpha: float | None = None,
    k: float | None = None,
    delta: float | None = None,
    **values: float,
) -> Hyperparameters:
    """Checked hyperparameters: the objective of `variant` and the optimisation settings.

    Unset settings take :data:`HYPERPARAMETER_DEFAULTS`; unknown names and out-of-range values
    raise ``ValueError`` naming the parameter.
    """
    unknown = sorted(set(values) - set(HYPERPARAMETER_DEFAULTS))
    if unknown:
        raise ValueError(
            f"unknown hyperparameter {', '.join(unknown)}; valid: epsilon, alpha, k, delta, "
            + ", ".join(HYPERPARAMETER_DEFAULTS)
        )
    settings = {**HYPERPARAMETER_DEFAULTS, **{k_: v for k_, v in values.items() if v is not None}}
    for name, value in settings.items():
        bound, ok = _RANGES[name]
        if not (math.isfinite(float(value)) and ok(float(value))):
            raise ValueError(f"{name} must be {bound}, got {value}")
    return Hyperparameters(
        objective=objective(variant, epsilon=epsilon, alpha=alpha, k=k, delta=delta),
        **{name: jnp.asarray(value, jnp.float32) for name, value in settings.items()},
    )
