"""fppo-jax: PPO and its fast variants (FPPO-LP, FPPO-QP, TR-PPO, PPO-RB, TR-PPO-RB, SPO,
clip-higher, DPO) in JAX, and surrogates of one's own (:func:`surrogate`).

The surrogate objective is a pure function of traced data (:func:`objective`), and the whole
training run is one compiled function of its key and hyperparameters (:func:`make_train`), so
seeds, variants and their hyperparameters vmap into one program. :func:`train` runs one
policy, checkpointed and resumable; :func:`sweep` runs a grid of settings × seeds as one
program; :func:`load_policy` reads a trained policy back, saved or from its checkpoints;
:func:`merge` joins sweeps of other seeds into one, and :mod:`fppo_jax.statistics` compares
settings with interval estimates.
"""

import os
import sys

__version__ = "0.1.0"

if sys.platform.startswith("linux") and not os.environ.get("DISPLAY"):
    # MuJoCo picks its OpenGL backend once, when first imported; without a display only an
    # off-screen one (EGL) can render. A backend the user chose is kept.
    os.environ.setdefault("MUJOCO_GL", "egl")

from fppo_jax.api import train
from fppo_jax.checkpoint import (
    CheckpointsUnavailable,
    ConfigMismatch,
    DamagedCheckpoint,
)
from fppo_jax.config import Hyperparameters, TrainConfig, hyperparameters, stack_hyperparameters
from fppo_jax.driver import StoppedBySignal, TrainingDiverged
from fppo_jax.envs import TASKS, Environment, make_env
from fppo_jax.evaluation import evaluate
from fppo_jax.objectives import VARIANTS, Objective, negative_regions, objective, stack
from fppo_jax.options import Snapshot
from fppo_jax.policy import Policy
from fppo_jax.progress import Progress
from fppo_jax.results import SweepResult, TrainResult, merge
from fppo_jax.saved_policy import load_policy
from fppo_jax.surrogates import Surrogate, surrogate
from fppo_jax.sweep import expand_grid, sweep
from fppo_jax.trainer import METRICS, Metrics, Trainer, TrainState, make_train

__all__ = [
    "METRICS",
    "TASKS",
    "VARIANTS",
    "CheckpointsUnavailable",
    "ConfigMismatch",
    "DamagedCheckpoint",
    "Environment",
    "Hyperparameters",
    "Metrics",
    "Objective",
    "Policy",
    "Progress",
    "Snapshot",
    "StoppedBySignal",
    "Surrogate",
    "SweepResult",
    "TrainConfig",
    "TrainResult",
    "TrainState",
    "Trainer",
    "TrainingDiverged",
    "evaluate",
    "expand_grid",
    "hyperparameters",
    "load_policy",
    "make_env",
    "make_train",
    "merge",
    "negative_regions",
    "objective",
    "stack",
    "stack_hyperparameters",
    "surrogate",
    "sweep",
    "train",
]
