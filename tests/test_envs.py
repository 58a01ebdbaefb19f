import dataclasses
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fppo_jax import TrainConfig, hyperparameters, make_train
from fppo_jax.envs import (
    NAMESPACES,
    TASKS,
    Box,
    Discrete,
    as_environment,
    check_environment,
    draw_resets,
    lookup,
    make_env,
    where_done,
)
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


def test_mountaincar_random_policy_is_truncated_at_200():
    steps, out = run_until_done(make_env("mountaincar"), lambda o: jnp.int32(1))
    assert steps == 200 and bool(out.truncated) and not bool(out.terminated)


def test_cartpole_terminates_when_the_pole_falls():
    steps, out = run_until_done(make_env("cartpole"), lambda o: jnp.int32(1))
    assert steps < 50 and bool(out.terminated)


@pytest.mark.parametrize(
    "name, obs_size, actions", [("cartpole", 4, 2), ("acrobot", 6, 3), ("mountaincar", 2, 3)]
)
def test_registered_tasks(name, obs_size, actions):
    env = make_env(name)
    assert env.observation_size == obs_size
    assert env.action_space == Discrete(actions)
    state, _ = env.reset(jax.random.key(1))
    state, out = env.step(jax.random.key(2), state, jnp.int32(0))
    assert out.obs.shape == (obs_size,) and out.obs.dtype == jnp.float32
    assert TASKS[name].total_steps == 100_000


def test_acrobot_episode_limit_is_500():
    assert make_env("acrobot").params.max_steps_in_episode == 500


REGISTERED = "cartpole, acrobot, mountaincar, hopper, walker2d, halfcheetah, ant, reacher, swimmer"


@pytest.mark.parametrize(
    "name, suggested",
    [
        ("cartpol", ""),
        ("gym/CartPole-v1", ""),
        ("gymnax/", ""),
        ("Pendulum-v1", "; did you mean gymnax/Pendulum-v1 or gymnasium/Pendulum-v1?"),
        ("Hopper-v4", "; did you mean gymnasium/Hopper-v4?"),
    ],
)
def test_an_unknown_name_lists_the_registered_tasks_and_the_namespaces(name, suggested):
    message = (
        f"unknown environment {name!r}; registered: {REGISTERED}; "
        "namespaced: gymnax/<id>, brax/<id>, playground/<id>, native/<id>, gymnasium/<id>"
        + suggested
    )
    with pytest.raises(ValueError) as error:
        lookup(name)
    assert str(error.value) == message
    with pytest.raises(ValueError, match=r"^unknown environment"):
        make_env(name)


@pytest.mark.parametrize("name", [None, 3])
def test_make_env_takes_a_name(name):
    with pytest.raises(
        ValueError, match=f"make_env takes a task's name, such as 'cartpole'; got {name}"
    ):
        make_env(name)


def test_lookup_gives_registered_and_namespaced_tasks():
    assert lookup("hopper") is TASKS["hopper"]
    task = lookup("brax/humanoid")
    assert task.name == "brax/humanoid" and task.total_steps == 100_000
    assert task.description == "humanoid from the brax namespace"
    assert set(NAMESPACES) == {"gymnax", "brax", "playground", "native", "gymnasium"}
    with pytest.raises(TypeError, match="expected a registered environment name"):
        as_environment(42)


def test_neither_importing_nor_looking_up_loads_an_environment_library():
    code = (
        "import sys, fppo_jax; from fppo_jax.envs import lookup; "
        "[lookup(n) for n in ('cartpole', 'gymnax/Pendulum-v1', 'brax/ant', 'playground/X')]; "
        "print(sorted({m.split('.')[0] for m in sys.modules} "
        "& {'gymnax', 'brax', 'mujoco', 'mujoco_playground'}))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


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
