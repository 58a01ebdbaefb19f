"""The task registry: named tasks with the paper's settings, and what turns a name or a
foreign environment into an :class:`~fppo_jax.envs.core.Environment`.

Adapters are imported inside the factories, so that a task pays only for its own library.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

from fppo_jax.envs.core import Environment


def _mujoco(name: str, episode_length: int) -> Callable[[], Environment]:
    def make() -> Environment:
        from fppo_jax.envs import mjx

        if name == "swimmer":
            return mjx.Swimmer(episode_length=episode_length)
        return mjx.brax_environment(name, episode_length)

    return make


def _gymnax(env_id: str, max_steps: int) -> Callable[[], Environment]:
    def make() -> Environment:
        from fppo_jax.envs.gymnax import gymnax_environment

        return gymnax_environment(env_id, max_steps)

    return make


@dataclasses.dataclass(frozen=True)
class Task:
    """A named task with the paper's step budget for it (SPEC §1; SPEC §2)."""

    name: str
    make: Callable[[], Environment]
    total_steps: int
    description: str


TASKS: dict[str, Task] = {
    task.name: task
    for task in (
        Task(
            "cartpole",
            _gymnax("CartPole-v1", 200),
            100_000,
            "CartPole-v0: 200-step episodes, discrete",
        ),
        Task(
            "acrobot",
            _gymnax("Acrobot-v1", 500),
            100_000,
            "Acrobot-v1: 500-step episodes, discrete",
        ),
        Task(
            "mountaincar",
            _gymnax("MountainCar-v0", 200),
            100_000,
            "MountainCar-v0: 200-step episodes, sparse reward, discrete",
        ),
        *(
            Task(name, _mujoco(name, limit), 1_000_000, f"{title} on MJX: {text}")
            for name, title, limit, text in (
                ("hopper", "Hopper", 1000, "1000-step episodes, 3 actions"),
                ("walker2d", "Walker2d", 1000, "1000-step episodes, 6 actions"),
                ("halfcheetah", "HalfCheetah", 1000, "1000-step episodes, 6 actions"),
                ("ant", "Ant", 1000, "1000-step episodes, 8 actions"),
                ("reacher", "Reacher", 50, "50-step episodes, 2 actions"),
                ("swimmer", "Swimmer", 1000, "1000-step episodes, 2 actions"),
            )
        ),
    )
}

MUJOCO_TASKS: tuple[str, ...] = ("hopper", "walker2d", "halfcheetah", "ant", "reacher", "swimmer")


def make_env(name: str) -> Environment:
    """The registered task `name` (see :data:`TASKS`)."""
    if name not in TASKS:
        raise ValueError(f"unknown environment {name!r}; registered: {', '.join(TASKS)}")
    return TASKS[name].make()


def as_environment(env: str | Environment | Any) -> Environment:
    """A registered name, a gymnax environment (default parameters), a Brax ``Env``
    (1000-step episodes) or an :class:`Environment`."""
    from fppo_jax.envs.gymnax import GymnaxEnvironment, is_gymnax_env

    if isinstance(env, str):
        return make_env(env)
    if is_gymnax_env(env):
        return GymnaxEnvironment(env, env.default_params)
    from fppo_jax.envs import mjx

    if mjx.is_brax_env(env):
        return mjx.BraxEnvironment(env)
    if isinstance(env, Environment):
        return env
    raise TypeError(
        f"expected a registered environment name ({', '.join(TASKS)}), a gymnax or Brax "
        "environment, or an object with observation_size, action_space, reset and step; got "
        + type(env).__name__
    )
