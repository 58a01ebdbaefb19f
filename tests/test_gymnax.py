"""Gymnax's environments (fppo_jax.envs.gymnax): the classic tasks' episode limits and ends, any
gymnax id by name, and a continuous one trained under jit."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fppo_jax import TrainConfig, hyperparameters, make_train
from fppo_jax.envs import Box, Discrete, make_env
from fppo_jax.envs.gymnax import gymnax_environment


def run_until_done(env, policy, limit=1000):
    """Steps one environment until its episode ends; returns (steps, last Step)."""
    state, obs = env.reset(jax.random.key(0))
    step = jax.jit(env.step)
    for t in range(1, limit + 1):
        state, out = step(jax.random.key(t), state, policy(obs))
        if out.terminated or out.truncated:
            return t, out
        obs = out.obs
    raise AssertionError("episode did not end")


def balance(o):
    return (o[2] + 0.5 * o[3] + 0.01 * o[0] + 0.1 * o[1] > 0).astype(jnp.int32)


def test_cartpole_is_truncated_at_200_steps():
    steps, out = run_until_done(make_env("cartpole"), balance)
    assert steps == 200
    assert bool(out.truncated) and not bool(out.terminated)


def test_mountaincar_random_policy_is_truncated_at_200():
    steps, out = run_until_done(make_env("mountaincar"), lambda o: jnp.int32(1))
    assert steps == 200 and bool(out.truncated) and not bool(out.terminated)


def test_cartpole_terminates_when_the_pole_falls():
    steps, out = run_until_done(make_env("cartpole"), lambda o: jnp.int32(1))
    assert steps < 50 and bool(out.terminated)


def test_acrobot_episode_limit_is_500():
    assert make_env("acrobot").params.max_steps_in_episode == 500


@pytest.mark.parametrize(
    "name, obs_size, action_space",
    [
        ("gymnax/Acrobot-v1", 6, Discrete(3)),
        ("gymnax/Pendulum-v1", 3, Box((-2.0,), (2.0,))),
        ("gymnax/Breakout-MinAtar", 10 * 10 * 4, Discrete(3)),  # image observations, flattened
    ],
)
def test_any_gymnax_environment_by_id(name, obs_size, action_space):
    env = make_env(name)
    assert env.observation_size == obs_size and env.action_space == action_space
    assert env.params.max_steps_in_episode == env.env.default_params.max_steps_in_episode
    state, obs = env.reset(jax.random.key(1))
    action = jnp.zeros(action_space.size) if isinstance(action_space, Box) else jnp.int32(0)
    state, out = jax.jit(env.step)(jax.random.key(2), state, action)
    assert obs.shape == out.obs.shape == (obs_size,) and out.obs.dtype == jnp.float32
    assert out.reward.shape == out.terminated.shape == out.truncated.shape == ()


def test_an_unknown_gymnax_id_lists_what_gymnax_offers():
    with pytest.raises(ValueError, match=r"^gymnax has no environment 'Nope-v0'; it offers: Cart"):
        make_env("gymnax/Nope-v0")


def test_a_continuous_gymnax_environment_trains_under_jit(tiny):
    env = gymnax_environment("Pendulum-v1")
    assert env.action_space == Box((-2.0,), (2.0,))
    config = TrainConfig(total_steps=3 * 128, **tiny)
    _, metrics = jax.jit(make_train(config, env))(jax.random.key(0), hyperparameters("ppo"))
    for name in ("policy_loss", "value_loss", "entropy", "approx_kl"):
        assert np.isfinite(getattr(metrics, name)).all(), name
