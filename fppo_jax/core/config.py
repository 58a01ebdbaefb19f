"""What a training run is made of: static shapes and structure, and traced hyperparameters.

:class:`TrainConfig` fixes array shapes and program structure; changing it recompiles.
:class:`Hyperparameters` is a pytree of arrays passed into the compiled program, so seeds and
hyperparameters (variants included) can be vmapped without recompiling.
The run's shape has its defaults (the paper's protocol, OpenAI baselines' ppo2 settings) and
checks here, in :class:`TrainConfig` and its presets; the hyperparameters have theirs in
:mod:`fppo_jax.core.resolution`, where a variant's name is resolved; how a run is driven has its
defaults and checks in :mod:`fppo_jax.run.options`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any, cast

import jax
import jax.numpy as jnp
import numpy as np

from fppo_jax.core.checks import positive_int
from fppo_jax.core.objectives import Objective, union
from fppo_jax.envs import MUJOCO_TASKS, lookup
from fppo_jax.errors import InvalidInput

# The most env steps a run may take: the compiled program counts them in int32.
MAX_STEPS = 2**31 - 1

# A hyperparameter's value as records and tables hold it: the variant's name, or a number.
Value = str | float | int
# One run's setting: its variant and each hyperparameter's value, by name.
Setting = dict[str, Value]


def _field(default: Any, help: str) -> Any:
    """A :class:`TrainConfig` field and its help text (which the command line shows)."""
    return dataclasses.field(default=default, metadata={"help": help})


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """Static settings. Samples per update = `num_envs` × `num_steps`."""

    total_steps: int = _field(100_000, "env steps per run (default: the task's budget)")
    num_envs: int = _field(8, "parallel environments")
    num_steps: int = _field(256, "steps per environment per update")
    num_minibatches: int = _field(32, "minibatches per epoch")
    num_epochs: int = _field(10, "epochs per update")
    hidden_sizes: tuple[int, ...] = _field((64, 64), "hidden layer widths of both MLPs")
    normalize_observations: bool = _field(True, "normalise observations (running statistics)")
    normalize_rewards: bool = _field(True, "scale rewards by the std of discounted returns")
    clip_value_loss: bool = _field(True, "clip the value loss with range epsilon")
    anneal_learning_rate: bool = _field(False, "decay the learning rate linearly to 0")
    # A small pool (MuJoCo with thousands of environments, where a reset costs a fifth of a
    # step) is cycled by environments that end several episodes in one rollout.
    resets_per_rollout: int | None = _field(
        None,
        "reset states drawn per environment per rollout (default: one per step, so every "
        "episode starts fresh)",
    )
    initial_log_std: float = _field(
        0.0, "the Gaussian policy's log-std at initialisation (continuous actions only)"
    )

    def __post_init__(self) -> None:
        for name in ("total_steps", "num_envs", "num_steps", "num_minibatches", "num_epochs"):
            object.__setattr__(self, name, positive_int(name, getattr(self, name)))
        if self.resets_per_rollout is not None:
            pool = positive_int("resets_per_rollout", self.resets_per_rollout)
            object.__setattr__(self, "resets_per_rollout", pool)
        if self.total_steps > MAX_STEPS:
            raise InvalidInput(
                f"total_steps must be at most {MAX_STEPS:,} (the compiled program counts env "
                f"steps in 32-bit integers), got {self.total_steps:,}"
            )
        sizes = self.hidden_sizes
        if isinstance(sizes, str) or not isinstance(sizes, tuple | list) or not sizes:
            raise InvalidInput(
                f"hidden_sizes must be a sequence of positive layer widths such as (64, 64), "
                f"got {sizes!r}"
            )
        widths = tuple(positive_int("each of hidden_sizes", h) for h in sizes)
        object.__setattr__(self, "hidden_sizes", widths)
        for name in (
            "normalize_observations",
            "normalize_rewards",
            "clip_value_loss",
            "anneal_learning_rate",
        ):
            if not isinstance(getattr(self, name), bool | np.bool_):
                raise InvalidInput(f"{name} must be True or False, got {getattr(self, name)!r}")
        if (
            isinstance(self.initial_log_std, bool)
            or not isinstance(self.initial_log_std, int | float)
            or not np.isfinite(self.initial_log_std)
        ):
            raise InvalidInput(
                f"initial_log_std must be a finite number, got {self.initial_log_std!r}"
            )
        object.__setattr__(self, "initial_log_std", float(self.initial_log_std))
        if self.samples_per_update % self.num_minibatches:
            raise InvalidInput(
                f"num_minibatches ({self.num_minibatches}) must divide the samples per update "
                f"(num_envs × num_steps = {self.samples_per_update})"
            )
        if self.total_steps < self.samples_per_update:
            raise InvalidInput(
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


PRESETS: dict[str, dict[str, int]] = {
    # baselines' ppo2 batch: 2048 samples per update, 32 minibatches, 10 epochs. Its MuJoCo runs
    # collect them from 1 environment × 2048 steps; here 8 × 256, the same batch in shorter unrolls.
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


# baselines' ppo2, whose PPO the paper compares against, anneals the learning rate
# linearly to 0 with its MuJoCo defaults (`lr=lambda f: 3e-4 * f`) and keeps it constant
# elsewhere (it has no defaults of its own for classic control). The paper does not say it
# departed from them, so its preset does the same, task by task.
ANNEALED_IN_PAPER: tuple[str, ...] = MUJOCO_TASKS


def task_preset(preset: str, task: str | None) -> dict[str, bool]:
    """What `preset` sets for `task` beyond its shape: the paper's learning-rate schedule."""
    return {"anneal_learning_rate": True} if preset == "paper" and task in ANNEALED_IN_PAPER else {}


def preset_config(preset: str, **overrides: Any) -> TrainConfig:
    """The :class:`TrainConfig` of preset `preset` ("paper" or "massive"), with `overrides`."""
    if preset not in PRESETS:
        raise InvalidInput(f"unknown preset {preset!r}; valid presets: {', '.join(PRESETS)}")
    return TrainConfig(**{**PRESETS[preset], **overrides})


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Hyperparameters:
    """Traced settings. The surrogate's own (variant, ε, α, k, δ) live in `objective`.

    `num_updates`, the run's length in updates (the learning-rate schedule's horizon and the
    run's end), is the configuration's unless set. A compiled program's runs carry it
    (:func:`with_budget`, once per run, in :func:`~fppo_jax.run.execution.run_chunks`), so that
    one program serves every step budget."""

    objective: Objective
    learning_rate: jax.Array
    gamma: jax.Array
    gae_lambda: jax.Array
    entropy_coef: jax.Array
    value_coef: jax.Array
    max_grad_norm: jax.Array
    num_updates: jax.Array | None = None


def run_length(hp: Hyperparameters, config: TrainConfig) -> jax.Array | int:
    """Updates in the run: `hp`'s, traced, if it carries them; else `config`'s, a constant."""
    return config.num_updates if hp.num_updates is None else hp.num_updates


def with_budget(hps: Hyperparameters, num_updates: int) -> Hyperparameters:
    """`hps` (along a leading run axis) carrying `num_updates` as every run's length."""
    runs = hps.learning_rate.shape[0]
    return dataclasses.replace(
        hps, num_updates=jax.device_put(np.full(runs, num_updates, np.int32))
    )


CONFIG_FIELDS: tuple[str, ...] = tuple(field.name for field in dataclasses.fields(TrainConfig))


def stack_hyperparameters(hps: Sequence[Hyperparameters]) -> Hyperparameters:
    """`hps` as one batch (a leading run axis) over all of their surrogates, for ``vmap``."""
    menu = union([s for hp in hps for s in hp.objective.surrogates])
    among = [dataclasses.replace(hp, objective=hp.objective.among(menu)) for hp in hps]
    return cast(Hyperparameters, jax.tree.map(lambda *xs: jnp.stack(xs), *among))


def resolve_config(
    env: Any,
    total_steps: int | None,
    overrides: Mapping[str, object],
    also_valid: tuple[str, ...] = (),
    preset: str = "paper",
) -> TrainConfig:
    """The checked TrainConfig of `preset` and `overrides` (values given for its fields, as
    yet unchecked), with the task's step budget and the preset's learning-rate schedule for it
    (:func:`task_preset`) by default."""
    task = lookup(env) if isinstance(env, str) else None  # an unknown name is refused here
    unknown = sorted(set(overrides) - set(CONFIG_FIELDS))
    if unknown:
        raise InvalidInput(
            f"unknown setting {', '.join(unknown)}; valid: "
            + ", ".join([*CONFIG_FIELDS, *also_valid])
        )
    values = {**task_preset(preset, task.name if task else None), **overrides}
    if total_steps is not None:
        values["total_steps"] = total_steps
    elif "total_steps" not in values:
        values["total_steps"] = task.total_steps if task else TrainConfig.total_steps
    return preset_config(preset, **values)


def environment_name(env: Any, environment: Any) -> str:
    """The name a run records for its environment: the task's, the environment's own name (a
    Gymnasium environment's), or the adapter's class."""
    if isinstance(env, str):
        return env
    named = getattr(environment, "name", None)
    return (
        named if isinstance(named, str) else type(getattr(environment, "env", environment)).__name__
    )


def describe(config: TrainConfig, preset: str | None = None) -> str:
    """One run's length and shape, in words."""
    prefix = "" if preset is None else f"preset {preset}, "
    schedule = ", learning rate annealed linearly to 0" if config.anneal_learning_rate else ""
    trained = config.num_updates * config.samples_per_update
    budget = (
        ""
        if trained == config.total_steps
        else f" = {trained:,} env steps (whole updates of the {config.total_steps:,} asked)"
    )
    return f"{prefix}{config.num_updates} updates × {describe_update(config)}{budget}{schedule}"


def describe_update(config: TrainConfig) -> str:
    """One update's shape, in words."""
    return (
        f"{config.samples_per_update:,} samples ({config.num_envs} envs × {config.num_steps} "
        f"steps), {config.num_minibatches} minibatches × {config.num_epochs} epochs"
    )
