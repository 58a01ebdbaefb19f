"""Gymnasium environments, registered or a user's own, one ``gymnasium.Env`` per environment or
a user's vector environments, stepped from inside the compiled training program.

As with native MuJoCo (:mod:`.native`), the environments run on the host: the JAX state of each
environment of a run is only the number of a host-side pool and its place in it. ``reset`` and
``step`` are ``jax.pure_callback``\\ s that vmap as one call over every environment of every run
(``vmap_method="broadcast_all"``), so a sweep makes one host call per step of its rollout,
whatever its number of runs and environments.

The step that ends an episode (``terminated`` or ``truncated``, kept apart) gives both the
episode's final observation, which the trainer bootstraps from at truncation, and the new
episode's first, which it acts on next: no action is spent on a reset or ignored. Each
environment is seeded from its own key, so a run's environments are the same whether it trains
alone or in a sweep. Their state lives outside JAX and no checkpoint holds it: a restored run
starts new episodes in fresh environments, as native MuJoCo's does.

**One** ``gymnasium.Env`` **per environment** (a registered id, a ``gymnasium.Env`` subclass or
a function that makes one): the step that ends an episode resets that environment at once. Each
is seeded at its first reset.

**A vector environment** (``gymnasium.vector.VectorEnv``) of N sub-environments serves N
environments of one run, so a run's ``num_envs`` (and an evaluation's episodes) must be a
multiple of N: otherwise an error names both numbers. Given as a function or a subclass that
makes one, it is made once per N environments of each run, so sweeps work as they do with a
``gymnasium.Env`` each. Given as an instance, it is the one vector environment there is: it
serves one run of ``num_envs=N``, a batch of several runs (a sweep's) is refused, naming the
function to pass instead, and resetting it for another batch (an evaluation during training)
retires the batch before, whose next step says so. Its autoreset mode,
``metadata["autoreset_mode"]``, says where an ended episode's observations are:

- ``SAME_STEP``: the step gives the new episode's first observation, and the final one in
  ``info["final_obs"]``.
- ``NEXT_STEP`` (Gymnasium's default, and taken where the metadata names none) and
  ``DISABLED``: the step gives the final observation, and the sub-environments that ended are
  reset at once, alone (``reset(options={"reset_mask": ended})``), rather than on the next step,
  which would ignore their action. A vector environment whose masked reset restarts the others
  too cannot do this and is refused: ``gymnasium.make_vec("CartPole-v1", n)``'s own
  ``CartPoleVectorEnv`` is one, and ``vectorization_mode="sync"`` makes CartPole a
  ``SyncVectorEnv`` instead. So is, in ``NEXT_STEP`` mode, an ``AsyncVectorEnv`` without shared
  memory, whose workers reset an ended sub-environment again on the step after its masked reset.

``SyncVectorEnv`` and ``AsyncVectorEnv`` seed each sub-environment from its own key, as a
``gymnasium.Env`` of its own is seeded, so the two give the same episodes; another vector
environment takes one seed, its first sub-environment's.

Observations must be a 1-D ``Box``; actions a ``Discrete`` or a 1-D ``Box`` (an action is
clipped to its bounds before ``step``). Other spaces are refused, naming the wrapper to use.

An environment is reset and stepped once on the host when its adapter is made, before anything
compiles, with the checks every later step has: one that breaks Gymnasium's API (a ``reset`` or
``step`` that raises or gives the wrong values, an observation or reward that is not finite
numbers of the right shape, an empty observation space) is refused with an ``InvalidInput`` that
names it and the fault. An id may be ``gymnasium.make``'s ``module:id``, whose module is imported
to register it.
"""

from __future__ import annotations

import collections
import dataclasses
import importlib
import importlib.util
import threading
import tracemalloc
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from fppo_jax.envs.core import Box, Discrete, HostState, OnHost, Step, seeds_of
from fppo_jax.envs.gymnasium_api import CheckedApi
from fppo_jax.errors import (
    InvalidInput,
    MissingPackage,
    did_you_mean,
    first_line,
    install_hint,
)

if TYPE_CHECKING:
    import jax

MAX_POOLS = 16  # pools kept alive at once: training's, and a few evaluations' beside it


def import_gymnasium() -> Any:
    if importlib.util.find_spec("gymnasium") is None:
        raise MissingPackage(f"Gymnasium environments need gymnasium: {install_hint('gymnasium')}")
    import gymnasium

    return gymnasium


class _Pools:
    """The live pools by number: each the environments of one reset of a batch of them (one per
    run or sweep group, and one per evaluation), ``gymnasium.Env``\\ s or vector environments.
    The oldest beyond :data:`MAX_POOLS` are closed, except a user's own vector environment
    instance, which is not ours to close; resetting that instance again retires its pool before,
    since one instance serves one batch at a time."""

    def __init__(self) -> None:
        self.pools: collections.OrderedDict[int, list[Any]] = collections.OrderedDict()
        self.instances: set[int] = set()  # the live pools of a user's instance
        self.retired: set[int] = set()
        self.count = 0
        self.lock = threading.Lock()

    def add(self, envs: list[Any], instance: bool = False) -> int:
        with self.lock:
            self.count += 1
            if instance:
                for number in [n for n in self.instances if self.pools[n][0] is envs[0]]:
                    del self.pools[number]
                    self.instances.remove(number)
                    self.retired.add(number)
                self.instances.add(self.count)
            self.pools[self.count] = envs
            while len(self.pools) > MAX_POOLS:
                number, dropped = self.pools.popitem(last=False)
                if number in self.instances:
                    self.instances.remove(number)
                else:
                    for env in dropped:
                        env.close()
            return self.count

    def __getitem__(self, number: int) -> list[Any]:
        with self.lock:
            if number in self.retired:
                raise RuntimeError(
                    f"Gymnasium environment pool {number}: its vector environment instance was "
                    "reset since for another batch of environments (a sweep's, or an evaluation "
                    "during training), and one instance serves one batch at a time: pass a "
                    "function that makes one, gymnasium_environment(lambda: ...)"
                )
            if number not in self.pools:
                raise RuntimeError(
                    f"Gymnasium environment pool {number} is closed (only the newest "
                    f"{MAX_POOLS} are kept, and none outlives its process): reset the environments"
                )
            return self.pools[number]


_POOLS = _Pools()


@dataclasses.dataclass(frozen=True, eq=False)
class GymnasiumEnvironment(OnHost):
    """The Gymnasium environments that `make()` gives, one ``gymnasium.Env`` or one
    ``gymnasium.vector.VectorEnv`` per call, as an :class:`~fppo_jax.envs.core.Environment`
    that resets itself, called through `api`; `name` names them in errors and records.
    `instance`: `make` gives the same vector environment every time, a user's own (see the
    module's docstring). Made by :func:`_probed`, which checks them first."""

    make: Callable[[], Any]
    name: str
    api: CheckedApi
    instance: bool = False
    vector_size: int = 0  # sub-environments per vector environment; 0: one gymnasium.Env each
    same_step: bool = False  # a vector environment's autoreset mode is SAME_STEP
    host_bytes: int = 0  # what each gymnasium.Env of a run holds on the host (0: not measured)
    backend = "gymnasium"

    @property
    def observation_size(self) -> int:  # type: ignore[override]
        return self.api.observation_size

    @property
    def action_space(self) -> Discrete | Box:  # type: ignore[override]
        return self.api.action_space

    def check_runs(self, runs: int, evaluates: bool) -> None:
        """Refuse, before compiling, what a vector environment instance cannot serve: the one
        vector environment there is serves one run, and no evaluation beside it."""
        if self.instance and (runs > 1 or evaluates):
            what = f"a sweep's {runs} runs" if runs > 1 else "an evaluation during training"
            raise InvalidInput(
                f"{self.name} is one vector environment, for one run and no evaluation beside "
                f"it, so it cannot serve {what}: pass a function that makes one, "
                "gymnasium_environment(lambda: gymnasium.make_vec(...)), or its class"
            )

    def check_batch(self, per_run: int) -> None:
        """Refuse `per_run` environments per run (num_envs, or an evaluation's episodes) that
        the vector environments' sub-environments cannot serve; checked before compiling."""
        size = self.vector_size
        if size and per_run % size:
            raise InvalidInput(
                f"{self.name}: its vector environment has {size} sub-environments, which cannot "
                f"serve {per_run} environments per run (num_envs, or an evaluation's episodes): "
                f"make them a multiple of {size} (num_envs={size}, say), or make the vector "
                f"environment with {per_run}"
            )

    def _host_reset(self, key_data: np.ndarray) -> tuple[HostState, np.ndarray]:
        key_data = np.asarray(key_data)
        batch = key_data.shape[:-1]
        seeds = seeds_of(key_data)
        if self.vector_size:
            envs, first = self._reset_vectors(batch, seeds)
        else:
            envs = [self.make() for _ in seeds]
            first = np.stack(
                [
                    self.api.observation(self.api.reset(env, seed=seed), "reset")
                    for env, seed in zip(envs, seeds, strict=True)
                ]
            )
        number = _POOLS.add(envs, self.instance)
        slots = np.arange(len(seeds), dtype=np.int32)
        # numpy arrays in the fields typed as the jax.Arrays that pure_callback makes of them
        state = HostState(
            cast("jax.Array", np.full(batch, number, np.int32)),
            cast("jax.Array", slots.reshape(batch)),
            cast("jax.Array", np.zeros(batch, np.int32)),
        )
        return state, first.reshape(*batch, self.observation_size)

    def _reset_vectors(
        self, batch: tuple[int, ...], seeds: list[int]
    ) -> tuple[list[Any], np.ndarray]:
        """A vector environment per `vector_size` environments of each run (the last axis of
        `batch`: a run's environments, or an evaluation's episodes), reset from their seeds."""
        size = self.vector_size
        per_run = batch[-1] if batch else 1
        self.check_batch(per_run)
        count = len(seeds) // size
        if self.instance and count > 1:
            raise InvalidInput(
                f"{self.name} is one vector environment, for one run of num_envs={size}; it "
                f"cannot serve {len(seeds) // per_run} run(s) of {per_run} environments (a "
                "sweep's runs, say): pass a function that makes one, "
                "gymnasium_environment(lambda: gymnasium.make_vec(...)), or its class, and one "
                f"is made for each {size} environments of each run"
            )
        vectors = [self.make() for _ in range(count)]
        first = [
            self.api.observation(
                self.api.reset(
                    vector, seed=_vector_seeds(vector, seeds[i * size : (i + 1) * size])
                ),
                "reset",
                size,
            )
            for i, vector in enumerate(vectors)
        ]
        return vectors, np.concatenate(first)

    def _host_step(
        self, pool: np.ndarray, slot: np.ndarray, steps: np.ndarray, action: np.ndarray
    ) -> Step:
        batch = np.shape(pool)
        pools, slots = np.asarray(pool).reshape(-1), np.asarray(slot).reshape(-1)
        actions = self.api.actions(np.asarray(action).reshape(len(slots), -1))
        count = len(slots)
        # numpy arrays in the fields typed as the jax.Arrays that pure_callback makes of them
        out = Step(
            obs=cast("jax.Array", np.empty((count, self.observation_size), np.float32)),
            reward=cast("jax.Array", np.empty(count, np.float32)),
            terminated=cast("jax.Array", np.empty(count, bool)),
            truncated=cast("jax.Array", np.empty(count, bool)),
            next_obs=cast("jax.Array", np.empty((count, self.observation_size), np.float32)),
        )
        step = self._step_vectors if self.vector_size else self._step_envs
        for number in np.unique(pools):
            rows = np.flatnonzero(pools == number)
            step(_POOLS[int(number)], slots[rows], actions[rows], rows, out)
        return Step(*(x.reshape(batch + x.shape[1:]) for x in cast("tuple[jax.Array, ...]", out)))

    def _step_envs(
        self, envs: list[Any], slots: np.ndarray, actions: np.ndarray, rows: np.ndarray, out: Step
    ) -> None:
        """Step `envs`' `slots` (one ``gymnasium.Env`` each) and write `rows` of `out`."""
        assert out.next_obs is not None  # given, as by every environment that resets itself
        for env_slot, action, row in zip(slots, actions, rows, strict=True):
            env = envs[env_slot]
            obs, reward, terminated, truncated, _ = self.api.step(env, action)
            out.obs[row] = self.api.observation(obs, "step")
            out.reward[row] = self.api.reward(reward)
            terminated = self.api.flags(terminated, "terminated")
            truncated = self.api.flags(truncated, "truncated")
            out.terminated[row] = terminated
            out.truncated[row] = truncated and not terminated
            out.next_obs[row] = out.obs[row]
            if terminated or truncated:
                out.next_obs[row] = self.api.observation(self.api.reset(env), "reset")

    def _step_vectors(
        self,
        vectors: list[Any],
        slots: np.ndarray,
        actions: np.ndarray,
        rows: np.ndarray,
        out: Step,
    ) -> None:
        """Step `vectors`, every sub-environment at once, and write `rows` of `out`."""
        size = self.vector_size
        order = np.argsort(slots)
        if not np.array_equal(slots[order], np.arange(len(vectors) * size)):
            raise RuntimeError(
                f"{self.name}: a vector environment steps all its sub-environments at once, so a "
                "step must take every environment that its reset made"
            )
        for i, vector in enumerate(vectors):
            block = order[i * size : (i + 1) * size]
            self._step_vector(vector, actions[block], rows[block], out)

    def _step_vector(self, vector: Any, actions: np.ndarray, rows: np.ndarray, out: Step) -> None:
        assert out.next_obs is not None  # given, as by every environment that resets itself
        obs, reward, terminated, truncated, info = self.api.step(vector, actions)
        size = self.vector_size
        obs = self.api.observation(obs, "step", size)
        reward = self.api.reward(reward, size)
        # casts: with a count, _flags gives an array
        terminated = cast(np.ndarray, self.api.flags(terminated, "terminated", size))
        truncated = cast(np.ndarray, self.api.flags(truncated, "truncated", size))
        ended = terminated | truncated
        final = first = obs
        if ended.any() and self.same_step:
            final = obs.copy()
            final[ended] = self.api.final_observations(info, ended)
        elif ended.any():
            first = obs.copy()
            reset = self.api.reset(vector, options={"reset_mask": ended})
            first[ended] = self.api.observation(reset, "reset", size)[ended]
        out.obs[rows] = final
        out.reward[rows] = reward
        out.terminated[rows] = terminated
        out.truncated[rows] = truncated & ~terminated
        out.next_obs[rows] = first


def _probed(make: Callable[[], Any], name: str, instance: bool = False) -> GymnasiumEnvironment:
    """The environments that `make` gives, checked on one made for the purpose (closed after,
    unless it is the `instance`): its spaces, and a reset and a step with the checks every later
    step has, or a vector environment's autoreset; an environment that breaks the API is named
    before a program is compiled around it."""
    gymnasium = import_gymnasium()
    try:
        probe = make()
    except gymnasium.error.DependencyNotInstalled as error:
        raise MissingPackage(f"{name} cannot be made: {first_line(error)}") from None
    vector = isinstance(probe, gymnasium.vector.VectorEnv)
    if not vector and not isinstance(probe, gymnasium.Env):
        raise TypeError(
            f"{name}: expected a gymnasium.Env or a gymnasium.vector.VectorEnv, got "
            f"{type(probe).__name__}"
        )
    try:
        api = CheckedApi.of(gymnasium, probe, name)
        if vector:
            size, same_step = _checked_autoreset(api, probe)
        else:
            api.observation(api.reset(probe, seed=0), "reset")
            api.check_step(api.step(probe, api.still_actions(1)[0]))
    finally:
        if not instance:
            probe.close()
    if vector:
        return GymnasiumEnvironment(make, name, api, instance, size, same_step)
    return GymnasiumEnvironment(make, name, api, host_bytes=_bytes_per_environment(api, make))


def _bytes_per_environment(api: CheckedApi, make: Callable[[], Any]) -> int:
    """The Python memory one more environment takes, made and reset, as tracemalloc counts it
    (what a C library allocates itself, such as a simulator's state, is not counted): a run's
    pool holds num_envs of them, which :mod:`fppo_jax.run.memory` checks. Measured on a second one,
    since the first also imported the environment's modules."""
    tracing = tracemalloc.is_tracing()
    if not tracing:
        tracemalloc.start()
    before = tracemalloc.get_traced_memory()[0]
    env = make()
    try:
        api.reset(env, seed=0)
        return max(0, tracemalloc.get_traced_memory()[0] - before)
    finally:
        env.close()
        if not tracing:
            tracemalloc.stop()


def _checked_autoreset(api: CheckedApi, vector: Any) -> tuple[int, bool]:
    """`vector`'s size and whether its autoreset mode is SAME_STEP, once checked: refused where
    an ended episode cannot restart at once (in NEXT_STEP or DISABLED mode, a reset of one
    sub-environment alone must leave the others as they were)."""
    from gymnasium.vector import AsyncVectorEnv, AutoresetMode

    mode = AutoresetMode(vector.metadata.get("autoreset_mode", AutoresetMode.NEXT_STEP))
    unwrapped = vector.unwrapped
    if (
        mode == AutoresetMode.NEXT_STEP
        and isinstance(unwrapped, AsyncVectorEnv)
        and not unwrapped.shared_memory
    ):
        # Gymnasium 1.x: its workers clear their pending autoreset on a reset only when
        # they share memory, so without it each masked reset is followed by another.
        raise InvalidInput(
            f"{api.name}: an AsyncVectorEnv without shared memory, in NEXT_STEP autoreset "
            "mode, resets an ended sub-environment again on the step after its masked "
            "reset, ignoring its action; make it with shared_memory=True (the default) or "
            'autoreset_mode="SameStep"'
        )
    size, same_step = int(vector.num_envs), mode == AutoresetMode.SAME_STEP
    api.observation(api.reset(vector, seed=0), "reset", size)
    stepped = api.step(vector, api.still_actions(size))
    api.check_step(stepped, size)
    if same_step or size == 1:
        return size, same_step
    first_alone = np.arange(size) == 0
    kept = api.reset(vector, options={"reset_mask": first_alone})
    if not np.array_equal(np.array(kept)[1:], np.array(stepped[0])[1:]):
        raise InvalidInput(
            f"{api.name}: reset(options={{'reset_mask': mask}}) restarts sub-environments "
            f"outside the mask, so in its {mode.name} autoreset mode an episode that ends "
            "cannot restart alone without an action ignored on the next step; use a vector "
            "environment that resets the masked ones alone (gymnasium.vector.SyncVectorEnv "
            'or AsyncVectorEnv: gymnasium.make_vec(..., vectorization_mode="sync"))'
        )
    return size, same_step


def _vector_seeds(vector: Any, seeds: list[int]) -> list[int] | int:
    """What `vector` is reset from, given its sub-environments' seeds: one each where it takes
    them (SyncVectorEnv, AsyncVectorEnv), else the first one."""
    from gymnasium.vector import AsyncVectorEnv, SyncVectorEnv

    each = isinstance(vector.unwrapped, SyncVectorEnv | AsyncVectorEnv)
    return seeds if each else seeds[0]


def gymnasium_environment(
    env: str | Callable[[], Any] | Any, **kwargs: Any
) -> GymnasiumEnvironment:
    """A registered Gymnasium id (made with ``gymnasium.make(env, **kwargs)``), a function that
    makes one ``gymnasium.Env`` or one ``gymnasium.vector.VectorEnv`` (a subclass of either, say;
    called with `kwargs`), or a vector environment itself, for ``train`` and ``sweep`` (see the
    module's docstring for vector environments). The same id and arguments give the same
    environment object, so that a later run reuses the program compiled for it."""
    if isinstance(env, str):
        return _registered(env, tuple(sorted(kwargs.items())))
    if isinstance(env, import_gymnasium().vector.VectorEnv):
        if kwargs:
            raise TypeError(f"{env} is made already: keyword arguments are for an id or a function")
        return _probed(lambda: env, str(env), instance=True)
    name = getattr(env, "__name__", repr(env))
    if kwargs:
        return _probed(lambda: env(**kwargs), name)
    return _probed(env, name)


_MADE: dict[tuple[str, tuple[tuple[str, Any], ...]], GymnasiumEnvironment] = {}


def _registered(env_id: str, kwargs: tuple[tuple[str, Any], ...]) -> GymnasiumEnvironment:
    """`env_id` as ``gymnasium.make`` takes it: a registered id, or ``module:id``, whose module
    is imported first to register it."""
    key = (env_id, kwargs)
    if key not in _MADE:
        gymnasium = import_gymnasium()
        module, _, registered_id = env_id.rpartition(":")
        if module:
            try:
                importlib.import_module(module)
            except ImportError as error:
                raise MissingPackage(
                    f"gymnasium/{env_id}: cannot import {module!r}, which should register "
                    f"{registered_id!r}: {first_line(error)}"
                ) from None
        if registered_id not in gymnasium.registry:
            imported = f" once {module!r} is imported" if module else ""
            raise InvalidInput(
                f"Gymnasium has no environment {registered_id!r} registered{imported}"
                f"{did_you_mean(registered_id, gymnasium.registry)} "
                "(gymnasium.pprint_registry() lists them; an environment of one's own is "
                "registered by its module, named as gymnasium/module:id)"
            )
        arguments = ", ".join(f"{name}={value!r}" for name, value in kwargs)
        _MADE[key] = _probed(
            lambda: gymnasium.make(env_id, **dict(kwargs)),
            f"gymnasium/{env_id}" + (f"({arguments})" if arguments else ""),
        )
    return _MADE[key]


def is_gymnasium_env(env: Any) -> bool:
    """Whether `env` is what :func:`gymnasium_environment` takes as it is, without a function
    around it: a ``gymnasium.Env`` or ``gymnasium.vector.VectorEnv`` subclass (a class), or a
    vector environment (an instance)."""
    if importlib.util.find_spec("gymnasium") is None:
        return False
    import gymnasium

    kinds = (gymnasium.Env, gymnasium.vector.VectorEnv)
    return isinstance(env, gymnasium.vector.VectorEnv) or (
        isinstance(env, type) and issubclass(env, kinds)
    )
