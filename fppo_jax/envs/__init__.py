"""Environments: the interface the trainer steps (:mod:`.core`), one module per adapter
(:mod:`.gymnax`; :mod:`.mjx`: Brax on MJX and Swimmer on MJX itself; :mod:`.playground`:
MuJoCo Playground; :mod:`.native`: gym's MuJoCo tasks in native MuJoCo through envpool;
:mod:`.gymnasium`: Gymnasium environments stepped on the host) and
the task registry with its namespaces and backends (:mod:`.tasks`).

Only the interface, the gymnax adapter (which imports gymnax on first use) and the registry
are imported here: the classic tasks never pay for Brax, MuJoCo or Playground.
"""

from fppo_jax.envs.core import (
    Box,
    Discrete,
    Environment,
    Step,
    check_environment,
    draw_resets,
    resets_itself,
    where_done,
)
from fppo_jax.envs.gymnax import GymnaxEnvironment
from fppo_jax.envs.tasks import (
    BACKENDS,
    MUJOCO_TASKS,
    NAMESPACES,
    NATIVE_TASKS,
    TASKS,
    Task,
    as_environment,
    backend_name,
    choose_backend,
    describe_backend,
    lookup,
    make_env,
)

__all__ = [
    "BACKENDS",
    "MUJOCO_TASKS",
    "NAMESPACES",
    "NATIVE_TASKS",
    "TASKS",
    "Box",
    "Discrete",
    "Environment",
    "GymnaxEnvironment",
    "Step",
    "Task",
    "as_environment",
    "backend_name",
    "check_environment",
    "choose_backend",
    "describe_backend",
    "draw_resets",
    "lookup",
    "make_env",
    "resets_itself",
    "where_done",
]
