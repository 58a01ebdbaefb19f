"""The task registry: named tasks with the paper's settings, names by namespace
(``gymnax/<id>``, ``brax/<name>``, ``playground/<Name>``, ``native/<id>``,
``gymnasium/<id>``), the backends that
run them, and what turns a name or a foreign environment into an
:class:`~fppo_jax.envs.core.Environment`.

Adapters are imported inside the factories, so that a task pays only for its own library.
"""

from __future__ import annotations

import collections
import dataclasses
import functools
from collections.abc import Callable
from typing import Any

import jax

from fppo_jax.envs.core import Environment
from fppo_jax.errors import InvalidInput, suggested


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


def _gymnasium(env_id: str) -> Callable[[], Environment]:
    def make() -> Environment:
        from fppo_jax.envs.gymnasium import gymnasium_environment

        return gymnasium_environment(env_id)

    return make


def _native(task_id: str) -> Callable[[], Environment]:
    def make() -> Environment:
        from fppo_jax.envs.native import NativeEnvironment

        return NativeEnvironment.of(task_id)

    return make


@dataclasses.dataclass(frozen=True)
class Task:
    """A named task and its default step budget: the paper's, for a registered task.
    `backend` names what runs `make`'s environment; `native`, if given, is the
    envpool id of the same task in native MuJoCo (gym's own version of it)."""

    name: str
    make: Callable[[], Environment]
    total_steps: int
    description: str
    backend: str
    native: str | None = None

    @property
    def backends(self) -> tuple[str, ...]:
        return (self.backend, "native") if self.native else (self.backend,)


TASKS: dict[str, Task] = {
    task.name: task
    for task in (
        Task(
            "cartpole",
            _gymnax("CartPole-v1", 200),
            100_000,
            "CartPole-v0: 200-step episodes, discrete",
            "gymnax",
        ),
        Task(
            "acrobot",
            _gymnax("Acrobot-v1", 500),
            100_000,
            "Acrobot-v1: 500-step episodes, discrete",
            "gymnax",
        ),
        Task(
            "mountaincar",
            _gymnax("MountainCar-v0", 200),
            100_000,
            "MountainCar-v0: 200-step episodes, sparse reward, discrete",
            "gymnax",
        ),
        *(
            Task(
                name,
                _swimmer(limit) if name == "swimmer" else _brax(name, limit),
                1_000_000,
                f"{native.split('-')[0]}: {limit}-step episodes, {actions} actions",
                "mjx",
                native,
            )
            for name, native, limit, actions in (
                ("hopper", "Hopper-v3", 1000, 3),
                ("walker2d", "Walker2d-v3", 1000, 6),
                ("halfcheetah", "HalfCheetah-v3", 1000, 6),
                ("ant", "Ant-v3", 1000, 8),
                ("reacher", "Reacher-v2", 50, 2),
                ("swimmer", "Swimmer-v3", 1000, 2),
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
    "native": "any envpool MuJoCo task in native MuJoCo, its own episode limit (native/Hopper-v4)",
    "gymnasium": "any registered Gymnasium environment, stepped on the host, its own episode "
    "limit (gymnasium/CartPole-v1)",
}
_NAMESPACE_BACKENDS = {
    "gymnax": "gymnax",
    "brax": "mjx",
    "playground": "mjx",
    "native": "native",
    "gymnasium": "gymnasium",
}
_NAMESPACED_FORMS = ", ".join(f"{namespace}/<id>" for namespace in NAMESPACES)

_FACTORIES: dict[str, Callable[[str], Callable[[], Environment]]] = {
    "gymnax": _gymnax,
    "brax": _brax,
    "playground": _playground,
    "native": _native,
    "gymnasium": _gymnasium,
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
        backend = _NAMESPACE_BACKENDS[namespace]
        return Task(name, _FACTORIES[namespace](env_id), 100_000, description, backend)
    raise InvalidInput(
        f"unknown environment {name!r}; registered: {', '.join(TASKS)}; "
        f"namespaced: {_NAMESPACED_FORMS}{_suggestion(name)}"
    )


def _suggestion(name: str) -> str:
    """For an id that a namespace knows, given without it: the namespaced names it may mean."""
    import importlib.util

    found = []
    if importlib.util.find_spec("gymnax") is not None:
        from fppo_jax.envs.gymnax import imported_gymnax

        if name in imported_gymnax().registered_envs:
            found.append(f"gymnax/{name}")
    if importlib.util.find_spec("gymnasium") is not None:
        import gymnasium

        if name in gymnasium.registry:
            found.append(f"gymnasium/{name}")
    return suggested(found)


BACKENDS: dict[str, str] = {
    "auto": "MJX where JAX has a GPU or TPU, native MuJoCo on a CPU (MJX if envpool is missing)",
    "mjx": "MuJoCo on MJX, in JAX: the whole program on the accelerator",
    "native": "gym's own MuJoCo tasks in native MuJoCo on the host (envpool), for CPUs",
}
NATIVE_TASKS: tuple[str, ...] = tuple(name for name, task in TASKS.items() if task.native)


def choose_backend(env: str | Any, backend: str = "auto") -> tuple[str, str]:
    """The backend that runs `env` when `backend` is asked for, and why, if "auto" chose it;
    checked without building anything. A task's own backend (as a run records it, "gymnax"
    say) is taken as it is, and a custom environment object runs as it is."""
    if isinstance(env, str) and backend == lookup(env).backend:
        return backend, ""
    if backend not in BACKENDS:
        raise InvalidInput(f"unknown backend {backend!r}; valid backends: {', '.join(BACKENDS)}")
    if not isinstance(env, str):
        if backend != "auto":
            raise InvalidInput(
                "backend applies to tasks given by name; this environment runs as is"
            )
        from fppo_jax.envs.gymnasium import is_gymnasium_env

        default = "gymnasium" if is_gymnasium_env(env) else "custom"
        return str(getattr(env, "backend", default)), ""
    task = lookup(env)
    if backend == "auto":
        if not task.native:
            return task.backend, ""
        from fppo_jax.envs.native import INSTALL, envpool_installed

        if jax.default_backend() != "cpu":
            return task.backend, f"auto: JAX runs on a {jax.default_backend().upper()}"
        if not envpool_installed():
            return task.backend, f"auto: native MuJoCo needs envpool, {INSTALL}"
        return "native", "auto: JAX runs on the CPU"
    if backend == "native" and not task.native and task.backend != "native":
        raise InvalidInput(
            f"{env} has no native version; tasks with one: {', '.join(NATIVE_TASKS)} "
            "(and native/<envpool id>)"
        )
    if backend == "mjx" and task.backend != "mjx":
        raise InvalidInput(
            f"{env} runs on {task.backend}, not MJX; backend applies to MuJoCo tasks"
        )
    if backend == "native":
        from fppo_jax.envs.native import require_envpool

        require_envpool()
    return backend, ""


def backend_name(backend: str | None) -> str | None:
    """What a MuJoCo run's backend is called in what it prints (None for other tasks')."""
    return {"mjx": "MJX", "native": "native MuJoCo"}.get(backend or "")


def describe_backend(backend: str, why: str) -> str:
    """How the line printed before compiling names the backend a MuJoCo run runs on, and
    why it was chosen ("" for other tasks)."""
    name = backend_name(backend)
    return f" ({name}{'; ' + why if why else ''})" if name else ""


def make_env(name: str, backend: str = "auto") -> Environment:
    """The registered or namespaced task `name` (see :func:`lookup`) on `backend` (see
    :data:`BACKENDS` and :func:`choose_backend`). Environments hold no state of their own, so
    one object is made per task and backend and shared: a later run on it reuses the training
    program compiled for it (:mod:`fppo_jax.run.execution`)."""
    if not isinstance(name, str):
        raise InvalidInput(f"make_env takes a task's name, such as 'cartpole'; got {name!r}")
    lookup(name)
    return _made(name, choose_backend(name, backend)[0])


@functools.lru_cache(maxsize=64)
def _made(name: str, backend: str) -> Environment:
    task = lookup(name)
    if backend == "native" and task.native:
        return _native(task.native)()
    return task.make()


# A foreign environment's adapter, by the foreign object's identity (kept alive here, so that
# its id is not reused): the same object gives the same adapter.
_ADAPTERS: collections.OrderedDict[int, tuple[Any, Environment]] = collections.OrderedDict()
_ADAPTERS_KEPT = 16


def _adapter(env: Any, make: Callable[[], Environment]) -> Environment:
    if id(env) not in _ADAPTERS:
        _ADAPTERS[id(env)] = (env, make())
        while len(_ADAPTERS) > _ADAPTERS_KEPT:
            _ADAPTERS.popitem(last=False)
    return _ADAPTERS[id(env)][1]


def as_environment(env: str | Environment | Any, backend: str = "auto") -> Environment:
    """A registered or namespaced name (on `backend`), a gymnax environment (default
    parameters), a Brax ``Env`` (1000-step episodes), a ``gymnasium.Env`` or
    ``gymnasium.vector.VectorEnv`` subclass or a vector environment (see
    :func:`~fppo_jax.envs.gymnasium.gymnasium_environment` for other Gymnasium environments)
    or an :class:`Environment`."""
    if isinstance(env, str):
        return make_env(env, backend)
    choose_backend(env, backend)
    from fppo_jax.envs.gymnax import GymnaxEnvironment, is_gymnax_env

    if is_gymnax_env(env):
        return _adapter(env, lambda: GymnaxEnvironment(env, env.default_params))
    from fppo_jax.envs import mjx

    if mjx.is_brax_env(env):
        return _adapter(env, lambda: mjx.BraxEnvironment(env))
    from fppo_jax.envs.gymnasium import gymnasium_environment, is_gymnasium_env

    if is_gymnasium_env(env):
        return _adapter(env, lambda: gymnasium_environment(env))
    if isinstance(env, Environment):
        return env
    raise TypeError(
        f"expected a registered environment name ({', '.join(TASKS)}), a namespaced one "
        f"({_NAMESPACED_FORMS}), a gymnax or Brax "
        "environment, a gymnasium.Env or gymnasium.vector.VectorEnv subclass or a vector "
        "environment (fppo_jax.envs.gymnasium.gymnasium_environment takes any function that "
        "makes one), or an object with observation_size, action_space, "
        "reset and step; got " + type(env).__name__
    )
