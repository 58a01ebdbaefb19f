"""The interface the trainer steps, and the helpers it resets environments with.

An environment is a pair of pure functions on one (unbatched) environment; the trainer vmaps
them over its parallel environments and resets the environments whose episode ended (it draws
the reset states for a whole rollout in one vectorised batch, outside the sequential loop).
"""

from __future__ import annotations

import dataclasses
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


class Timed(NamedTuple):
    """An environment's own state and the steps taken in its episode, for adapters that keep
    the episode limit themselves."""

    inner: Any
    steps: jax.Array


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
