"""Gymnasium environments of the tests' own, and their rollouts, for tests/test_gymnasium.py and
tests/test_gymnasium_api.py."""

import gymnasium
import jax
import jax.numpy as jnp
import numpy as np

from fppo_jax.envs import Step, draw_resets


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


def rollouts(env, actions, steps: int) -> tuple[jax.Array, Step]:
    """`steps` steps of `len(actions)` environments reset together, the i-th always taking
    ``actions[i]``: (their first observations, the steps' outcomes [step, environment])."""
    actions = jnp.asarray(actions)
    count = len(actions)

    def step(state, key):
        return jax.vmap(env.step)(jax.random.split(key, count), state, actions)

    state, first = draw_resets(env, jax.random.key(0), (count,))
    keys = jax.random.split(jax.random.key(1), steps)
    return first, jax.jit(lambda s: jax.lax.scan(step, s, keys))(state)[1]
