"""The return of a policy over whole episodes, run side by side in one compiled loop."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from fppo_jax.core.checks import check_seed, positive_int
from fppo_jax.core.policy import Policy
from fppo_jax.envs import Environment
from fppo_jax.errors import InvalidInput
from fppo_jax.run.execution import run_keys


def evaluate(
    env: Environment,
    policy: Policy,
    episodes: int = 10,
    *,
    seed: int = 0,
    deterministic: bool = True,
    max_steps: int = 10_000,
) -> np.ndarray:
    """The undiscounted return of each of `episodes` episodes of `policy` on `env`: the most
    likely actions if `deterministic`, sampled ones otherwise. Episodes run in lockstep until
    each ends (terminated or truncated) or `max_steps` have passed."""
    run = make_evaluator(env, episodes, deterministic=deterministic, max_steps=max_steps)
    return np.asarray(jax.jit(run)(policy, evaluation_key(seed)))


def evaluation_key(seed: int = 0) -> jax.Array:
    """The key of :func:`evaluate`'s episodes for `seed`: the same key, the same episodes."""
    return run_keys([check_seed(seed)])[0]


def make_evaluator(
    env: Environment,
    episodes: int,
    *,
    deterministic: bool = True,
    max_steps: int = 10_000,
) -> Callable[[Policy, jax.Array], jax.Array]:
    """:func:`evaluate` as a pure function of the policy and the key of its episodes
    (:func:`evaluation_key`), to jit once and call as often as training goes. To evaluate a
    batch of policies, vmap it over the policies and over a copy of the key for each: an
    environment stepped on the host (native MuJoCo, Gymnasium) makes its environments when it
    resets, and a key closed over, or not batched, would have every policy step the same ones."""
    positive_int("episodes", episodes)
    positive_int("max_steps", max_steps)  # else no step, and returns of 0 that look measured
    if not isinstance(deterministic, bool | np.bool_):
        raise InvalidInput(f"deterministic must be True or False, got {deterministic!r}")

    def run(policy: Policy, key: jax.Array) -> jax.Array:
        reset_key, run_key = jax.random.split(key)
        state, obs = jax.vmap(env.reset)(jax.random.split(reset_key, episodes))
        ended = jnp.zeros(episodes, bool)
        returns = jnp.zeros(episodes)

        def going(
            carry: tuple[jax.Array, jax.Array, Any, jax.Array, jax.Array, jax.Array],
        ) -> jax.Array:
            t, *_, ended, _ = carry
            return (t < max_steps) & ~jnp.all(ended)

        def step(
            carry: tuple[jax.Array, jax.Array, Any, jax.Array, jax.Array, jax.Array],
        ) -> tuple[jax.Array, jax.Array, Any, jax.Array, jax.Array, jax.Array]:
            t, key, state, obs, ended, returns = carry
            key, act_key, step_key = jax.random.split(key, 3)
            action = policy.act(obs, None if deterministic else act_key)
            state, out = jax.vmap(env.step)(jax.random.split(step_key, episodes), state, action)
            returns = returns + jnp.where(ended, 0.0, out.reward)
            ended = ended | out.terminated | out.truncated
            return t + 1, key, state, out.obs, ended, returns

        carry = (jnp.asarray(0), run_key, state, obs, ended, returns)
        return jax.lax.while_loop(going, step, carry)[-1]

    return run
