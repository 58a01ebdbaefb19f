"""MuJoCo Playground on MJX, with its cheapest dm_control suite task (its XML ships with the
package, so it loads offline). Stepping it compiles in 10–20 s on a CPU, training in over a
minute."""

import subprocess
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fppo_jax import TrainConfig, hyperparameters, make_env, make_train
from fppo_jax.envs import Box
from fppo_jax.envs.playground import PlaygroundEnvironment, playground_environment


@pytest.fixture(scope="module")
def cartpole():
    return playground_environment("CartpoleBalance", episode_length=3)


def test_cartpole_resets_steps_and_is_truncated_at_its_limit(cartpole):
    assert make_env("playground/CartpoleBalance").episode_length == 1000
    assert cartpole.observation_size == 5 and cartpole.action_space == Box((-1.0,), (1.0,))

    @jax.jit
    def run(key):
        state, obs = jax.vmap(cartpole.reset)(jax.random.split(key, 2))
        actions = jnp.full((4, 2, 1), 0.5)
        step = lambda state, action: jax.vmap(cartpole.step, (None, 0, 0))(key, state, action)  # noqa: E731
        return obs, jax.lax.scan(step, state, actions)[1]

    obs, out = run(jax.random.key(0))
    assert obs.shape == (2, 5) and out.obs.shape == (4, 2, 5) and out.reward.shape == (4, 2)
    assert obs.dtype == out.obs.dtype == out.reward.dtype == jnp.float32
    assert np.isfinite(out.obs).all() and (out.reward > 0).all()
    assert not np.array_equal(obs[0], obs[1])
    # No reset in between: the trainer resets ended episodes, so the count runs past the limit.
    assert np.asarray(out.truncated).tolist() == [[False] * 2, [False] * 2, [True] * 2, [True] * 2]
    assert not out.terminated.any()


@pytest.mark.slow  # 60–100 s to compile on a CPU
def test_cartpole_trains(cartpole):
    config = TrainConfig(
        total_steps=2 * 64, num_envs=2, num_steps=32, num_minibatches=1, num_epochs=1
    )
    _, metrics = jax.jit(make_train(config, cartpole))(jax.random.key(0), hyperparameters("ppo"))
    for name in ("policy_loss", "value_loss", "entropy", "approx_kl"):
        assert np.isfinite(getattr(metrics, name)).all(), name
    assert np.isfinite(metrics.average_return[-1])  # 3-step episodes have ended


class DictState(NamedTuple):
    obs: dict[str, jax.Array]


class DictObserving:
    """Stands in for a Playground environment whose observation is a dict."""

    def reset(self, key: jax.Array) -> DictState:
        return DictState({"state": jnp.ones(3), "privileged_state": jnp.ones(7)})


def test_a_dict_observation_gives_the_chosen_key():
    env = DictObserving()
    assert PlaygroundEnvironment(env).reset(jax.random.key(0))[1].shape == (3,)
    assert PlaygroundEnvironment(env, obs_key="privileged_state").observation_size == 7
    with pytest.raises(ValueError, match="no 'pixels'; choose obs_key from: state, privileged"):
        PlaygroundEnvironment(env, obs_key="pixels").reset(jax.random.key(0))


def test_unknown_names_and_offline_assets_are_explained(monkeypatch):
    with pytest.raises(ValueError, match="no environment 'Nope'; it offers: AcrobotSwingup, "):
        make_env("playground/Nope")

    def clone_fails(name, config=None, config_overrides=None):
        raise subprocess.CalledProcessError(128, ["git", "clone"])

    monkeypatch.setattr("mujoco_playground.registry.load", clone_fails)
    with pytest.raises(RuntimeError, match=r"fetches its assets .* at run time, which needs net"):
        make_env("playground/Go1JoystickFlatTerrain")
