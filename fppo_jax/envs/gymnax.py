"""gymnax environments: the adapter, one made by id, and a check that needs no gymnax import.

gymnax is imported only when needed: importing it runs JAX computations, which would start
JAX's backends before a multi-process run can join (fppo_jax.run.distributed).
"""

from __future__ import annotations

import dataclasses
import functools
import importlib
import sys
from types import ModuleType
from typing import Any, TypeGuard

import jax
import jax.numpy as jnp
import numpy as np

from fppo_jax.envs.core import Box, Discrete, Step, key_shape
from fppo_jax.errors import InvalidInput


@dataclasses.dataclass(frozen=True)
class GymnaxEnvironment:
    """A gymnax (≥ 1.0) environment with fixed parameters (they set the episode limit).

    Observations are flattened: the trainer's networks take vectors, and MinAtar observes
    images.
    """

    env: Any  # gymnax.environments.environment.Environment
    params: Any
    backend = "gymnax"

    @functools.cached_property
    def observation_size(self) -> int:
        # From the reset's shapes, as the other adapters do: gymnax's observation space holds
        # arrays, each a small compiled program outside a trace.
        _, obs = jax.eval_shape(self.reset, key_shape())
        return int(obs.shape[-1])

    @property
    def action_space(self) -> Discrete | Box:
        from gymnax.environments import spaces

        space = self.env.action_space(self.params)
        if isinstance(space, spaces.Discrete):
            return Discrete(int(space.n))
        # numpy, not jnp: the bounds are constants, and jnp would trace them under jit.
        low = np.broadcast_to(np.asarray(space.low, np.float64), space.shape)
        high = np.broadcast_to(np.asarray(space.high, np.float64), space.shape)
        return Box(tuple(map(float, low)), tuple(map(float, high)))

    def reset(self, key: jax.Array) -> tuple[Any, jax.Array]:
        obs, state = self.env.reset(key, self.params)
        return state, obs.reshape(-1).astype(jnp.float32)

    def step(self, key: jax.Array, state: Any, action: jax.Array) -> tuple[Any, Step]:
        # gymnax's own `step` also computes a reset at every step; the trainer does that for
        # a whole rollout at once, so only the transition is taken here.
        obs, state, reward, terminated, _ = self.env.step_env(key, state, action, self.params)
        truncated = self.env.is_truncated(state, self.params)
        return state, Step(
            obs.reshape(-1).astype(jnp.float32), reward.astype(jnp.float32), terminated, truncated
        )


def gymnax_environment(env_id: str, max_steps: int | None = None) -> GymnaxEnvironment:
    """gymnax's environment `env_id`, with its default parameters and, if given, `max_steps`
    steps per episode."""
    gymnax = imported_gymnax()
    if env_id not in gymnax.registered_envs:
        raise InvalidInput(
            f"gymnax has no environment {env_id!r}; it offers: " + ", ".join(gymnax.registered_envs)
        )
    env, params = gymnax.make(env_id)
    if max_steps is not None:
        params = params.replace(max_steps_in_episode=max_steps)
    return GymnaxEnvironment(env, params)


# gymnax 1.0 imports seaborn and matplotlib (pyplot, colors) as it is imported, though only the
# render functions of a few of its environments use them; loading them is most of its import.
_DRAWING = ("seaborn", "matplotlib", "matplotlib.pyplot", "matplotlib.colors")


class _StandIn(ModuleType):
    """What gymnax's modules import in place of a drawing library: the library itself is
    imported, the usual way, when an attribute is first asked of this."""

    def __getattr__(self, attr: str) -> Any:
        if attr.startswith("__"):  # the import system's questions (``__path__``), not a use
            raise AttributeError(attr)
        submodule = sys.modules.get(f"{self.__name__}.{attr}")
        if isinstance(submodule, _StandIn):  # ``import matplotlib.pyplot as plt``, say
            return submodule
        if sys.modules.get(self.__name__) is self:  # asked during gymnax's own import
            sys.modules.pop(self.__name__, None)
        return getattr(importlib.import_module(self.__name__), attr)


def imported_gymnax() -> ModuleType:
    """gymnax, imported with its drawing libraries deferred (see :class:`_StandIn`);
    ``sys.modules`` is left as a plain import would leave it, less those libraries."""
    stand_ins = {
        name: _StandIn(name)
        for name in _DRAWING
        if name not in sys.modules and "gymnax" not in sys.modules
    }
    sys.modules.update(stand_ins)
    try:
        return importlib.import_module("gymnax")
    finally:
        for name, stand_in in stand_ins.items():
            if sys.modules.get(name) is stand_in:
                del sys.modules[name]


def is_gymnax_env(env: Any) -> TypeGuard[Any]:
    """Whether `env` is a gymnax environment (checked without importing gymnax if it is not
    loaded)."""
    if "gymnax" not in sys.modules:
        return False
    from gymnax.environments.environment import Environment as GymnaxEnv

    return isinstance(env, GymnaxEnv)
