"""The rollout (fppo_jax.core.rollout): episodes that end where the environment says, each
followed by a reset, fresh at every step or cycled through a pool."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fppo_jax import TrainConfig, hyperparameters, make_train, train
from fppo_jax.envs import Discrete, Step


@dataclasses.dataclass(frozen=True)
class Countdown:
    """Reward 1 per step; the episode ends after `length` steps (terminated or truncated)."""

    length: int
    truncate: bool
    observation_size = 1
    action_space = Discrete(2)

    def reset(self, key):
        return jnp.asarray(0), jnp.zeros(1)

    def step(self, key, t, action):
        t = t + 1
        ended = t >= self.length
        obs = jnp.asarray([t / self.length], jnp.float32)
        return t, Step(obs, jnp.float32(1.0), ended & (not self.truncate), ended & self.truncate)


@pytest.mark.parametrize("truncate", [False, True])
def test_auto_reset_and_episode_returns(tiny, truncate):
    # 4 envs × 32 steps per update: each env finishes an episode every 3 steps.
    m = train(Countdown(3, truncate), "ppo", total_steps=256, **tiny).metrics
    assert m["average_return"].tolist() == [3.0, 3.0]


@dataclasses.dataclass(frozen=True)
class RandomStart:
    """Episodes of 3 steps; the observation is the episode's random starting value."""

    observation_size = 1
    action_space = Discrete(2)

    def reset(self, key):
        start = jax.random.uniform(key, (1,))
        return (jnp.asarray(0), start), start

    def step(self, key, state, action):
        t, start = state
        ended = t + 1 >= 3
        return (t + 1, start), Step(start, jnp.float32(1.0), ended, jnp.asarray(False))


@pytest.mark.parametrize("pool", [None, 2])
def test_reset_pool_is_cycled_and_default_resets_are_fresh(pool):
    config = TrainConfig(
        total_steps=48, num_envs=4, num_steps=12, num_minibatches=1, resets_per_rollout=pool
    )
    trainer = make_train(config, RandomStart())
    hp = hyperparameters("ppo")
    state = trainer.init(jax.random.key(0), hp)
    traj, _ = trainer._rollout(state, hp, jax.random.key(1))
    # Each environment ends episodes at steps 2, 5, 8 and 11; the next ones start at 3, 6, 9.
    starts = np.asarray(traj.raw_obs[jnp.array([3, 6, 9]), :, 0])
    if pool is None:
        assert len(np.unique(starts)) == starts.size
    else:
        np.testing.assert_array_equal(starts[0], starts[2])
        assert np.all(starts[0] != starts[1])
    with pytest.raises(ValueError, match="resets_per_rollout must be a positive integer"):
        TrainConfig(resets_per_rollout=0)
