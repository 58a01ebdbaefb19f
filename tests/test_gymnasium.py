"""fppo_jax/envs/gymnasium.py: Gymnasium environments, registered and a user's own, stepped on
the host from inside the compiled program."""

import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import TINY

from fppo_jax import make_env, sweep, train
from fppo_jax.envs import Discrete, as_environment
from fppo_jax.envs.gymnasium import gymnasium_environment


class Corridor(gymnasium.Env):
    """Walk right (action 1) to position 3: terminated there; truncated at 5 steps otherwise.
    Observations are (position, steps); every step rewards 1."""

    observation_space = gymnasium.spaces.Box(-10.0, 10.0, (2,), np.float32)
    action_space = gymnasium.spaces.Discrete(2)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.position, self.steps = 0, 0
        return np.array([0.0, 0.0], np.float32), {}

    def step(self, action):
        self.position += int(action)
        self.steps += 1
        obs = np.array([self.position, self.steps], np.float32)
        return obs, 1.0, self.position >= 3, self.steps >= 5, {}


class Broken(Corridor):
    def step(self, action):
        raise RuntimeError("the simulator crashed")


class NaNs(Corridor):
    def step(self, action):
        obs, reward, terminated, truncated, info = super().step(action)
        return obs * np.nan, reward, terminated, truncated, info


def rollout(env, action: int, steps: int):
    """`steps` steps of one environment, always taking `action`."""

    def step(state, key):
        state, out = env.step(key, state, jnp.int32(action))
        return state, out

    state, _ = env.reset(jax.random.key(0))
    return jax.jit(lambda s: jax.lax.scan(step, s, jax.random.split(jax.random.key(1), steps)))(
        state
    )[1]


def test_episodes_end_where_the_environment_says_and_restart_at_once():
    env = as_environment(Corridor)
    assert env.observation_size == 2 and env.action_space == Discrete(2)
    right = rollout(env, 1, 9)
    np.testing.assert_array_equal(np.flatnonzero(right.terminated) + 1, [3, 6, 9])
    assert not right.truncated.any()
    np.testing.assert_array_equal(right.obs[2], [3, 3])  # the final observation, kept
    np.testing.assert_array_equal(right.next_obs[2], [0, 0])  # and the next episode's first
    still = rollout(env, 0, 10)
    np.testing.assert_array_equal(np.flatnonzero(still.truncated) + 1, [5, 10])
    assert not still.terminated.any()
    assert as_environment(Corridor) is env  # one adapter per class: one compiled program


def test_a_user_s_environment_trains_and_is_recorded_by_name():
    result = train(Corridor, "ppo", total_steps=512, **TINY)
    assert result.config["env"] == "Corridor" and result.config["backend"] == "gymnasium"
    returns = result.metrics["average_return"]
    assert np.isfinite(returns[-1]) and 3 <= returns[-1] <= 5  # episodes of 3 to 5 steps


def test_cartpole_v1_learns():
    result = train("gymnasium/CartPole-v1", "ppo", seed=0, total_steps=20480)
    first, last = result.metrics["average_return"][[0, -1]]
    assert last > 3 * first, (first, last)


def test_a_seed_repeats_alone_and_in_a_sweep_with_continuous_actions():
    alone = train("gymnasium/Pendulum-v1", "ppo", seed=1, total_steps=512, **TINY)
    again = train("gymnasium/Pendulum-v1", "ppo", seed=1, total_steps=512, **TINY)
    for name in alone.metrics:
        np.testing.assert_array_equal(alone.metrics[name], again.metrics[name], err_msg=name)
    both = sweep("gymnasium/Pendulum-v1", {"variant": "ppo"}, seeds=[0, 1], total_steps=512, **TINY)
    np.testing.assert_allclose(
        both.metrics["average_return"][1, :2], alone.metrics["average_return"][:2], rtol=1e-4
    )


def test_keyword_arguments_reach_gymnasium_make():
    short = gymnasium_environment("CartPole-v1", max_episode_steps=10)
    assert short is gymnasium_environment("CartPole-v1", max_episode_steps=10)
    assert short.name == "gymnasium/CartPole-v1(max_episode_steps=10)"
    steps = rollout(short, 0, 30)
    ends = np.flatnonzero(steps.terminated | steps.truncated) + 1
    assert ends.size and np.diff(np.concatenate([[0], ends])).max() <= 10


def test_environments_that_fail_are_named_with_what_they_did():
    with pytest.raises(Exception, match="Broken: step raised RuntimeError: the simulator crashed"):
        train(Broken, "ppo", total_steps=256, **TINY)
    with pytest.raises(Exception, match="NaNs: step returned a non-finite observation"):
        train(NaNs, "ppo", total_steps=256, **TINY)


def test_unsupported_spaces_and_unknown_ids_are_refused_naming_what_to_do():
    class Dictionary(Corridor):
        observation_space = gymnasium.spaces.Dict({"x": gymnasium.spaces.Box(0, 1, (2,))})

    class Several(Corridor):
        action_space = gymnasium.spaces.MultiDiscrete([2, 3])

    with pytest.raises(ValueError, match=r"1-D Box, got Dict.*FlattenObservation"):
        as_environment(Dictionary)
    with pytest.raises(ValueError, match="Discrete or a 1-D Box, got MultiDiscrete"):
        as_environment(Several)
    with pytest.raises(ValueError, match="no environment 'NoSuchEnv-v0' registered"):
        make_env("gymnasium/NoSuchEnv-v0")


@pytest.mark.slow
def test_gymnasium_s_mujoco_hopper_trains():
    result = train("gymnasium/Hopper-v5", "fppo-qp", total_steps=8192)
    assert result.config["backend"] == "gymnasium"
    assert np.isfinite(result.metrics["average_return"][-1])
    assert result.policy(np.zeros(11, np.float32)).shape == (3,)
