"""The interface the trainer steps, and the helpers it resets environments with.

An environment is a pair of pure functions on one (unbatched) environment; the trainer vmaps
them over its parallel environments and resets the environments whose episode ended (it draws
the reset states for a whole rollout in one vectorised batch, outside the sequential loop).
An environment whose state lives outside JAX resets itself instead (:func:`resets_itself`).
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any, NamedTuple, Protocol, cast, runtime_checkable

import jax
import jax.numpy as jnp
import numpy as np


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
    """The outcome of one step: `obs` is the observation it produced (before any reset).

    `next_obs` is given by an environment that resets itself, and only by one: the observation
    to act on next, the new episode's first where this step ended one and `obs` elsewhere.
    """

    obs: jax.Array
    reward: jax.Array
    terminated: jax.Array
    truncated: jax.Array
    next_obs: jax.Array | None = None


@runtime_checkable
class Environment(Protocol):
    """What the trainer needs of an environment."""

    # Read-only (properties, to a type checker): adapters compute them.
    @property
    def observation_size(self) -> int: ...

    @property
    def action_space(self) -> Discrete | Box: ...

    def reset(self, key: jax.Array) -> tuple[Any, jax.Array]:
        """(state, first observation)."""
        ...

    def step(self, key: jax.Array, state: Any, action: jax.Array) -> tuple[Any, Step]:
        """(next state, the step's outcome); no reset: the trainer resets ended episodes."""
        ...


def resets_itself(env: Environment) -> bool:
    """Whether `env` starts a new episode within the `step` that ends one (its next state is
    already the new episode's, and its step gives `next_obs`), as an environment must whose
    state lives outside JAX: then the trainer draws no reset states for it."""
    return bool(getattr(env, "resets_itself", False))


class HostState(NamedTuple):
    """The JAX side of an environment that lives on the host (native MuJoCo, Gymnasium):
    which host-side pool and which of its slots it is, and the steps it has taken:
    a pure callback given the same arguments twice may be run once, so every step's must
    differ."""

    pool: jax.Array
    slot: jax.Array
    steps: jax.Array


def seeds_of(key_data: np.ndarray) -> list[int]:
    """One seed (a 31-bit C int, as envpool takes) per key of `key_data` [..., words], from its
    words: how a host-side environment is seeded from its own key."""
    words = np.asarray(key_data).reshape(-1, key_data.shape[-1]).astype(np.uint64)
    return [int(s) for s in (words[:, 0] * np.uint64(0x9E3779B1) ^ words[:, -1]) % 2**31]


class OnHost:
    """``reset`` and ``step`` of an environment that lives on the host (its class gives
    `observation_size`, ``_host_reset(key_data)`` and ``_host_step(pool, slot, steps,
    action)``): each a ``jax.pure_callback`` that vmaps as one host call over every environment
    of every run (``vmap_method="broadcast_all"``). Such an environment resets itself."""

    resets_itself = True
    observation_size: int
    action_space: Discrete | Box

    if TYPE_CHECKING:

        def _host_reset(self, key_data: np.ndarray) -> tuple[HostState, np.ndarray]: ...

        def _host_step(
            self, pool: np.ndarray, slot: np.ndarray, steps: np.ndarray, action: np.ndarray
        ) -> Step: ...

    # The result shapes below stand in for the arrays of a HostState and a Step, which are
    # typed as the jax.Arrays they become: hence the casts.
    def reset(self, key: jax.Array) -> tuple[HostState, jax.Array]:
        scalar = cast(jax.Array, jax.ShapeDtypeStruct((), jnp.int32))
        shapes = (
            HostState(scalar, scalar, scalar),
            jax.ShapeDtypeStruct((self.observation_size,), jnp.float32),
        )
        return cast(
            tuple[HostState, jax.Array],
            jax.pure_callback(
                self._host_reset, shapes, jax.random.key_data(key), vmap_method="broadcast_all"
            ),
        )

    def step(self, key: jax.Array, state: HostState, action: jax.Array) -> tuple[HostState, Step]:
        obs = cast(jax.Array, jax.ShapeDtypeStruct((self.observation_size,), jnp.float32))
        flag = cast(jax.Array, jax.ShapeDtypeStruct((), jnp.bool_))
        shapes = Step(
            obs,
            cast(jax.Array, jax.ShapeDtypeStruct((), jnp.float32)),
            flag,
            flag,
            obs,
        )
        out = jax.pure_callback(
            self._host_step,
            shapes,
            state.pool,
            state.slot,
            state.steps,
            action,
            vmap_method="broadcast_all",
        )
        return state._replace(steps=state.steps + 1), out


class Timed(NamedTuple):
    """An environment's own state and the steps taken in its episode, for adapters that keep
    the episode limit themselves."""

    inner: Any
    steps: jax.Array


def limited_step(
    state: Timed, inner: Any, obs: jax.Array, reward: jax.Array, done: jax.Array, limit: int
) -> tuple[Timed, Step]:
    """The step of an adapter that keeps the episode limit itself: the inner environment's
    `done` is termination, and reaching `limit` steps without it is truncation."""
    steps = state.steps + 1
    terminated = done > 0
    return Timed(inner, steps), Step(
        obs=obs.astype(jnp.float32),
        reward=reward.astype(jnp.float32),
        terminated=terminated,
        truncated=(steps >= limit) & ~terminated,
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


def key_shape() -> jax.ShapeDtypeStruct:
    """A PRNG key's shape and dtype, for ``jax.eval_shape``: outside a trace a key of its own
    would be a small compiled program."""
    return cast(jax.ShapeDtypeStruct, jax.eval_shape(jax.random.key, 0))


def check_environment(env: Environment) -> None:
    """Raise ``TypeError`` unless `env` keeps the contract the trainer relies on, checked on
    shapes alone (``jax.eval_shape``: nothing runs): `reset` gives a ``(observation_size,)``
    float observation, and `step` a state of the same structure and a :class:`Step` whose
    observation has that shape too, with a scalar reward, boolean scalars `terminated` and
    `truncated`, and `next_obs` of that shape if and only if the environment resets itself
    (:func:`resets_itself`). The error names the field, what was expected and what was found."""
    size = env.observation_size
    if isinstance(size, bool) or not isinstance(size, int) or size < 1:
        raise TypeError(f"observation_size must be a positive integer, got {size!r}")
    space = env.action_space
    if not isinstance(space, Discrete | Box):
        raise TypeError(f"action_space must be a Discrete or a Box, got {space!r}")
    key = key_shape()
    state, obs = jax.eval_shape(env.reset, key)
    _expect("reset's observation", obs, (size,), jnp.floating, OBSERVATION_SIZE)
    action = (
        jax.ShapeDtypeStruct((), jnp.int32)
        if isinstance(space, Discrete)
        else jax.ShapeDtypeStruct((space.size,), jnp.float32)
    )
    out = jax.eval_shape(env.step, key, state, action)
    if not (isinstance(out, tuple) and len(out) == 2 and isinstance(out[1], Step)):
        raise TypeError(
            "step must return (next state, Step(obs, reward, terminated, truncated)), got "
            f"{type(out).__name__}"
            + (f" of {', '.join(type(x).__name__ for x in out)}" if isinstance(out, tuple) else "")
        )
    next_state, step = out
    # cast: jaxlib has no stub for PyTreeDef, which only compares.
    if cast(object, jax.tree.structure(next_state)) != jax.tree.structure(state):
        raise TypeError("step's next state must have the structure of reset's state")
    _expect("step's obs", step.obs, (size,), jnp.floating, OBSERVATION_SIZE)
    _expect("step's reward", step.reward, (), jnp.number)
    _expect("step's terminated", step.terminated, (), jnp.bool_)
    _expect("step's truncated", step.truncated, (), jnp.bool_)
    if resets_itself(env):
        _expect("step's next_obs", step.next_obs, (size,), jnp.floating, OBSERVATION_SIZE)
    elif step.next_obs is not None:
        raise TypeError("step's next_obs is for environments that reset themselves only")


OBSERVATION_SIZE = " (the environment's observation_size)"


def _expect(name: str, value: Any, shape: tuple[int, ...], kind: Any, why: str = "") -> None:
    found_shape = getattr(value, "shape", None)
    dtype = getattr(value, "dtype", None)
    if found_shape != shape or dtype is None or not jnp.issubdtype(dtype, kind):
        expected = {jnp.floating: "float", jnp.number: "numeric", jnp.bool_: "bool"}[kind]
        found = f"shape {found_shape}, dtype {dtype}" if dtype is not None else type(value).__name__
        raise TypeError(
            f"{name}: expected shape {shape}{why} and a {expected} dtype; found {found}"
        )
