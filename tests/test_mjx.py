"""The MuJoCo tasks on MJX. Compiling one task's step takes 5–20 s on a CPU, so each test
compiles one small program, and programs are shared through module-scoped fixtures."""

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

import fppo_jax
from fppo_jax import TrainConfig, hyperparameters, make_env, make_train, sweep
from fppo_jax.core.gae import gae
from fppo_jax.core.resolution import TABLE2
from fppo_jax.core.variants import VARIANTS
from fppo_jax.envs import MUJOCO_TASKS, TASKS, Box, as_environment
from fppo_jax.envs.mjx import BraxEnvironment, Swimmer, swimmer_model
from fppo_jax.export.render import RenderingUnavailable, episode_positions

SHAPES = {  # observation size, action size
    "hopper": (11, 3),
    "walker2d": (17, 6),
    "halfcheetah": (17, 6),
    "ant": (27, 8),
    "reacher": (11, 2),
    "swimmer": (8, 2),
}


# Hopper (Brax, terminating), Reacher (Brax, 50 steps) and Swimmer (MJX itself) in the default
# run; the other Brax tasks, which the same adapter steps, with -m slow.
@pytest.mark.parametrize(
    "name",
    [
        name if name in ("reacher", "swimmer") else pytest.param(name, marks=pytest.mark.slow)
        for name in MUJOCO_TASKS
    ],
)
def test_task_resets_and_steps(name):
    env = make_env(name, "mjx")
    obs_size, action_size = SHAPES[name]
    assert env.observation_size == obs_size
    assert env.action_space == Box((-1.0,) * action_size, (1.0,) * action_size)

    @jax.jit
    def run(key):
        reset_key, action_key = jax.random.split(key)
        state, obs = jax.vmap(env.reset)(jax.random.split(reset_key, 2))
        actions = jax.random.uniform(action_key, (3, 2, action_size), minval=-1, maxval=1)

        def step(state, action):
            state, out = jax.vmap(env.step)(jax.random.split(key, 2), state, action)
            return state, out

        return obs, jax.lax.scan(step, state, actions)[1]

    obs, out = run(jax.random.key(0))
    assert obs.shape == (2, obs_size) and out.obs.shape == (3, 2, obs_size)
    assert obs.dtype == out.obs.dtype == out.reward.dtype == jnp.float32
    assert np.isfinite(obs).all() and np.isfinite(out.obs).all() and np.isfinite(out.reward).all()
    assert not np.array_equal(obs[0], obs[1])  # each reset draws its own noise
    assert not np.array_equal(out.obs[0], out.obs[2])  # the state moves
    assert np.all(out.reward != 0)
    assert not out.terminated.any() and not out.truncated.any()


def test_brax_env_object_is_accepted():
    from brax import envs

    env = as_environment(envs.get_environment("reacher", backend="mjx"))
    assert isinstance(env, BraxEnvironment) and env.episode_length == 1000
    assert env.observation_size == 11 and env.action_space.size == 2


def test_any_brax_environment_by_name():
    env = make_env("brax/inverted_pendulum")
    assert isinstance(env, BraxEnvironment) and env.episode_length == 1000
    assert env.observation_size == 4 and env.action_space == Box((-3.0,), (3.0,))
    with pytest.raises(ValueError, match=r"^Brax has no environment 'nope'; it offers: ant, "):
        make_env("brax/nope")


def test_registered_tasks_have_gym_limits_budgets_and_table_2_settings():
    assert make_env("reacher", "mjx").episode_length == 50
    assert make_env("swimmer", "mjx").episode_length == 1000
    assert {name: (TABLE2[name]["alpha"], TABLE2[name]["k"]) for name in MUJOCO_TASKS} == {
        "hopper": (1.3, 0.2),
        "walker2d": (1.3, 0.1),
        "halfcheetah": (1.3, 0.4),
        "ant": (1.3, 0.4),
        "reacher": (1.1, 0.4),
        "swimmer": (1.1, 0.1),
    }
    assert all(TASKS[name].total_steps == 1_000_000 for name in MUJOCO_TASKS)


@pytest.fixture(scope="module")
def swimmer():
    return Swimmer()


@pytest.fixture(scope="module")
def swimmer_step(swimmer):
    return jax.jit(swimmer.step)


def _native_swimmer(model, qpos, qvel, actions, frame_skip):
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:] = qpos, qvel
    rewards = []
    for action in actions:
        before = data.qpos[0]
        data.ctrl[:] = action
        for _ in range(frame_skip):
            mujoco.mj_step(model, data)
        velocity = (data.qpos[0] - before) / (model.opt.timestep * frame_skip)
        rewards.append(velocity - 1e-4 * np.sum(np.square(action)))
    return data.qpos.copy(), np.array(rewards)


def test_swimmer_on_mjx_matches_native_mujoco(swimmer, swimmer_step):
    state, _ = swimmer.reset(jax.random.key(3))
    qpos, qvel = np.asarray(state.inner.qpos), np.asarray(state.inner.qvel)
    actions = np.random.default_rng(0).uniform(-1, 1, (60, 2)).astype(np.float32)
    rewards = []
    for action in actions:
        state, out = swimmer_step(jax.random.key(0), state, jnp.asarray(action))
        rewards.append(float(out.reward))
    native_qpos, native_rewards = _native_swimmer(swimmer.mj_model, qpos, qvel, actions, 4)
    np.testing.assert_allclose(np.asarray(state.inner.qpos), native_qpos, atol=1e-3)
    np.testing.assert_allclose(rewards, native_rewards, atol=2e-3)
    # The fluid is what moves a swimmer: without it the trajectory is far from MJX's.
    dry = swimmer_model()
    dry.opt.density, dry.opt.viscosity = 0.0, 0.0
    dry_qpos, _ = _native_swimmer(dry, qpos, qvel, actions, 4)
    assert np.abs(dry_qpos - native_qpos).max() > 0.1


def test_truncation_is_bootstrapped_on_a_continuous_task():
    env = Swimmer(episode_length=5)
    config = TrainConfig(total_steps=24, num_envs=2, num_steps=12, num_minibatches=1)
    trainer = make_train(config, env)
    hp = hyperparameters("ppo")
    state = jax.jit(trainer.init)(jax.random.key(0), hp)  # one program, not a hundred op by op
    traj, _ = jax.jit(trainer._rollout)(state, hp, jax.random.key(1))
    truncated = np.asarray(traj.truncated)
    assert np.flatnonzero(truncated[:, 0]).tolist() == [4, 9] and truncated[:, 1].sum() == 2
    assert not np.asarray(traj.terminated).any()
    # Mid-episode the step's observation is the next one acted on; at truncation it is the
    # last state's, not the reset's, and it is what the value bootstraps from.
    final, raw = np.asarray(traj.final_obs), np.asarray(traj.raw_obs)
    np.testing.assert_array_equal(final[:3], raw[1:4])
    assert not np.allclose(final[4], raw[5])
    values = trainer.networks.values(state.params, trainer.network_input(state.obs_stats, raw))
    next_values = trainer.networks.values(
        state.params, trainer.network_input(state.obs_stats, final)
    )
    _, targets = gae(traj.reward, values, next_values, traj.terminated, traj.truncated, 0.99, 0.95)
    np.testing.assert_allclose(
        targets[4], traj.reward[4] + 0.99 * next_values[4], rtol=1e-5, atol=1e-6
    )
    assert np.all(np.abs(next_values[4]) > 1e-6)


@pytest.mark.slow  # a minute on a CPU; every variant trains on Pendulum in the default run
def test_every_variant_trains_on_a_mujoco_task():
    result = sweep(
        "reacher",
        {"variant": list(VARIANTS)},
        backend="mjx",
        seeds=1,
        total_steps=256,
        num_envs=4,
        num_steps=32,
        num_minibatches=2,
        num_epochs=2,
    )
    m = result.metrics
    assert m["env_steps"].shape == (len(VARIANTS), 2)
    assert not result.diverged.any()
    for name in ("policy_loss", "value_loss", "entropy", "approx_kl"):
        assert np.isfinite(m[name]).all(), name
    # 50-step episodes: the first ends in the second update; rewards are negative distances.
    assert np.isnan(m["average_return"][:, 0]).all() and (m["average_return"][:, 1] < 0).all()
    assert (m["approx_kl"][:, -1] > 0).all()  # every variant moved its policy


# Training on MJX to render takes about a minute on a CPU: with -m slow (clipping is also
# tests/test_policy.py's, and the video writer tests/test_render.py's).
@pytest.mark.slow
def test_policy_actions_are_clipped_and_an_episode_renders(tmp_path, swimmer):
    result = fppo_jax.train(
        swimmer, "ppo", total_steps=64, num_envs=2, num_steps=32, num_minibatches=1, num_epochs=1
    )
    actions = np.asarray(result.policy(jnp.zeros((256, 8)), jax.random.key(0)))
    assert actions.shape == (256, 2)
    assert np.abs(actions).max() == 1.0  # unit-variance samples reach past the bounds
    qpos = episode_positions(swimmer, result.policy, jax.random.key(0), max_steps=6)
    assert qpos.shape == (7, swimmer.mj_model.nq) and np.isfinite(qpos).all()
    try:
        strip = result.render(tmp_path / "swimmer.png", max_steps=6)
    except RenderingUnavailable as error:
        assert "MUJOCO_GL" in str(error)
        pytest.skip(f"no OpenGL context on this machine: {error}")
    from PIL import Image

    image = np.asarray(Image.open(strip))
    assert image.shape == (240, 320 * 7, 3) and image.std() > 0
    with pytest.raises(ValueError, match=r"render to a \.png"):
        result.render(tmp_path / "swimmer.webm")
