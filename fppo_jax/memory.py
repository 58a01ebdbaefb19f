"""How much memory runs need, estimated from shapes before anything compiles, and how many
runs fit in one compiled call.

The estimate counts what a call holds: the training state, in and out, and one update's
buffers (the reset states drawn for a rollout, the trajectory and its batch), with room for
the temporaries an update makes of them (the shuffled minibatches, gradients). Only the
state's shapes are traced (``jax.eval_shape`` of ``init``); an update's buffers follow from
them and the configuration, so that the estimate costs a fraction of a compilation.
"""

from __future__ import annotations

import math
import os
from typing import Any

import jax

from fppo_jax.config import Hyperparameters
from fppo_jax.envs import Discrete
from fppo_jax.trainer import Trainer

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
    over `split` devices), else the most that do, a multiple of `across`. Raises
    ``MemoryError``, before anything compiles, if even one run per device does not fit."""
    need, budget = run_bytes(trainer, key, hp) / split, free_bytes() / 2
    if need > budget:
        raise MemoryError(
            f"one run needs about {need / 2**30:.2f} GiB and {budget / 2**30:.2f} GiB (half the "
            "free memory of a device) is available: lower num_envs, num_steps, "
            "resets_per_rollout or hidden_sizes (each layer's width)"
        )
    fit = math.floor(budget / need) * across
    return min(wanted, max(across, fit - fit % across))


def free_bytes() -> float:
    """Free memory of this process's first device: its allocator's limit where it reports one
    (GPU, TPU), else the host's available memory."""
    device = jax.local_devices()[0]
    stats = device.memory_stats() if hasattr(device, "memory_stats") else None
    if stats and "bytes_limit" in stats:
        return float(stats["bytes_limit"] - stats.get("bytes_in_use", 0))
    return float(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))


def _bytes(tree: Any) -> int:
    return sum(math.prod(leaf.shape) * leaf.dtype.itemsize for leaf in jax.tree.leaves(tree))
