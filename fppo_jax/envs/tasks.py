"""The task registry: named tasks with the paper's settings, names by namespace
(``gymnax/<id>``, ``brax/<name>``, ``playground/<Name>``), and what turns a name or a foreign
environment into an :class:`~fppo_jax.envs.core.Environment`.

Adapters are imported inside the factories, so that a task pays only for its own library.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

from fppo_jax.envs.core import Environment


def _gymnax(env_id: str, max_steps: int | None = None) -> Callable[[], Environment]:
    def make() -> Environment:
        from fppo_jax.envs.gymnax import gymnax_environment

        return gymnax_environment(env_id, max_steps)

    return make


def _brax(name: str, episode_length: int = 1000) -> Callable[[], Environment]:
    def make() -> Environment:
        from fppo_jax.envs.mjx import brax_environment

        return brax_environment(name, episode_length)

    return make


def _swimmer(episode_length: int) -> Callable[[], Environment]:
    def make() -> Environment:
        from fppo_jax.envs.mjx import Swimmer

        return Swimmer(episode_length=episode_length)

    return make


def _playground(name: str) -> Callable[[], Environment]:
    def make() -> Environment:
        from fppo_jax.envs.playground import playground_environment

        return playground_environment(name)

    return make


@dataclasses.dataclass(frozen=True)
class Task:
    """A named task and its default step budget: the paper's, for a registered task (SPEC §1;
    SPEC §2)."""

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
            Task(
                name,
                _swimmer(limit) if name == "swimmer" else _brax(name, limit),
                1_000_000,
                f"{title} on MJX: {text}",
            )
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


NAMESPACES: dict[str, str] = {
    "gymnax": "any gymnax environment by id, with its default parameters (gymnax/Pendulum-v1)",
    "brax": "any Brax environment on MJX, 1000-step episodes (brax/reacher)",
    "playground": "a MuJoCo Playground environment on MJX, its own episode limit "
    "(playground/CartpoleBalance)",
}
_NAMESPACED_FORMS = ", ".join(f"{namespace}/<id>" for namespace in NAMESPACES)

_FACTORIES: dict[str, Callable[[str], Callable[[], Environment]]] = {
    "gymnax": _gymnax,
    "brax": _brax,
    "playground": _playground,
}


def lookup(name: str) -> Task:
    """The registered task `name`, or the task of a namespaced name such as
    ``gymnax/Pendulum-v1`` (see :data:`NAMESPACES`). Nothing is imported or built, so that
    settings can be checked before anything compiles; an unknown id inside a namespace is
    reported by :func:`make_env`."""
    if name in TASKS:
        return TASKS[name]
    namespace, _, env_id = name.partition("/")
    if namespace in NAMESPACES and env_id:
        description = f"{env_id} from the {namespace} namespace"
        return Task(name, _FACTORIES[namespace](env_id), 100_000, description)
    raise ValueError(
        f"unknown environment {name!r}; registered: {', '.join(TASKS)}; "
        f"namespaced: {_NAMESPACED_FORMS}"
    )


def make_env(name: str) -> Environment:
    """The registered or namespaced task `name` (see :func:`lookup`)."""
    return lookup(name).make()


def as_environment(env: str | Environment | Any) -> Environment:
    """A registered or namespaced name, a gymnax environment (default parameters), a Brax
    ``Env`` (1000-step episodes) or an :class:`Environment`."""
    if isinstance(env, str):
        return make_env(env)
    from fppo_jax.envs.gymnax import GymnaxEnvironment, is_gymnax_env

    if is_gymnax_env(env):
        return GymnaxEnvironment(env, env.default_params)
    from fppo_jax.envs import mjx

    if mjx.is_brax_env(env):
        return mjx.BraxEnvironment(env)
    if isinstance(env, Environment):
        return env
    raise TypeError(
        f"expected a registered environment name ({', '.join(TASKS)}), a namespaced one "
        f"({_NAMESPACED_FORMS}), a gymnax or Brax "
        "environment, or an object with observation_size, action_space, reset and step; got "
        + type(env).__name__
    )
