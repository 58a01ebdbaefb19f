"""The PPO-family loss: a pure function of the parameters and a minibatch."""

from __future__ import annotations

from typing import Any, NamedTuple, cast

import jax
import jax.numpy as jnp

from fppo_jax.core.config import Hyperparameters
from fppo_jax.core.distributions import Distribution
from fppo_jax.core.networks import Networks, Params
from fppo_jax.core.variants import negative_regions, outside_clip_range


class Batch(NamedTuple):
    """Samples of one update; the rollout policy's distribution is kept for the exact KL."""

    obs: jax.Array
    action: jax.Array
    log_prob: jax.Array
    value: jax.Array
    advantage: jax.Array
    target: jax.Array
    distribution: Distribution


class LossInfo(NamedTuple):
    policy_loss: jax.Array
    value_loss: jax.Array
    entropy: jax.Array
    approx_kl: jax.Array
    clip_fraction: jax.Array
    negative_fraction: jax.Array


def ppo_loss(
    params: Params,
    batch: Batch,
    hp: Hyperparameters,
    networks: Networks,
    clip_value_loss: bool = True,
) -> tuple[jax.Array, LossInfo]:
    """−mean L(r, A) + c_v · value loss − c_e · entropy, with L the variant's surrogate.

    Value loss (baselines): ½ mean max((V − R)², (V_old + clip(V − V_old, −ε, ε) − R)²).
    `approx_kl` is the unbiased estimator mean((r − 1) − log r) of KL(π_old ‖ π_θ); the exact
    per-sample KL is what gates the trust-region variants.
    """
    o = hp.objective
    dist = networks.distribution(params, batch.obs)
    log_ratio = dist.log_prob(batch.action) - batch.log_prob
    ratio = jnp.exp(log_ratio)
    kl = jax.lax.stop_gradient(batch.distribution.kl(cast(Any, dist)))  # dist: the same kind
    policy_loss = -jnp.mean(o(ratio, batch.advantage, kl))

    value = networks.values(params, batch.obs)
    value_error = (value - batch.target) ** 2
    if clip_value_loss:
        clipped = batch.value + jnp.clip(value - batch.value, -o.epsilon, o.epsilon)
        value_error = jnp.maximum(value_error, (clipped - batch.target) ** 2)
    value_loss = 0.5 * jnp.mean(value_error)

    entropy = jnp.mean(dist.entropy())
    loss = policy_loss + hp.value_coef * value_loss - hp.entropy_coef * entropy

    below, above = o.clip_range()
    r_plus, r_minus = negative_regions(ratio, batch.advantage, below, above)
    # One stacked reduction instead of one per diagnostic: fewer kernels per minibatch step.
    diagnostics = jnp.mean(
        jax.lax.stop_gradient(
            jnp.stack(
                [
                    (ratio - 1) - log_ratio,
                    outside_clip_range(ratio, below, above),
                    r_plus | r_minus,
                ]
            )
        ),
        axis=1,
    )
    info = LossInfo(policy_loss, value_loss, entropy, *diagnostics)
    return loss, jax.tree.map(jax.lax.stop_gradient, info)
