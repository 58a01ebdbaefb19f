"""Environments: the interface the trainer steps, the gymnax adapter and the task registry.

An environment is a pair of pure functions on one (unbatched) environment; the trainer vmaps
them over its parallel environments and resets the environments whose episode ended (it draws
the reset states for a whole rollout in one vectorised batch, outside the sequential loop).
"""

from __future__ import annotations

import dataclasses
import sys
from collections.abc import Callable
from typing import Any, NamedTuple, Protocol, runtime_checkable

import jax
import jax.numpy as jnp


@dataclasses.dataclass(frozen=True)
class Discrete:
    """Actions 0 … n−1."""

    n: int


@dataclasses.dataclass(frozen=True)
class Box:
    """Real action vectors in [low, high] (element-wise)."""

    low: tuple[float, ...]
    high: tuple[float, ...]

    @property
    def size(self) -> int:
        return len(self.low)


class Step(NamedTuple):
    """The outcome of one step: `obs` is the observation it produced (before any reset)."""

    obs: jax.Array
    reward: jax.Array
    terminated: jax.Array
    truncated: jax.Array


@runtime_checkable
class Environment(Protocol):
    """What the trainer needs of an environment."""

    observation_size: int
    action_space: Discrete | Box

    def reset(self, key: jax.Array) -> tuple[Any, jax.Array]:
        """(state, first observation)."""
        ...

    def step(self, key: jax.Array, state: Any, action: jax.Array) -> tuple[Any, Step]:
        """(next state, the step's outcome); no reset: the trainer resets ended episodes."""
        ...


@dataclasses.dataclass(frozen=True)
class GymnaxEnvironment:
    """A gymnax (≥ 1.0) environment with fixed parameters (they set the episode limit)."""

    env: Any  # gymnax.environments.environment.Environment
    params: Any

    @property
    def observation_size(self) -> int:
        return int(self.env.observation_space(self.params).shape[0])

    @property
    def action_space(self) -> Discrete | Box:
        from gymnax.environments import spaces

        space = self.env.action_space(self.params)
        if isinstance(space, spaces.Discrete):
            return Discrete(int(space.n))
        low = jnp.broadcast_to(space.low, space.shape)
        high = jnp.broadcast_to(space.high, space.shape)
        return Box(tuple(map(float, low)), tuple(map(float, high)))

    def reset(self, key: jax.Array) -> tuple[Any, jax.Array]:
        obs, state = self.env.reset(key, self.params)
        return state, obs.astype(jnp.float32)

    def step(self, key: jax.Array, state: Any, action: jax.Array) -> tuple[Any, Step]:
        # gymnax's own `step` also computes a reset at every step; the trainer does that for
        # a whole rollout at once, so only the transition is taken here.
        obs, state, reward, terminated, _ = self.env.step_env(key, state, action, self.params)
        truncated = self.env.is_truncated(state, self.params)
        return state, Step(
            obs.astype(jnp.float32), reward.astype(jnp.float32), terminated, truncated
        )


def draw_resets(env: Environment, key: jax.Array, shape: tuple[int, ...]) -> tuple[Any, jax.Array]:
    """A fresh reset (state, obs) for every index of `shape`, drawn in one vectorised batch."""
    reset = env.reset
    for _ in shape:
        reset = jax.vmap(reset)
    return reset(jax.random.split(key, shape))


def where_done(done: jax.Array, reset: Any, stepped: Any) -> Any:
    """Per environment (the leading axis of every leaf): `reset` where done, else `stepped`."""

    def select(r: jax.Array, x: jax.Array) -> jax.Array:
        return jnp.where(done.reshape(done.shape + (1,) * (x.ndim - 1)), r, x)

    return jax.tree.map(select, reset, stepped)


def _mujoco(name: str, episode_length: int) -> Callable[[], Environment]:
    def make() -> Environment:
        from fppo_jax import mujoco_envs

        if name == "swimmer":
            return mujoco_envs.Swimmer(episode_length=episode_length)
        return mujoco_envs.brax_environment(name, episode_length)

    return make


def _gymnax(env_id: str, max_steps: int) -> Callable[[], GymnaxEnvironment]:
    def make() -> GymnaxEnvironment:
        import gymnax

        env, params = gymnax.make(env_id)
        return GymnaxEnvironment(env, params.replace(max_steps_in_episode=max_steps))

    return make


@dataclasses.dataclass(frozen=True)
class Task:
    """A named task and the paper's budget for it (SPEC §2)."""

    name: str
    make: Callable[[], Environment]
    total_steps: int
    description: str


TASKS: dict[str, Task] = {
    task.name: task
    for task in (
        Task(
            "cartpole",
            _gymnax("CartPole-v1", 200),
            100_000,
            "CartPole-v0: 200-step episodes, discrete",
        ),
        Task(
            "acrobot",
            _gymnax("Acrobot-v1", 500),
            100_000,
            "Acrobot-v1: 500-step episodes, discrete",
        ),
        Task(
            "mountaincar",
            _gymnax("MountainCar-v0", 200),
            100_000,
            "MountainCar-v0: 200-step episodes, sparse reward, discrete",
        ),
        *(
            Task(name, _mujoco(name, limit), 1_000_000, f"{title} on MJX: {text}")
            for name, title, limit, text in (
                ("hopper", "Hopper", 1000, "1000-step episodes, 3 actions"),
                ("walker2d", "Walker2d", 1000, "1000-step episodes, 6 actions"),
                ("halfcheetah", "HalfCheetah", 1000, "1000-step episodes, 6 actions"),
                ("ant", "Ant", 1000, "1000-step episodes, 8 actions"),
                ("reacher", "Reacher", 50, "50-step episodes, 2 actions"),
                ("swimmer", "Swimmer", 1000, "1000-step episodes, 2 actions"),
            )
        ),
    )
}

MUJOCO_TASKS: tuple[str, ...] = ("hopper", "walker2d", "halfcheetah", "ant", "reacher", "swimmer")


def make_env(name: str) -> Environment:
    """The registered task `name` (see :data:`TASKS`)."""
    if name not in TASKS:
        raise ValueError(f"unknown environment {name!r}; registered: {', '.join(TASKS)}")
    return TASKS[name].make()


def _is_gymnax_env(env: Any) -> bool:
    # gymnax is imported only when needed: importing it runs JAX computations, which would
    # start JAX's backends before a multi-process run can join (fppo_jax.distributed).
    if "gymnax" not in sys.modules:
        return False
    from gymnax.environments.environment import Environment as GymnaxEnv

    return isinstance(env, GymnaxEnv)


def as_environment(env: str | Environment | Any) -> Environment:
    """A registered name, a gymnax environment (default parameters), a Brax ``Env``
    (1000-step episodes) or an :class:`Environment`."""
    if isinstance(env, str):
        return make_env(env)
    if _is_gymnax_env(env):
        return GymnaxEnvironment(env, env.default_params)
    from fppo_jax import mujoco_envs

    if mujoco_envs.is_brax_env(env):
        return mujoco_envs.BraxEnvironment(env)
    if isinstance(env, Environment):
        return env
    raise TypeError(
        f"expected a registered environment name ({', '.join(TASKS)}), a gymnax or Brax "
        "environment, or an object with observation_size, action_space, reset and step; got "
        + type(env).__name__
    )
