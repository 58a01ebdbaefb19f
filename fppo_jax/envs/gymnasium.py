"""Gymnasium environments, registered or a user's own, stepped from inside the compiled
training program.

As with native MuJoCo (:mod:`.native`), the environments run on the host: each environment of
a run is one ``gymnasium.Env`` of a host-side pool, and its JAX state is only the pool's
number and its place in it. ``reset`` and ``step`` are ``jax.pure_callback``\\ s that vmap as
one call over every environment of every run (``vmap_method="broadcast_all"``), so a sweep
makes one host call per step of its rollout, whatever its number of runs and environments.

Each environment is a ``gymnasium.Env`` of its own, not a vector environment, so no
autoreset mode is involved: the step that ends an episode (``terminated`` or ``truncated``,
kept apart) resets that environment at once and returns both the episode's final observation,
which the trainer bootstraps from at truncation, and the new episode's first. Each
environment is seeded from its own key (its first reset), so a run's environments are the same
whether it trains alone or in a sweep. Their state lives outside JAX and no checkpoint holds
it: a restored run starts new episodes in fresh environments, as native MuJoCo's does.

Observations must be a 1-D ``Box``; actions a ``Discrete`` or a 1-D ``Box`` (an action is
clipped to its bounds before ``step``). Other spaces are refused, naming the wrapper to use.
"""

from __future__ import annotations

import collections
import dataclasses
import importlib.util
import threading
from collections.abc import Callable
from typing import Any

import numpy as np

from fppo_jax.envs.core import Box, Discrete, HostState, OnHost, Step, seeds_of
from fppo_jax.extras import install_hint

MAX_POOLS = 16  # pools kept alive at once: training's, and a few evaluations' beside it


def import_gymnasium() -> Any:
    if importlib.util.find_spec("gymnasium") is None:
        raise ImportError(f"Gymnasium environments need gymnasium: {install_hint('gymnasium')}")
    import gymnasium

    return gymnasium


class _Pools:
    """The live pools (lists of ``gymnasium.Env``) by number; the oldest beyond
    :data:`MAX_POOLS` are closed (a pool is made per reset of a batch of environments: one per
    run or sweep group, and one per evaluation)."""

    def __init__(self) -> None:
        self.pools: collections.OrderedDict[int, list[Any]] = collections.OrderedDict()
        self.count = 0
        self.lock = threading.Lock()

    def add(self, envs: list[Any]) -> int:
        with self.lock:
            self.count += 1
            self.pools[self.count] = envs
            while len(self.pools) > MAX_POOLS:
                for env in self.pools.popitem(last=False)[1]:
                    env.close()
            return self.count

    def __getitem__(self, number: int) -> list[Any]:
        with self.lock:
            if number not in self.pools:
                raise RuntimeError(
                    f"Gymnasium environment pool {number} is closed (only the newest "
                    f"{MAX_POOLS} are kept, and none outlives its process): reset the environments"
                )
            return self.pools[number]


_POOLS = _Pools()


@dataclasses.dataclass(frozen=True, eq=False)
class GymnasiumEnvironment(OnHost):
    """The Gymnasium environments that `make()` gives (one ``gymnasium.Env`` per call) as an
    :class:`~fppo_jax.envs.core.Environment` that resets itself; `name` names them in errors
    and records."""

    make: Callable[[], Any]
    name: str
    backend = "gymnasium"
    action_start = 0  # a Discrete space's first action

    def __post_init__(self) -> None:
        gymnasium = import_gymnasium()
        probe = self.make()
        if not isinstance(probe, gymnasium.Env):
            raise TypeError(f"{self.name}: expected a gymnasium.Env, got {type(probe).__name__}")
        try:
            spaces = gymnasium.spaces
            observations, actions = probe.observation_space, probe.action_space
            if not isinstance(observations, spaces.Box) or len(observations.shape) != 1:
                raise ValueError(
                    f"{self.name}: observations must be a 1-D Box, got {observations}; wrap the "
                    "environment in gymnasium.wrappers.FlattenObservation"
                )
            if isinstance(actions, spaces.Discrete):
                space: Discrete | Box = Discrete(int(actions.n))
                object.__setattr__(self, "action_start", int(actions.start))
            elif isinstance(actions, spaces.Box) and len(actions.shape) == 1:
                space = Box(tuple(map(float, actions.low)), tuple(map(float, actions.high)))
            else:
                raise ValueError(
                    f"{self.name}: actions must be Discrete or a 1-D Box, got {actions}; wrap "
                    "the environment in a gymnasium.ActionWrapper that maps one of those onto it"
                )
        finally:
            probe.close()
        object.__setattr__(self, "observation_size", int(observations.shape[0]))
        object.__setattr__(self, "action_space", space)

    def _host_reset(self, key_data: np.ndarray) -> tuple[HostState, np.ndarray]:
        key_data = np.asarray(key_data)
        batch = key_data.shape[:-1]
        seeds = seeds_of(key_data)
        envs = [self.make() for _ in seeds]
        first = np.stack(
            [
                self._observation(env.reset(seed=seed)[0], "reset")
                for env, seed in zip(envs, seeds, strict=True)
            ]
        )
        number = _POOLS.add(envs)
        slots = np.arange(len(envs), dtype=np.int32)
        state = HostState(
            np.full(batch, number, np.int32), slots.reshape(batch), np.zeros(batch, np.int32)
        )
        return state, first.reshape(*batch, self.observation_size)

    def _host_step(
        self, pool: np.ndarray, slot: np.ndarray, steps: np.ndarray, action: np.ndarray
    ) -> Step:
        batch = np.shape(pool)
        pools, slots = np.asarray(pool).reshape(-1), np.asarray(slot).reshape(-1)
        actions = np.asarray(action).reshape(len(slots), -1)
        count = len(slots)
        out = Step(
            obs=np.empty((count, self.observation_size), np.float32),
            reward=np.empty(count, np.float32),
            terminated=np.empty(count, bool),
            truncated=np.empty(count, bool),
            next_obs=np.empty((count, self.observation_size), np.float32),
        )
        for row in range(count):
            env = _POOLS[int(pools[row])][int(slots[row])]
            try:
                obs, reward, terminated, truncated, _ = env.step(self._action(actions[row]))
            except Exception as error:
                raise RuntimeError(
                    f"{self.name}: step raised {type(error).__name__}: {error}"
                ) from error
            out.obs[row] = self._observation(obs, "step")
            if not np.isfinite(reward):
                raise ValueError(f"{self.name}: step returned the reward {reward}")
            out.reward[row] = reward
            out.terminated[row] = bool(terminated)
            out.truncated[row] = bool(truncated) and not terminated
            out.next_obs[row] = out.obs[row]
            if terminated or truncated:
                out.next_obs[row] = self._observation(env.reset()[0], "reset")
        return Step(*(x.reshape(batch + x.shape[1:]) for x in out))

    def _action(self, action: np.ndarray) -> Any:
        if isinstance(self.action_space, Discrete):
            return int(action[0]) + self.action_start
        space = self.action_space
        return np.clip(action, space.low, space.high).astype(np.float32)

    def _observation(self, obs: Any, where: str) -> np.ndarray:
        obs = np.asarray(obs, np.float32)
        if obs.shape != (self.observation_size,):
            raise ValueError(
                f"{self.name}: {where} returned an observation of shape {obs.shape}, not "
                f"({self.observation_size},) as its observation space says"
            )
        if not np.isfinite(obs).all():
            raise ValueError(f"{self.name}: {where} returned a non-finite observation {obs}")
        return obs


def gymnasium_environment(env: str | Callable[[], Any], **kwargs: Any) -> GymnasiumEnvironment:
    """A registered Gymnasium id (made with ``gymnasium.make(env, **kwargs)``) or a function
    that makes one ``gymnasium.Env`` (a ``gymnasium.Env`` subclass, say), for ``train`` and
    ``sweep``. The same id and arguments give the same environment object, so that a later
    run reuses the program compiled for it."""
    if isinstance(env, str):
        return _registered(env, tuple(sorted(kwargs.items())))
    if kwargs:
        return GymnasiumEnvironment(lambda: env(**kwargs), getattr(env, "__name__", repr(env)))
    return GymnasiumEnvironment(env, getattr(env, "__name__", repr(env)))


_MADE: dict[tuple, GymnasiumEnvironment] = {}


def _registered(env_id: str, kwargs: tuple) -> GymnasiumEnvironment:
    key = (env_id, kwargs)
    if key not in _MADE:
        gymnasium = import_gymnasium()
        if env_id not in gymnasium.registry:
            raise ValueError(
                f"Gymnasium has no environment {env_id!r} registered (gymnasium.pprint_registry() "
                "lists them)"
            )
        arguments = ", ".join(f"{name}={value!r}" for name, value in kwargs)
        _MADE[key] = GymnasiumEnvironment(
            lambda: gymnasium.make(env_id, **dict(kwargs)),
            f"gymnasium/{env_id}" + (f"({arguments})" if arguments else ""),
        )
    return _MADE[key]


def is_gymnasium_env_class(env: Any) -> bool:
    """Whether `env` is a ``gymnasium.Env`` subclass (a class, not an instance)."""
    if importlib.util.find_spec("gymnasium") is None or not isinstance(env, type):
        return False
    import gymnasium

    return issubclass(env, gymnasium.Env)
