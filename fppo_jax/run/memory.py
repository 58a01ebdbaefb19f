"""How much memory runs need, estimated from shapes before anything compiles, and how many
runs fit in one compiled call.

The estimate counts what a call holds: the training state, in and out, and one update's
buffers (the reset states drawn for a rollout, the trajectory and its batch), with room for
the temporaries an update makes of them (the shuffled minibatches, gradients). Only the
state's shapes are traced (``jax.eval_shape`` of ``init``); an update's buffers follow from
them and the configuration, so that the estimate costs a fraction of a compilation.

Host-stepped environments (Gymnasium's) also hold a pool of Python objects on the host, one
per environment of each run, whose size the adapter measured on one of them
(``host_bytes``): those runs must fit in half the host's available memory too.
"""

from __future__ import annotations

import math
import os
from typing import Any

import jax

from fppo_jax.core.config import Hyperparameters
from fppo_jax.core.trainer import Trainer
from fppo_jax.envs import Discrete
from fppo_jax.errors import NotEnoughMemory

STATE_COPIES = 2  # the state a call takes and the one it returns
# An update's buffers, their shuffled copies and the temporaries around them. Set against XLA's
# own analysis of the compiled program: CartPole with the paper preset needs 2.6 MiB a run
# (temporaries and twice the arguments), and this estimates 2.7.
UPDATE_COPIES = 5


def run_bytes(trainer: Trainer, key: jax.Array, hp: Hyperparameters) -> int:
    """Bytes one run needs on its device, estimated from shapes (see the module docstring)."""
    config, space = trainer.config, trainer.env.action_space
    state = jax.eval_shape(trainer.init, key, hp)
    per_environment = _bytes(state.envs) / config.num_envs
    resets = (config.resets_per_rollout or config.num_steps) * config.num_envs * per_environment
    # Per sample of the trajectory and again of its batch: the observation (as the policy saw
    # it, raw, and the step's own), the action with its distribution's parameters (logits, or
    # mean and log-std), and about a dozen scalars (log-probability, reward, flags, returns,
    # value, advantage, target), all four bytes wide.
    action = 1 + space.n if isinstance(space, Discrete) else 3 * space.size
    sample = 4 * (3 * trainer.env.observation_size + action + 12)
    samples = 2 * config.samples_per_update * sample
    return int(STATE_COPIES * _bytes(state) + UPDATE_COPIES * (resets + samples))


def host_run_bytes(trainer: Trainer) -> int:
    """Bytes one run's environments hold on the host outside JAX: a host-stepped environment's
    pool of Python objects (Gymnasium's ``host_bytes`` each), 0 for the others."""
    return getattr(trainer.env, "host_bytes", 0) * trainer.config.num_envs


def check_host_memory(trainer: Trainer, runs: int) -> None:
    """Raise ``MemoryError``, before anything compiles, if `runs` runs' host-stepped
    environments would not fit in half the host's available memory."""
    per_run, budget = host_run_bytes(trainer), host_available_bytes() / 2
    if per_run * runs <= budget:
        return
    env, count = trainer.env, trainer.config.num_envs
    raise NotEnoughMemory(
        f"{getattr(env, 'name', type(env).__name__)}: {runs} run(s) of {count:,} environments, "
        f"each a Python object of about {env.host_bytes / 2**10:.1f} KiB on the host, need "  # type: ignore[attr-defined]  # host-stepped envs have it
        f"about {per_run * runs / 2**30:.2f} GiB and {budget / 2**30:.2f} GiB (half the "
        "host's available memory) is available: lower num_envs"
        + (", or the runs per call (chunk)" if runs > 1 else "")
    )


def runs_per_call(
    trainer: Trainer,
    key: jax.Array,
    hp: Hyperparameters,
    wanted: int,
    across: int = 1,
    split: int = 1,
) -> int:
    """How many of `wanted` runs to train per compiled call: all of them if they fit in half
    the free memory of the `across` devices that share them (each run's environments split
    over `split` devices), else the most that do, a multiple of `across`; host-stepped
    environments' runs also fit in half the host's available memory. Raises ``MemoryError``,
    before anything compiles, if even one run per device does not fit."""
    need, budget = run_bytes(trainer, key, hp) / split, free_bytes() / 2
    if need > budget:
        raise NotEnoughMemory(
            f"one run needs about {need / 2**30:.2f} GiB and {budget / 2**30:.2f} GiB (half the "
            "free memory of a device) is available: lower num_envs, num_steps, "
            "resets_per_rollout or hidden_sizes (each layer's width)"
        )
    fit = math.floor(budget / need) * across
    host = host_run_bytes(trainer)
    if host:  # host-stepped environments, on one device in one process (across is 1)
        check_host_memory(trainer, 1)
        fit = min(fit, math.floor(host_available_bytes() / 2 / host))
    return min(wanted, max(across, fit - fit % across))


def free_bytes() -> float:
    """Free memory of this process's first device: its allocator's limit where it reports one
    (GPU, TPU), else the host's available memory."""
    device = jax.local_devices()[0]
    stats = device.memory_stats() if hasattr(device, "memory_stats") else None
    if stats and "bytes_limit" in stats:
        return float(stats["bytes_limit"] - stats.get("bytes_in_use", 0))
    return float(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))


def host_available_bytes() -> float:
    """The host's available memory: what the kernel could give without swapping (Linux's
    MemAvailable, which counts the page cache it would drop), else its free memory."""
    try:
        with open("/proc/meminfo") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024
    except OSError:
        pass
    return float(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))


def _bytes(tree: Any) -> int:
    return sum(math.prod(leaf.shape) * leaf.dtype.itemsize for leaf in jax.tree.leaves(tree))
