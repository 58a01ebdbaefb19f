"""Environments and checks shared by the tests."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from fppo_jax.envs import Step, make_env


@dataclasses.dataclass(frozen=True)
class NaNRewardAfter:
    """CartPole whose reward turns NaN after `start` steps of an episode."""

    start: int
    inner: object = dataclasses.field(default_factory=lambda: make_env("cartpole"))
    observation_size = 4

    @property
    def action_space(self):
        return self.inner.action_space

    def reset(self, key):
        return self.inner.reset(key)

    def step(self, key, state, action):
        state, out = self.inner.step(key, state, action)
        reward = jnp.where(state.time >= self.start, jnp.nan, out.reward)
        return state, Step(out.obs, reward, out.terminated, out.truncated)


def assert_bitwise_equal(a, b) -> None:
    """Every leaf of pytrees `a` and `b` equal bit for bit (NaN equal to NaN; PRNG keys by
    their data)."""
    leaves_a, leaves_b = jax.tree.leaves(a), jax.tree.leaves(b)
    assert jax.tree.structure(a) == jax.tree.structure(b)
    for x, y in zip(leaves_a, leaves_b, strict=True):
        if jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key):
            x, y = jax.random.key_data(x), jax.random.key_data(y)
        x, y = np.asarray(x), np.asarray(y)
        assert x.dtype == y.dtype and x.shape == y.shape
        assert x.tobytes() == y.tobytes()
