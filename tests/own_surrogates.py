"""Surrogates of one's own, importable by the tests as ``own_surrogates:NAME`` (the way the
command line's ``--variant module:attribute`` finds a user's)."""

import jax.numpy as jnp

import fppo_jax


def clipped(ratio, advantage, epsilon):
    """PPO's clipped objective, written again."""
    return jnp.minimum(ratio * advantage, jnp.clip(ratio, 1 - epsilon, 1 + epsilon) * advantage)


def clip_higher(ratio, advantage, kl, eps_low, eps_high):
    clipped_ratio = jnp.clip(ratio, 1 - eps_low, 1 + eps_high)
    return jnp.minimum(ratio * advantage, clipped_ratio * advantage)


my_ppo = fppo_jax.surrogate("my-ppo", clipped)
my_clip_higher = fppo_jax.surrogate(
    "my-clip-higher",
    clip_higher,
    eps_low=0.2,
    eps_high=0.28,
    ranges={"eps_low": "(0, 1)", "eps_high": "> 0"},
    clip_range=("eps_low", "eps_high"),
)


def unmoved(ratio, advantage):
    """An objective whose gradient is zero everywhere: the policy never moves, so it never
    learns, whatever the learning rate: a candidate any study can tell from one that learns."""
    return 0.0 * ratio * advantage


frozen = fppo_jax.surrogate("frozen", unmoved)


def nan_above_half(ratio, advantage, epsilon, beta):
    """PPO's clipped objective where beta <= 1/2, and NaN above: a surrogate not finite over
    part of its search interval."""
    return clipped(ratio, advantage, epsilon) + jnp.where(beta > 0.5, jnp.nan, 0.0)


half_finite = fppo_jax.surrogate(
    "half-finite", nan_above_half, beta=0.25, ranges={"beta": "[0, 1]"}, search={"beta": (0, 1)}
)
