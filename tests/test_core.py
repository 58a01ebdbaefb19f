"""The environment interface (fppo_jax.envs.core): reset states drawn up front, the choice per
environment between a reset and a step, and an environment that breaks the interface named,
with what was expected and found, before anything compiles."""

import dataclasses

import jax
import jax.numpy as jnp
import pytest

from fppo_jax import TrainConfig, make_train
from fppo_jax.envs import check_environment, draw_resets, make_env, where_done


def test_draw_resets_gives_distinct_fresh_states():
    env = make_env("cartpole")
    states, obs = draw_resets(env, jax.random.key(0), (3, 5))
    assert obs.shape == (3, 5, 4) and states.time.shape == (3, 5)
    assert bool(jnp.all(jnp.abs(obs) <= 0.05)) and bool(jnp.all(states.time == 0))
    assert len({tuple(o) for o in obs.reshape(-1, 4).tolist()}) == 15


def test_where_done_selects_per_environment():
    done = jnp.array([True, False])
    reset = {"a": jnp.zeros((2, 3)), "b": jnp.zeros(2)}
    stepped = {"a": jnp.ones((2, 3)), "b": jnp.ones(2)}
    chosen = where_done(done, reset, stepped)
    assert chosen["a"].tolist() == [[0, 0, 0], [1, 1, 1]]
    assert chosen["b"].tolist() == [0, 1]


@dataclasses.dataclass(frozen=True)
class Broken:
    """CartPole with one part of its contract broken."""

    how: str
    inner: object = dataclasses.field(default_factory=lambda: make_env("cartpole"))

    @property
    def observation_size(self):
        return 5 if self.how == "size" else 4

    @property
    def action_space(self):
        return self.inner.action_space

    def reset(self, key):
        return self.inner.reset(key)

    def step(self, key, state, action):
        state, out = self.inner.step(key, state, action)
        if self.how == "tuple":
            return state, tuple(out)
        if self.how == "reward":
            return state, out._replace(reward=jnp.stack([out.reward, out.reward]))
        if self.how == "terminated":
            return state, out._replace(terminated=out.terminated.astype(jnp.float32))
        return state, out


@pytest.mark.parametrize(
    "how, message",
    [
        (
            "size",
            r"reset's observation: expected shape \(5,\) \(the environment's observation_size\) "
            r"and a float dtype; found shape \(4,\)",
        ),
        ("tuple", r"step must return \(next state, Step\(obs, reward, terminated, truncated\)\)"),
        ("reward", r"step's reward: expected shape \(\) and a numeric dtype; found shape \(2,\)"),
        ("terminated", r"step's terminated: expected shape \(\) and a bool dtype; found .*float32"),
    ],
)
def test_a_broken_environment_is_named_before_compiling(how, message):
    config = TrainConfig(total_steps=128, num_envs=4, num_steps=32, num_minibatches=4)
    with pytest.raises(TypeError, match=message):
        make_train(config, Broken(how))
    check_environment(Broken("none"))  # the unbroken wrapper passes
