"""gym's own MuJoCo tasks in native MuJoCo (envpool's C++ ports), stepped from inside the
compiled training program.

The physics runs on the host: each environment of a run is a slot of an envpool pool, and
its JAX state is only the pool's number and the slot's. ``reset`` and ``step`` are
``jax.pure_callback``s that vmap as one call over every environment of every run
(``vmap_method="broadcast_all"``), so a sweep steps one pool of runs × environments per step of
its rollout, with no Python loop per environment.

envpool resets an ended environment on its next ``step`` and reports that call's output as if it
were a transition. Here the step that ends an episode resets the environment at once (a reset of
just those slots), and returns both the episode's final observation, which the trainer
bootstraps from at truncation, and the new episode's first, which it acts on next: the
environment resets itself (:attr:`resets_itself`), so the trainer draws no reset states for it.

Each environment is seeded from its own key, so a run's environments are the same whether it
trains alone or in a sweep. The state behind the slots lives outside JAX and no checkpoint
holds it: a restored run starts new episodes in fresh environments (see
:meth:`~fppo_jax.core.trainer.Trainer.restart_envs`).
"""

from __future__ import annotations

import collections
import dataclasses
import importlib.util
import os
import threading
from types import ModuleType
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from fppo_jax.envs.core import Box, HostState, OnHost, Step, seeds_of
from fppo_jax.errors import InvalidInput, did_you_mean, install_hint

if TYPE_CHECKING:
    import jax

INSTALL = f"{install_hint('native')}; envpool, Linux only"
MAX_POOLS = 16  # pools kept alive at once: training's, and a few evaluations' beside it


def envpool_installed() -> bool:
    return importlib.util.find_spec("envpool") is not None


def require_envpool() -> None:
    if not envpool_installed():
        raise InvalidInput(f"the native backend steps MuJoCo through envpool: {INSTALL}")


def import_envpool() -> ModuleType:
    """envpool, without the process-wide settings its import makes: envpool 1.2 sets
    MPLBACKEND=Agg (and MPLCONFIGDIR, TF_CPP_MIN_LOG_LEVEL, ...) in the environment, which
    would silence matplotlib's figures in this process and in every process it starts."""
    require_envpool()
    saved = dict(os.environ)
    import envpool

    for name in set(os.environ) - set(saved):
        del os.environ[name]
    os.environ.update({n: v for n, v in saved.items() if os.environ.get(n) != v})
    return envpool


class _Pools:
    """The live pools by number, the newest :data:`MAX_POOLS` kept (a pool is made per reset
    of a batch of environments: one per run or sweep group, and one per evaluation)."""

    def __init__(self) -> None:
        self.pools: collections.OrderedDict[int, Any] = collections.OrderedDict()
        self.count = 0
        self.lock = threading.Lock()

    def add(self, pool: Any) -> int:
        with self.lock:
            self.count += 1
            self.pools[self.count] = pool
            while len(self.pools) > MAX_POOLS:
                self.pools.popitem(last=False)
            return self.count

    def __getitem__(self, number: int) -> Any:
        with self.lock:
            if number not in self.pools:
                raise RuntimeError(
                    f"native environment pool {number} is closed (only the newest {MAX_POOLS} "
                    "are kept, and none outlives its process): reset the environments"
                )
            return self.pools[number]


_POOLS = _Pools()


@dataclasses.dataclass(frozen=True, eq=False)
class NativeEnvironment(OnHost):
    """The envpool task `task_id` (e.g. ``"Hopper-v3"``) as an
    :class:`~fppo_jax.envs.core.Environment` that resets itself; its episode limit is reported
    as truncation, separately from termination."""

    task_id: str
    observation_size: int
    action_space: Box
    max_episode_steps: int
    backend = "native"

    @classmethod
    def of(cls, task_id: str) -> NativeEnvironment:
        """envpool's `task_id`, refused unless envpool has it as a MuJoCo task."""
        envpool = import_envpool()
        if task_id not in (tasks := envpool.list_all_envs()):
            raise InvalidInput(f"envpool has no task {task_id!r}{did_you_mean(task_id, tasks)}")
        spec = envpool.make_spec(task_id)
        space = spec.action_space
        if len(spec.observation_space.shape) != 1 or not hasattr(space, "low"):
            raise InvalidInput(
                f"envpool's {task_id} is not a MuJoCo task (its observations have shape "
                f"{spec.observation_space.shape}, its actions are {type(space).__name__}): "
                "native/ takes envpool's MuJoCo tasks, e.g. native/Hopper-v4"
            )
        (size,) = spec.observation_space.shape
        bounds = Box(tuple(map(float, space.low)), tuple(map(float, space.high)))
        return cls(task_id, int(size), bounds, int(spec.config.max_episode_steps))

    def _host_reset(self, key_data: np.ndarray) -> tuple[HostState, np.ndarray]:
        envpool = import_envpool()
        key_data = np.asarray(key_data)
        batch = key_data.shape[:-1]
        seeds = seeds_of(key_data)
        count = len(seeds)
        pool = envpool.make(
            self.task_id,
            env_type="gymnasium",
            num_envs=count,
            env_seed=seeds,
            num_threads=min(count, usable_cores()),
        )
        obs, info = pool.reset()
        number = _POOLS.add(pool)
        slots = np.arange(count, dtype=np.int32)
        first = np.empty_like(obs)
        first[info["env_id"]] = obs
        # numpy arrays in the fields typed as the jax.Arrays that pure_callback makes of them
        return (
            HostState(
                cast("jax.Array", np.full(batch, number, np.int32)),
                cast("jax.Array", slots.reshape(batch)),
                cast("jax.Array", np.zeros(batch, np.int32)),
            ),
            first.reshape(*batch, -1).astype(np.float32),
        )

    def _host_step(
        self, pool: np.ndarray, slot: np.ndarray, steps: np.ndarray, action: np.ndarray
    ) -> Step:
        batch = np.shape(pool)
        pools, slots = np.asarray(pool).reshape(-1), np.asarray(slot).reshape(-1)
        actions = np.asarray(action, np.float64).reshape(len(slots), -1)
        # numpy arrays in the fields typed as the jax.Arrays that pure_callback makes of them
        out = Step(
            obs=cast("jax.Array", np.empty((len(slots), self.observation_size), np.float32)),
            reward=cast("jax.Array", np.empty(len(slots), np.float32)),
            terminated=cast("jax.Array", np.empty(len(slots), bool)),
            truncated=cast("jax.Array", np.empty(len(slots), bool)),
            next_obs=cast("jax.Array", np.empty((len(slots), self.observation_size), np.float32)),
        )
        for number in np.unique(pools):
            rows = np.flatnonzero(pools == number)
            _step_pool(_POOLS[int(number)], slots[rows], actions[rows], rows, out)
        return Step(*(x.reshape(*batch, *x.shape[1:]) for x in cast("tuple[jax.Array, ...]", out)))


def usable_cores() -> int:
    """The cores this process may run on: a cluster job's share (its CPU affinity, and at most
    SLURM's ``SLURM_CPUS_PER_TASK``), not the whole node's count."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cores = os.cpu_count() or 1
    # A cluster that binds no task to its cores (SLURM's task/none plugin) leaves the whole
    # node in the affinity; the task's share is then SLURM's count alone.
    given = os.environ.get("SLURM_CPUS_PER_TASK", "")
    if given.isascii() and given.isdigit() and int(given) > 0:
        return min(cores, int(given))
    return cores


def _step_pool(
    pool: Any, slots: np.ndarray, actions: np.ndarray, rows: np.ndarray, out: Step
) -> None:
    """Step `slots` of `pool` with `actions`, reset the ones whose episode ended, and write
    their outcome to `out`'s `rows`."""
    assert out.next_obs is not None  # given, as by every environment that resets itself
    obs, reward, terminated, truncated, info = pool.step(actions, slots)
    # envpool answers in its own order: each answer is placed by the slot it names.
    where = rows[_positions(slots, info["env_id"])]
    out.obs[where] = obs
    out.reward[where] = reward
    out.terminated[where] = terminated
    out.truncated[where] = truncated & ~terminated
    out.next_obs[where] = obs
    ended = info["env_id"][terminated | truncated]
    if len(ended):
        first, info = pool.reset(ended)
        out.next_obs[rows[_positions(slots, info["env_id"])]] = first


def _positions(slots: np.ndarray, answered: np.ndarray) -> np.ndarray:
    """Where each slot of `answered` sits in `slots`."""
    order = np.argsort(slots)
    return order[np.searchsorted(slots, answered, sorter=order)]
