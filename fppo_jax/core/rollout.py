"""A rollout: ``lax.scan`` over steps, the environments vmapped, each episode's end followed by
a reset behind one small interface (:class:`Resets`: :class:`OwnResets` where the environment
resets itself, :class:`DrawnResets` drawn up front, one per step or a pool). Everything random
in it is drawn before the loop, in vectorised batches."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any, NamedTuple, Protocol, cast

import jax
import jax.numpy as jnp

from fppo_jax.core.config import Hyperparameters, TrainConfig
from fppo_jax.core.distributions import Distribution
from fppo_jax.core.networks import Networks, Params
from fppo_jax.envs import Box, Environment, Step, draw_resets, resets_itself, where_done


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Envs:
    """The environments of a run, each leaf with a leading environment axis."""

    state: Any
    obs: jax.Array  # raw observation of each environment, to act on next
    episode_return: jax.Array  # undiscounted return of each environment's current episode
    discounted_return: jax.Array  # for reward scaling, reset at episode ends


class Transition(NamedTuple):
    obs: jax.Array  # as the policy saw it (normalised)
    raw_obs: jax.Array
    action: jax.Array
    log_prob: jax.Array
    distribution: Distribution
    reward: jax.Array
    terminated: jax.Array
    truncated: jax.Array
    final_obs: jax.Array  # raw, the observation the step produced, before any reset
    discounted_return: jax.Array
    episode_return: jax.Array


class Resets(Protocol):
    """Where an episode ends in the rollout, what the environment goes on from."""

    def after_step(
        self, t: jax.Array, ended: jax.Array, done: jax.Array, stepped: Any, out: Step
    ) -> tuple[Any, jax.Array]:
        """The environments' state and observation after rollout step `t`, given each one's
        episodes `ended` before it, where `done`, the state `stepped` to, and the step `out`."""
        ...


class OwnResets:
    """The environment resets itself (a host-stepped one): its next observation is the new
    episode's first."""

    def after_step(
        self, t: jax.Array, ended: jax.Array, done: jax.Array, stepped: Any, out: Step
    ) -> tuple[Any, jax.Array]:
        return stepped, cast(jax.Array, out.next_obs)


@dataclasses.dataclass(frozen=True)
class DrawnResets:
    """Reset states and observations drawn up front, ``[row, env]``. Without a `pool`, an
    environment ending at step t takes row t, so every reset is fresh; with one, its episodes
    take the pool's rows in turn."""

    states: Any
    obs: jax.Array
    pool: int | None

    def after_step(
        self, t: jax.Array, ended: jax.Array, done: jax.Array, stepped: Any, out: Step
    ) -> tuple[Any, jax.Array]:
        if self.pool is None:
            take = lambda x: x[t]  # noqa: E731
        else:
            pool, envs = self.pool, jnp.arange(done.shape[0])
            take = lambda x: x[ended % pool, envs]  # noqa: E731
        reset_state, first_obs = jax.tree.map(take, (self.states, self.obs))
        return where_done(done, reset_state, stepped), where_done(done, first_obs, out.obs)


def make_resets(env: Environment, config: TrainConfig, key: jax.Array) -> Resets:
    """The rollout's resets: the environment's own, or drawn from `key`, one row per step or
    `config.resets_per_rollout` rows."""
    if resets_itself(env):
        return OwnResets()
    rows = config.resets_per_rollout or config.num_steps
    states, obs = draw_resets(env, key, (rows, config.num_envs))
    return DrawnResets(states, obs, config.resets_per_rollout)


def rollout(
    config: TrainConfig,
    env: Environment,
    networks: Networks,
    params: Params,
    observe: Callable[[jax.Array], jax.Array],
    envs: Envs,
    hp: Hyperparameters,
    key: jax.Array,
) -> tuple[Transition, Envs]:
    """`config.num_steps` steps of `config.num_envs` environments from `envs`, acting with
    the policy of `params` on what `observe` makes of each raw observation: the trajectory,
    time-major, and the environments where it left them."""
    action_space = env.action_space
    noise_key, step_key, reset_key = jax.random.split(key, 3)
    # Everything random in the rollout is drawn here, in vectorised batches: the action
    # noise, the step keys and the reset states taken where an episode ends. In the
    # sequential loop, per-step random draws and resets would cost more than the
    # environment's own dynamics.
    shape = (config.num_steps, config.num_envs)
    action_noise = networks.action_noise(noise_key, shape)
    step_keys = jax.random.split(step_key, shape)
    resets = make_resets(env, config, reset_key)
    step_env = jax.vmap(env.step)

    def step(
        carry: tuple[Envs, jax.Array], inputs: tuple[jax.Array, jax.Array, jax.Array]
    ) -> tuple[tuple[Envs, jax.Array], Transition]:
        envs, episodes_ended = carry
        noise, keys, t = inputs
        seen = observe(envs.obs)
        dist = networks.distribution(params, seen)
        action = dist.sample_from(noise)
        env_action = action
        if isinstance(action_space, Box):
            # The log-probability stays that of the unclipped sample.
            env_action = jnp.clip(
                action, jnp.asarray(action_space.low), jnp.asarray(action_space.high)
            )
        env_state, out = step_env(keys, envs.state, env_action)
        episode_return = envs.episode_return + out.reward
        discounted_return = envs.discounted_return * hp.gamma + out.reward
        done = out.terminated | out.truncated
        transition = Transition(
            obs=seen,
            raw_obs=envs.obs,
            action=action,
            log_prob=dist.log_prob(action),
            distribution=dist,
            reward=out.reward,
            terminated=out.terminated,
            truncated=out.truncated,
            final_obs=out.obs,
            discounted_return=discounted_return,
            episode_return=episode_return,
        )
        next_state, next_obs = resets.after_step(t, episodes_ended, done, env_state, out)
        envs = Envs(
            state=next_state,
            obs=next_obs,
            episode_return=jnp.where(done, 0.0, episode_return),
            discounted_return=jnp.where(done, 0.0, discounted_return),
        )
        return (envs, episodes_ended + done), transition

    ended = jnp.zeros(config.num_envs, jnp.int32)
    inputs = (action_noise, step_keys, jnp.arange(config.num_steps))
    (envs, _), traj = jax.lax.scan(step, (envs, ended), inputs)
    return traj, envs
