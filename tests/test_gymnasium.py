"""fppo_jax/envs/gymnasium.py: Gymnasium environments, registered and a user's own, one
``gymnasium.Env`` each or in vector environments, stepped on the host from inside the compiled
program."""

import functools
import importlib.util

import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import TINY
from gymnasium_envs import Corridor, rollout, rollouts

import fppo_jax.run.driver
import fppo_jax.run.memory
from fppo_jax import make_env, sweep, train
from fppo_jax.envs import Discrete, Step, as_environment, draw_resets
from fppo_jax.envs.gymnasium import gymnasium_environment


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


def test_a_missing_extra_and_a_module_s_own_id_are_named():
    if importlib.util.find_spec("Box2D") is None:
        with pytest.raises(
            ImportError, match=r"gymnasium/CarRacing-v3 cannot be made: Box2D .*box2d"
        ):
            make_env("gymnasium/CarRacing-v3")
    env = make_env("gymnasium/gymnasium.envs.classic_control.cartpole:CartPole-v1")
    assert env.name == "gymnasium/gymnasium.envs.classic_control.cartpole:CartPole-v1"
    assert env.observation_size == 4
    with pytest.raises(ImportError, match=r"cannot import 'no_such_package.envs', which should"):
        make_env("gymnasium/no_such_package.envs:Mine-v0")
    with pytest.raises(ValueError, match=r"no environment 'Mine-v0' registered once 'json' is"):
        make_env("gymnasium/json:Mine-v0")


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
    with pytest.raises(ValueError, match=r"'CartPol-v1' registered; did you mean CartPole-v1 or"):
        make_env("gymnasium/CartPol-v1")


@pytest.mark.parametrize("mode", list(gymnasium.vector.AutoresetMode), ids=lambda m: m.name)
def test_a_vector_environment_s_episodes_end_where_they_say_whatever_its_autoreset_mode(mode):
    vector = gymnasium.vector.SyncVectorEnv([Corridor, Corridor], autoreset_mode=mode)
    first, steps = rollouts(as_environment(vector), [1, 0], 12)
    np.testing.assert_array_equal(np.flatnonzero(steps.terminated[:, 0]) + 1, [3, 6, 9, 12])
    np.testing.assert_array_equal(np.flatnonzero(steps.truncated[:, 1]) + 1, [5, 10])
    assert not steps.truncated[:, 0].any() and not steps.terminated[:, 1].any()
    np.testing.assert_array_equal(steps.obs[[2, 4], [0, 1]], [[3, 3], [0, 5]])  # final, kept
    np.testing.assert_array_equal(steps.next_obs[[2, 4], [0, 1]], [[0, 0], [0, 0]])  # restarted
    np.testing.assert_array_equal(steps.reward, 1)  # no action ignored at a reset
    one_by_one = rollouts(as_environment(Corridor), [1, 0], 12)
    np.testing.assert_array_equal(first, one_by_one[0])
    for name, got, alone in zip(Step._fields, steps, one_by_one[1], strict=True):
        np.testing.assert_array_equal(got, alone, err_msg=name)


@pytest.mark.parametrize(
    "env_id, actions", [("CartPole-v1", [1, 0]), ("Pendulum-v1", [[3.0], [-1.0]])]
)
def test_a_vector_environment_s_sub_environments_are_seeded_as_environments_of_their_own(
    env_id, actions
):
    def vector():
        return gymnasium.make_vec(env_id, 2, vectorization_mode="sync", max_episode_steps=7)

    first, steps = rollouts(gymnasium_environment(vector), actions, 30)
    one_by_one = rollouts(gymnasium_environment(env_id, max_episode_steps=7), actions, 30)
    np.testing.assert_array_equal(first, one_by_one[0])
    for name, got, alone in zip(Step._fields, steps, one_by_one[1], strict=True):
        np.testing.assert_array_equal(got, alone, err_msg=name)
    assert (steps.terminated | steps.truncated).sum() >= 4
    # A sweep's two runs of four environments: a vector environment for each two of each run,
    # each run's the same as alone.
    keys = jax.random.split(jax.random.key(2), (2, 4))
    swept = jax.vmap(jax.vmap(gymnasium_environment(vector).reset))(keys)[1]
    np.testing.assert_array_equal(
        swept[1], jax.vmap(gymnasium_environment(vector).reset)(keys[1])[1]
    )
    assert len(np.unique(swept.reshape(8, -1), axis=0)) == 8


def test_a_vector_environment_trains_and_those_that_cannot_restart_one_alone_are_refused():
    with pytest.raises(ValueError, match=r'outside the mask.*vectorization_mode="sync"'):
        train(gymnasium.make_vec("CartPole-v1", 4), "ppo", total_steps=512, **TINY)
    cartpole = functools.partial(gymnasium.make, "CartPole-v1")
    unshared = gymnasium.vector.AsyncVectorEnv(
        [cartpole, cartpole], shared_memory=False, context="spawn"
    )
    with pytest.raises(ValueError, match=r"without shared memory.*shared_memory=True"):
        as_environment(unshared)
    unshared.close()
    vector = gymnasium.make_vec("CartPole-v1", 4, vectorization_mode="sync")
    result = train(vector, "ppo", total_steps=512, **TINY)
    assert result.config["env"] == "SyncVectorEnv(CartPole-v1, num_envs=4)"
    assert result.config["backend"] == "gymnasium"
    returns = result.metrics["average_return"]
    assert np.isfinite(returns).all() and 8 <= returns[-1] <= 100


def test_a_run_takes_vector_environments_whole_and_an_instance_serves_one_batch_at_a_time():
    def pair():
        return gymnasium.vector.SyncVectorEnv([Corridor, Corridor])

    with pytest.raises(Exception, match=r"2 sub-environments, which cannot serve 3 .*num_envs=2"):
        draw_resets(gymnasium_environment(pair), jax.random.key(0), (3,))
    draw_resets(gymnasium_environment(pair), jax.random.key(0), (3, 4))  # 3 runs of 4: 6 pairs
    instance = as_environment(pair())
    with pytest.raises(Exception, match=r"one run of num_envs=2; .* 3 run\(s\) .*pass a function"):
        draw_resets(instance, jax.random.key(0), (3, 2))
    training, _ = draw_resets(instance, jax.random.key(0), (2,))
    draw_resets(instance, jax.random.key(1), (2,))  # an evaluation's, say: it takes the instance
    with pytest.raises(Exception, match="reset since for another batch"):
        jax.vmap(instance.step)(jax.random.split(jax.random.key(2), 2), training, jnp.ones(2, int))


def test_environments_a_vector_environment_cannot_serve_are_refused_before_compiling(
    monkeypatch,
):
    monkeypatch.setattr(fppo_jax.run.driver, "compile_program", lambda *_: pytest.fail("compiled"))
    pairs = gymnasium_environment(lambda: gymnasium.vector.SyncVectorEnv([Corridor, Corridor]))
    with pytest.raises(ValueError, match="2 sub-environments, which cannot serve 3 "):
        train(pairs, "ppo", total_steps=512, **{**TINY, "num_envs": 3})
    with pytest.raises(ValueError, match="2 sub-environments, which cannot serve 5 "):
        train(pairs, "ppo", total_steps=512, **TINY, eval_every=1, eval_episodes=5)
    instance = gymnasium.vector.SyncVectorEnv([Corridor] * 4)
    with pytest.raises(ValueError, match=r"one vector environment.*a sweep's 2 runs: pass a func"):
        sweep(instance, {"variant": "ppo"}, seeds=[0, 1], total_steps=512, **TINY)
    with pytest.raises(ValueError, match=r"cannot serve an evaluation during training"):
        train(instance, "ppo", total_steps=512, **TINY, eval_every=1, eval_episodes=4)


def test_environments_that_would_not_fit_in_host_memory_are_refused_before_compiling(
    monkeypatch, capsys
):
    env = as_environment(Corridor)
    assert 1000 < env.host_bytes < 100_000  # a Python object of a few KiB
    monkeypatch.setattr(fppo_jax.run.driver, "compile_program", lambda *_: pytest.fail("compiled"))
    monkeypatch.setattr(fppo_jax.run.memory, "host_available_bytes", lambda: 2 * 7 * env.host_bytes)
    with pytest.raises(MemoryError, match=r"Corridor: 1 run\(s\) of 8 environments, each a Py"):
        train(Corridor, "ppo", total_steps=512, **{**TINY, "num_envs": 8})
    with pytest.raises(MemoryError, match=r"2 run\(s\) of 4 .*lower num_envs, or the runs per"):
        sweep(Corridor, {"variant": "ppo"}, seeds=2, total_steps=512, chunk=2, **TINY)
    # Without a chunk given, a sweep takes as many runs per call as fit: one here.
    monkeypatch.setattr(fppo_jax.run.memory, "host_available_bytes", lambda: 2 * 5 * env.host_bytes)
    monkeypatch.setattr(fppo_jax.run.driver, "HOST_BYTES_SHOWN", 4 * env.host_bytes)
    with pytest.raises(pytest.fail.Exception, match="compiled"):
        sweep(Corridor, {"variant": "ppo"}, seeds=2, total_steps=512, progress=True, **TINY)
    shown = capsys.readouterr().err
    assert "Corridor: 4 environments, made on the host at the first reset, take about" in shown


@pytest.mark.slow
def test_gymnasium_s_mujoco_hopper_trains():
    result = train("gymnasium/Hopper-v5", "fppo-qp", total_steps=8192)
    assert result.config["backend"] == "gymnasium"
    assert np.isfinite(result.metrics["average_return"][-1])
    assert result.policy(np.zeros(11, np.float32)).shape == (3,)
