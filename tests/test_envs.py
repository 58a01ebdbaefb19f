import jax
import jax.numpy as jnp
import pytest

from fppo_jax.envs import TASKS, Discrete, as_environment, make_env


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


def test_cartpole_is_truncated_at_200_steps():
    balance = lambda o: (o[2] + 0.5 * o[3] + 0.01 * o[0] + 0.1 * o[1] > 0).astype(jnp.int32)  # noqa: E731
    steps, out = run_until_done(make_env("cartpole"), balance)
    assert steps == 200
    assert bool(out.truncated) and not bool(out.terminated)
    # The final observation is the last state, not the reset one that `obs` holds.
    assert abs(float(out.final_obs[2])) > 0 and not jnp.allclose(out.final_obs, out.obs)


def test_mountaincar_random_policy_is_truncated_at_200():
    steps, out = run_until_done(make_env("mountaincar"), lambda o: jnp.int32(1))
    assert steps == 200 and bool(out.truncated) and not bool(out.terminated)


def test_cartpole_terminates_when_the_pole_falls():
    steps, out = run_until_done(make_env("cartpole"), lambda o: jnp.int32(1))
    assert steps < 50 and bool(out.terminated)


@pytest.mark.parametrize("name, obs_size, actions", [("cartpole", 4, 2), ("acrobot", 6, 3), ("mountaincar", 2, 3)])
def test_registered_tasks(name, obs_size, actions):
    env = make_env(name)
    assert env.observation_size == obs_size
    assert env.action_space == Discrete(actions)
    state, obs = env.reset(jax.random.key(1))
    state, out = env.step(jax.random.key(2), state, jnp.int32(0))
    assert out.obs.shape == (obs_size,) and out.obs.dtype == jnp.float32
    assert TASKS[name].total_steps == 100_000


def test_acrobot_episode_limit_is_500():
    assert make_env("acrobot").params.max_steps_in_episode == 500


def test_unknown_environment_lists_the_registered_ones():
    with pytest.raises(ValueError, match="unknown environment 'cartpol'; registered: cartpole, acrobot"):
        make_env("cartpol")
    with pytest.raises(TypeError, match="expected a registered environment name"):
        as_environment(42)
