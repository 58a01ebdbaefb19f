"""MuJoCo Playground environments (``mujoco_playground``) on MJX.

Playground's environments are Brax-like: ``reset(rng)`` and ``step(state, action)`` on a state
whose ``done`` is the environment's termination. Their time limit (``episode_length`` in an
environment's config) is left to a training wrapper, so the adapter keeps it in its state and
reports it as truncation. Playground is imported on first use.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Mapping
from types import ModuleType
from typing import Any, cast

import jax
import jax.numpy as jnp

from fppo_jax.envs.core import Box, Step, Timed, key_shape, limited_step
from fppo_jax.errors import InvalidInput, MissingPackage, install_hint


def _registry() -> ModuleType:
    try:
        from mujoco_playground import registry
    except ImportError as error:
        raise MissingPackage(
            f"MuJoCo Playground is not installed: {install_hint('playground')}, or pip "
            "install playground"
        ) from error
    return cast(ModuleType, registry)


@dataclasses.dataclass(frozen=True, eq=False)
class PlaygroundEnvironment:
    """A Playground ``MjxEnv`` with an episode limit; its actions are in [-1, 1].

    Where the environment observes a dict of arrays, the policy sees the one at `obs_key`.
    """

    env: Any  # mujoco_playground.MjxEnv
    episode_length: int = 1000
    obs_key: str = "state"
    backend = "mjx"

    @functools.cached_property
    def observation_size(self) -> int:
        _, obs = jax.eval_shape(self.reset, key_shape())
        return int(obs.shape[-1])

    @property
    def action_space(self) -> Box:
        size = int(self.env.action_size)
        return Box((-1.0,) * size, (1.0,) * size)

    @property
    def mj_model(self) -> Any:
        return self.env.mj_model

    @property
    def dt(self) -> float:
        return float(self.env.dt)

    def qpos(self, state: Timed) -> jax.Array:
        """Generalised positions, for rendering."""
        return cast(jax.Array, state.inner.data.qpos)

    def reset(self, key: jax.Array) -> tuple[Timed, jax.Array]:
        state = self.env.reset(key)
        return Timed(state, jnp.zeros((), jnp.int32)), self._observation(state.obs)

    def step(self, key: jax.Array, state: Timed, action: jax.Array) -> tuple[Timed, Step]:
        inner = self.env.step(state.inner, action)
        obs = self._observation(inner.obs)
        return limited_step(state, inner, obs, inner.reward, inner.done, self.episode_length)

    def _observation(self, obs: jax.Array | Mapping[str, jax.Array]) -> jax.Array:
        if isinstance(obs, Mapping):
            if self.obs_key not in obs:
                raise InvalidInput(
                    f"the observation has no {self.obs_key!r}; choose obs_key from: "
                    + ", ".join(obs)
                )
            obs = obs[self.obs_key]
        return obs.astype(jnp.float32)


def playground_environment(
    name: str, episode_length: int | None = None, obs_key: str = "state", impl: str = "jax"
) -> PlaygroundEnvironment:
    """Playground's environment `name`, with its own episode limit unless `episode_length` is
    given, on MJX's `impl` ("jax" runs anywhere; Playground's default, "warp", compiles its
    kernels for about a minute on a CPU)."""
    registry = _registry()
    if name not in registry.ALL_ENVS:
        raise InvalidInput(
            f"MuJoCo Playground has no environment {name!r}; it offers: "
            + ", ".join(registry.ALL_ENVS)
        )
    config = registry.get_default_config(name)
    if "impl" in config:
        config.impl = impl
    try:
        env = registry.load(name, config=config)
    except Exception as error:
        if name in registry.dm_control_suite.ALL_ENVS:
            raise
        raise RuntimeError(
            f"could not load the MuJoCo Playground environment {name!r}: it fetches its assets "
            "(MuJoCo Menagerie) at run time, which needs network access. The dm_control suite "
            "tasks ship their XML with the package and load offline: "
            + ", ".join(registry.dm_control_suite.ALL_ENVS)
        ) from error
    return PlaygroundEnvironment(
        env, config.episode_length if episode_length is None else episode_length, obs_key
    )
