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
import math
import threading
import traceback
import tracemalloc
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from fppo_jax.envs.core import Box, Discrete, HostState, OnHost, Step, seeds_of
from fppo_jax.errors import InvalidInput, MissingPackage, install_hint
from fppo_jax.files import first_line

if TYPE_CHECKING:
    import jax

MAX_POOLS = 16  # pools kept alive at once: training's, and a few evaluations' beside it
# What one environment's step gives as its reward, and as terminated and truncated, mostly.
SCALARS = (float, int, np.float32, np.float64, np.int64)
FLAGS = (bool, np.bool_)


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
    that resets itself; `name` names them in errors and records. `instance`: `make` gives the
    same vector environment every time, a user's own (see the module's docstring)."""

    make: Callable[[], Any]
    name: str
    instance: bool = False
    backend = "gymnasium"
    action_start = 0  # a Discrete space's first action
    vector_size = 0  # sub-environments per vector environment; 0: one gymnasium.Env each
    same_step = False  # a vector environment's autoreset mode is SAME_STEP
    host_bytes = 0  # what each gymnasium.Env of a run holds on the host (0: not measured)

    def __post_init__(self) -> None:
        gymnasium = import_gymnasium()
        try:
            probe = self.make()
        except gymnasium.error.DependencyNotInstalled as error:
            raise MissingPackage(f"{self.name} cannot be made: {first_line(error)}") from None
        vector = isinstance(probe, gymnasium.vector.VectorEnv)
        if not vector and not isinstance(probe, gymnasium.Env):
            raise TypeError(
                f"{self.name}: expected a gymnasium.Env or a gymnasium.vector.VectorEnv, got "
                f"{type(probe).__name__}"
            )
        try:
            if vector:
                observations, actions = probe.single_observation_space, probe.single_action_space
                wrappers = "gymnasium.wrappers.vector.", "gymnasium.vector.VectorActionWrapper"
            else:
                observations, actions = probe.observation_space, probe.action_space
                wrappers = "gymnasium.wrappers.", "gymnasium.ActionWrapper"
            spaces = gymnasium.spaces
            if not isinstance(observations, spaces.Box) or len(observations.shape) != 1:
                raise InvalidInput(
                    f"{self.name}: observations must be a 1-D Box, got {observations}; wrap the "
                    f"environment in {wrappers[0]}FlattenObservation"
                )
            if observations.shape[0] == 0:
                raise InvalidInput(
                    f"{self.name}: its observation space {observations} is empty, and a policy "
                    "needs at least one number to act on"
                )
            if isinstance(actions, spaces.Discrete):
                space: Discrete | Box = Discrete(int(actions.n))
                object.__setattr__(self, "action_start", int(actions.start))
            elif isinstance(actions, spaces.Box) and len(actions.shape) == 1:
                space = Box(tuple(map(float, actions.low)), tuple(map(float, actions.high)))
            else:
                raise InvalidInput(
                    f"{self.name}: actions must be Discrete or a 1-D Box, got {actions}; wrap "
                    f"the environment in a {wrappers[1]} that maps one of those onto it"
                )
            object.__setattr__(self, "observation_size", int(observations.shape[0]))
            object.__setattr__(self, "action_space", space)
            if vector:
                self._check_autoreset(probe)
            else:
                self._check_first_step(probe)
        finally:
            if not self.instance:
                probe.close()
        if not vector:
            object.__setattr__(self, "host_bytes", self._bytes_per_environment())

    def _bytes_per_environment(self) -> int:
        """The Python memory one more environment takes, made and reset, as tracemalloc counts
        it (what a C library allocates itself, such as a simulator's state, is not counted):
        a run's pool holds num_envs of them, which :mod:`fppo_jax.memory` checks. Measured on a
        second one, since the first also imported the environment's modules."""
        tracing = tracemalloc.is_tracing()
        if not tracing:
            tracemalloc.start()
        before = tracemalloc.get_traced_memory()[0]
        env = self.make()
        try:
            self._reset(env, seed=0)
            return max(0, tracemalloc.get_traced_memory()[0] - before)
        finally:
            env.close()
            if not tracing:
                tracemalloc.stop()

    def _check_first_step(self, env: Any) -> None:
        """Reset `env` and step it once, on the host, with the checks every step has: an
        environment that breaks the API is named before a program is compiled around it."""
        self._observation(self._reset(env, seed=0), "reset")
        self._check_step(self._step(env, self._still_actions(1)[0]))

    def _check_step(self, out: tuple[Any, ...], count: int | None = None) -> None:
        """A step's outcome (`count` of them from a vector environment) checked."""
        obs, reward, terminated, truncated, _ = out
        self._observation(obs, "step", count)
        self._reward(reward, count)
        self._flags(terminated, "terminated", count)
        self._flags(truncated, "truncated", count)

    def _check_autoreset(self, vector: Any) -> None:
        """Take `vector`'s size and autoreset mode, and refuse it where an ended episode cannot
        restart at once: in NEXT_STEP or DISABLED mode, a reset of one sub-environment alone
        must leave the others as they were."""
        from gymnasium.vector import AsyncVectorEnv, AutoresetMode

        mode = AutoresetMode(vector.metadata.get("autoreset_mode", AutoresetMode.NEXT_STEP))
        object.__setattr__(self, "vector_size", int(vector.num_envs))
        object.__setattr__(self, "same_step", mode == AutoresetMode.SAME_STEP)
        unwrapped = vector.unwrapped
        if (
            mode == AutoresetMode.NEXT_STEP
            and isinstance(unwrapped, AsyncVectorEnv)
            and not unwrapped.shared_memory
        ):
            # Gymnasium 1.x: its workers clear their pending autoreset on a reset only when
            # they share memory, so without it each masked reset is followed by another.
            raise InvalidInput(
                f"{self.name}: an AsyncVectorEnv without shared memory, in NEXT_STEP autoreset "
                "mode, resets an ended sub-environment again on the step after its masked "
                "reset, ignoring its action; make it with shared_memory=True (the default) or "
                'autoreset_mode="SameStep"'
            )
        size = self.vector_size
        self._observation(self._reset(vector, seed=0), "reset", size)
        stepped = self._step(vector, self._still_actions(size))
        self._check_step(stepped, size)
        if self.same_step or size == 1:
            return
        first_alone = np.arange(size) == 0
        kept = self._reset(vector, options={"reset_mask": first_alone})
        if not np.array_equal(np.array(kept)[1:], np.array(stepped[0])[1:]):
            raise InvalidInput(
                f"{self.name}: reset(options={{'reset_mask': mask}}) restarts sub-environments "
                f"outside the mask, so in its {mode.name} autoreset mode an episode that ends "
                "cannot restart alone without an action ignored on the next step; use a vector "
                "environment that resets the masked ones alone (gymnasium.vector.SyncVectorEnv "
                'or AsyncVectorEnv: gymnasium.make_vec(..., vectorization_mode="sync"))'
            )

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
                    self._observation(self._reset(env, seed=seed), "reset")
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
            self._observation(
                self._reset(vector, seed=_vector_seeds(vector, seeds[i * size : (i + 1) * size])),
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
        actions = self._actions(np.asarray(action).reshape(len(slots), -1))
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
            obs, reward, terminated, truncated, _ = self._step(env, action)
            out.obs[row] = self._observation(obs, "step")
            out.reward[row] = self._reward(reward)
            terminated = self._flags(terminated, "terminated")
            truncated = self._flags(truncated, "truncated")
            out.terminated[row] = terminated
            out.truncated[row] = truncated and not terminated
            out.next_obs[row] = out.obs[row]
            if terminated or truncated:
                out.next_obs[row] = self._observation(self._reset(env), "reset")

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
        obs, reward, terminated, truncated, info = self._step(vector, actions)
        size = self.vector_size
        obs = self._observation(obs, "step", size)
        reward = self._reward(reward, size)
        # casts: with a count, _flags gives an array
        terminated = cast(np.ndarray, self._flags(terminated, "terminated", size))
        truncated = cast(np.ndarray, self._flags(truncated, "truncated", size))
        ended = terminated | truncated
        final = first = obs
        if ended.any() and self.same_step:
            final = obs.copy()
            final[ended] = self._final_observations(info, ended)
        elif ended.any():
            first = obs.copy()
            reset = self._reset(vector, options={"reset_mask": ended})
            first[ended] = self._observation(reset, "reset", size)[ended]
        out.obs[rows] = final
        out.reward[rows] = reward
        out.terminated[rows] = terminated
        out.truncated[rows] = truncated & ~terminated
        out.next_obs[rows] = first

    def _final_observations(self, info: dict[str, Any], ended: np.ndarray) -> np.ndarray:
        """The final observations of the episodes that `ended`, from a SAME_STEP step's info."""
        if "final_obs" not in info:
            raise InvalidInput(
                f"{self.name}: its autoreset mode is SAME_STEP, but step gave no "
                "info['final_obs'] for the episodes that ended"
            )
        final = np.stack([info["final_obs"][i] for i in np.flatnonzero(ended)])
        return self._observation(final, "step's info['final_obs']", int(ended.sum()))

    def _reset(self, env: Any, **arguments: Any) -> Any:
        """`env`'s first observation(s) from ``reset(**arguments)``, which must give
        (observation, info)."""
        try:
            out = env.reset(**arguments)
        except Exception as error:
            raise InvalidInput(f"{self.name}: reset {_raised(error)}") from error
        if not (isinstance(out, tuple) and len(out) == 2):
            raise InvalidInput(
                f"{self.name}: reset returned {_described(out)}, not the pair (observation, "
                "info) of Gymnasium's API"
            )
        return out[0]

    def _step(self, env: Any, action: Any) -> tuple[Any, ...]:
        """``env.step(action)``, which must give Gymnasium's five values."""
        try:
            out = env.step(action)
        except Exception as error:
            raise InvalidInput(f"{self.name}: step {_raised(error)}") from error
        if not (isinstance(out, tuple) and len(out) == 5):
            raise InvalidInput(
                f"{self.name}: step returned {_described(out)}, not the five values (observation, "
                "reward, terminated, truncated, info) of Gymnasium's API (four are the old Gym "
                "API's, with one done for both terminated and truncated)"
            )
        return out

    def _still_actions(self, count: int) -> np.ndarray:
        """`count` actions for a check, as Gymnasium takes them: a Discrete space's first, or
        the Box's point nearest zero."""
        width = 1 if isinstance(self.action_space, Discrete) else self.action_space.size
        return self._actions(np.zeros((count, width), np.float32))

    def _actions(self, actions: np.ndarray) -> np.ndarray:
        """The actions [count, …] as Gymnasium takes them: a Discrete space's from its first
        action (integers, as its ``sample`` gives), a Box's clipped to its bounds."""
        if isinstance(self.action_space, Discrete):
            return cast(np.ndarray, actions[:, 0].astype(np.int64) + self.action_start)
        space = self.action_space
        return cast(np.ndarray, np.clip(actions, space.low, space.high).astype(np.float32))

    def _reward(self, reward: Any, count: int | None = None) -> Any:
        """`reward` checked: one finite number, or `count` of them from a vector environment."""
        if count is None and type(reward) in SCALARS and math.isfinite(reward):
            return reward  # the usual case, at every step of every environment
        shape = () if count is None else (count,)
        values = _numbers(reward)
        if values is None or values.shape != shape or not np.isfinite(values).all():
            expected = "a finite number" if count is None else f"{count} finite numbers"
            raise InvalidInput(
                f"{self.name}: step returned the reward {_described(reward)}, not {expected}"
            )
        return values

    def _flags(self, flags: Any, which: str, count: int | None = None) -> np.ndarray | bool:
        """`terminated` or `truncated` checked: one flag, or `count` of them."""
        if count is None and type(flags) in FLAGS:
            return bool(flags)  # the usual case, at every step of every environment
        shape = () if count is None else (count,)
        values = np.asarray(flags)
        if values.shape != shape or values.dtype.kind not in "biu":
            raise InvalidInput(
                f"{self.name}: step returned {which}={_described(flags)}, not "
                + ("a bool" if count is None else f"{count} bools")
            )
        return values.astype(bool)

    def _observation(self, obs: Any, where: str, count: int | None = None) -> np.ndarray:
        """`obs` checked: one observation, or `count` of them from a vector environment. A copy,
        since a vector environment may hand back a buffer of its own that its reset rewrites."""
        checked = _numbers(obs)
        if checked is None:
            raise InvalidInput(
                f"{self.name}: {where} returned the observation {_described(obs)}, not numbers"
            )
        obs = checked.astype(np.float32)
        shape = (self.observation_size,) if count is None else (count, self.observation_size)
        if obs.shape != shape:
            raise InvalidInput(
                f"{self.name}: {where} returned observations of shape {obs.shape}, not {shape} "
                "as its observation space says"
            )
        if not np.isfinite(obs).all():
            raise InvalidInput(f"{self.name}: {where} returned a non-finite observation {obs}")
        return cast(np.ndarray, obs)  # `obs`, the parameter, is Any; it is `checked` now


def _numbers(value: Any) -> np.ndarray | None:
    """`value` as an array of numbers (a copy), or None where it holds something else (None, a
    string, a ragged list)."""
    try:
        array = np.array(value)
    except (TypeError, ValueError):
        return None
    return array if array.dtype.kind in "biuf" else None


def _described(value: Any) -> str:
    """`value` in a few words, for an error: its type, and its shape or text."""
    if isinstance(value, tuple):
        return f"a {len(value)}-tuple"
    if isinstance(value, np.ndarray):
        return f"an array of shape {value.shape} ({value.dtype})"
    text = repr(value)
    return f"{text[:60]}…" if len(text) > 60 else f"{text} ({type(value).__name__})"


def _raised(error: Exception) -> str:
    """What an environment's own exception says, and where in its code it was raised."""
    frame = traceback.extract_tb(error.__traceback__)[-1]
    where = f"{frame.filename}:{frame.lineno}"
    return f"raised {type(error).__name__}: {first_line(error)} (at {where})"


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
        return GymnasiumEnvironment(lambda: env, str(env), instance=True)
    name = getattr(env, "__name__", repr(env))
    if kwargs:
        return GymnasiumEnvironment(lambda: env(**kwargs), name)
    return GymnasiumEnvironment(env, name)


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
                f"Gymnasium has no environment {registered_id!r} registered{imported} "
                "(gymnasium.pprint_registry() lists them; an environment of one's own is "
                "registered by its module, named as gymnasium/module:id)"
            )
        arguments = ", ".join(f"{name}={value!r}" for name, value in kwargs)
        _MADE[key] = GymnasiumEnvironment(
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
