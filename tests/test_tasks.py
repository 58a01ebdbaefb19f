"""The task registry (fppo_jax.envs.tasks): the registered tasks and their budgets, names looked
up in it and in its namespaces, an unknown one answered with what there is, and nothing loaded
until an environment is made."""

import subprocess
import sys

import jax
import jax.numpy as jnp
import pytest

from fppo_jax.envs import NAMESPACES, TASKS, Discrete, as_environment, lookup, make_env


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
