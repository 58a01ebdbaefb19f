"""Separate policy and value MLPs (baselines' ``value_network='copy'``), built with flax.

Orthogonal initialisation as in baselines: gain √2 on hidden layers, 0.01 on the policy head
(so the initial policy is near uniform / near zero-mean), 1 on the value head; biases 0.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any, TypedDict, cast

import flax.linen as nn
import jax
import jax.numpy as jnp
from flax.typing import VariableDict

from fppo_jax.core.distributions import Categorical, DiagonalGaussian, Distribution
from fppo_jax.envs import Box, Discrete
from fppo_jax.errors import InvalidInput


def orthogonal(scale: float) -> nn.initializers.Initializer:
    """Orthogonal initialisation whose QR stays unbatched under ``vmap``.

    Vmapping training over seeds would batch the QR, and jaxlib's CPU kernel for batched QR
    parallelises over the batch on the thread pool it runs on, which was seen to deadlock
    (every thread parked) on a 2-core machine. A sequential vmap does one QR per seed.
    """
    base = nn.initializers.orthogonal(scale)

    def init(key: jax.Array, shape: tuple[int, ...], dtype: Any = jnp.float32) -> jax.Array:
        per_seed = jax.custom_batching.sequential_vmap(lambda k: base(k, shape, dtype))
        return cast(jax.Array, per_seed(key))

    return init


class MLP(nn.Module):
    """tanh hidden layers, then a linear head of `out_size` units."""

    hidden_sizes: Sequence[int]
    out_size: int
    out_scale: float

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        for size in self.hidden_sizes:
            x = nn.tanh(nn.Dense(size, kernel_init=orthogonal(math.sqrt(2)))(x))
        return nn.Dense(self.out_size, kernel_init=orthogonal(self.out_scale))(x)


class CategoricalPolicy(nn.Module):
    hidden_sizes: Sequence[int]
    num_actions: int

    @nn.compact
    def __call__(self, obs: jax.Array) -> Categorical:
        return Categorical(MLP(self.hidden_sizes, self.num_actions, 0.01)(obs))


class GaussianPolicy(nn.Module):
    """Diagonal Gaussian with a state-independent log-std, initialised to `initial_log_std`."""

    hidden_sizes: Sequence[int]
    action_size: int
    initial_log_std: float = 0.0

    @nn.compact
    def __call__(self, obs: jax.Array) -> DiagonalGaussian:
        mean = MLP(self.hidden_sizes, self.action_size, 0.01)(obs)
        start = nn.initializers.constant(self.initial_log_std)
        log_std = self.param("log_std", start, (self.action_size,))
        return DiagonalGaussian(mean, jnp.broadcast_to(log_std, mean.shape))


class ValueFunction(nn.Module):
    hidden_sizes: Sequence[int]

    @nn.compact
    def __call__(self, obs: jax.Array) -> jax.Array:
        return MLP(self.hidden_sizes, 1, 1.0)(obs)[..., 0]


class Params(TypedDict):
    """Both networks' parameters, each as flax's ``init`` gives it."""

    policy: VariableDict
    value: VariableDict


@dataclasses.dataclass(frozen=True)
class Networks:
    policy: nn.Module
    value: nn.Module
    action_space: Discrete | Box

    def init(self, key: jax.Array, observation_size: int) -> Params:
        policy_key, value_key = jax.random.split(key)
        dummy = jnp.zeros((1, observation_size))
        return {
            "policy": self.policy.init(policy_key, dummy),
            "value": self.value.init(value_key, dummy),
        }

    def distribution(self, params: Params, obs: jax.Array) -> Distribution:
        return cast(Distribution, self.policy.apply(params["policy"], obs))

    def values(self, params: Params, obs: jax.Array) -> jax.Array:
        return cast(jax.Array, self.value.apply(params["value"], obs))

    def action_noise(self, key: jax.Array, batch_shape: tuple[int, ...]) -> jax.Array:
        """Standard noise for `batch_shape` samples of the policy (see ``sample_from``)."""
        if isinstance(self.action_space, Discrete):
            return Categorical.noise(key, (*batch_shape, self.action_space.n))
        return DiagonalGaussian.noise(key, (*batch_shape, self.action_space.size))


def policy_layers(params: VariableDict) -> list[dict[str, jax.Array]]:
    """The policy network's dense layers in order, hidden ones first, each its ``kernel`` and
    ``bias``, from the policy's parameters, where flax names them ``MLP_0/Dense_<i>`` (as
    checkpoints and saved policies keep them; numpy_policy reads the same names without JAX)."""
    mlp = params["params"]["MLP_0"]
    return [mlp[f"Dense_{i}"] for i in range(len(mlp))]


def make_networks(
    action_space: Discrete | Box, hidden_sizes: Sequence[int], initial_log_std: float = 0.0
) -> Networks:
    """The policy for `action_space` (categorical, or Gaussian starting at `initial_log_std`)
    and the value function."""
    hidden_sizes = tuple(hidden_sizes)
    policy: CategoricalPolicy | GaussianPolicy
    if isinstance(action_space, Discrete):
        if initial_log_std != 0.0:
            raise InvalidInput(
                f"initial_log_std ({initial_log_std:g}) sets a Gaussian policy's start: this "
                "task's actions are discrete"
            )
        policy = CategoricalPolicy(hidden_sizes, action_space.n)
    else:
        policy = GaussianPolicy(hidden_sizes, action_space.size, initial_log_std)
    return Networks(policy, ValueFunction(hidden_sizes), action_space)
