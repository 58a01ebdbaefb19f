"""Generalised advantage estimation with time-limit truncation."""

from __future__ import annotations

import jax
import jax.numpy as jnp


def gae(
    rewards: jax.Array,
    values: jax.Array,
    next_values: jax.Array,
    terminated: jax.Array,
    truncated: jax.Array,
    gamma: jax.Array | float,
    gae_lambda: jax.Array | float,
) -> tuple[jax.Array, jax.Array]:
    """Advantages and value targets of a rollout, time on the leading axis.

    `next_values[t]` is V of the observation step t produced *before any auto-reset*, so a
    time-limit truncation bootstraps from the true last state while a termination does not:

        δ_t = r_t + γ (1 − term_t) V(s'_t) − V(s_t)
        A_t = δ_t + γ λ (1 − done_t) A_{t+1},   done = term ∨ trunc,   A_T = 0

    Returns ``(A, A + V)``.
    """
    not_terminated = 1.0 - terminated.astype(values.dtype)
    not_done = 1.0 - jnp.logical_or(terminated, truncated).astype(values.dtype)
    deltas = rewards + gamma * not_terminated * next_values - values
    decay = gamma * gae_lambda * not_done

    # A_t = δ_t + c_t A_{t+1} is the affine map x ↦ δ_t + c_t x applied backwards in time.
    # Composing affine maps is associative, so a log-depth associative scan replaces a
    # sequential loop over the rollout's steps.
    def compose(
        later: tuple[jax.Array, jax.Array], earlier: tuple[jax.Array, jax.Array]
    ) -> tuple[jax.Array, jax.Array]:
        c_later, d_later = later
        c_earlier, d_earlier = earlier
        return c_earlier * c_later, d_earlier + c_earlier * d_later

    _, advantages = jax.lax.associative_scan(compose, (decay, deltas), reverse=True)
    return advantages, advantages + values
