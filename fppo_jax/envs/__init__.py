"""Environments: the interface the trainer steps (:mod:`.core`), one module per adapter
(:mod:`.gymnax`; :mod:`.mjx`: Brax on MJX and Swimmer on MJX itself; :mod:`.playground`:
MuJoCo Playground) and the task registry with its namespaces (:mod:`.tasks`).

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
    where_done,
)
from fppo_jax.envs.gymnax import GymnaxEnvironment
from fppo_jax.envs.tasks import (
    MUJOCO_TASKS,
    NAMESPACES,
    TASKS,
    Task,
    as_environment,
    lookup,
    make_env,
)

__all__ = [
    "MUJOCO_TASKS",
    "NAMESPACES",
    "TASKS",
    "Box",
    "Discrete",
    "Environment",
    "GymnaxEnvironment",
    "Step",
    "Task",
    "as_environment",
    "check_environment",
    "draw_resets",
    "lookup",
    "make_env",
    "where_done",
]
