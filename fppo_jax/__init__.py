"""fppo-jax: PPO and its fast variants (FPPO-LP, FPPO-QP, TR-PPO, PPO-RB, TR-PPO-RB, SPO,
clip-higher, DPO) in JAX, and surrogates of one's own (:func:`surrogate`).

The surrogate objective is a pure function of traced data (:func:`objective`), and the whole
training run is one compiled function of its key and hyperparameters (:func:`make_train`), so
seeds, variants and their hyperparameters vmap into one program. :func:`train` runs one
policy, checkpointed and resumable; :func:`sweep` runs a grid of settings × seeds as one
program; :func:`load_policy` reads a trained policy back, saved or from its checkpoints;
:func:`merge` joins sweeps of other seeds into one, and :mod:`fppo_jax.stats.statistics` compares
settings with interval estimates; :func:`study` compares candidates with a baseline, adding
seeds until a preregistered test decides; :func:`tune` tunes every arm with the same budget
(successive halving over a population, each rung one program) for a study on fresh seeds.

Each public name is imported from its module on first use (PEP 562), so that importing the
package, or a light part of it such as :mod:`fppo_jax.store.numpy_policy` or the command line's
``--help``, does not wait for JAX, Flax, orbax and SciPy.
"""

import importlib
import os
import sys
from typing import Any

__version__ = "0.1.0"

if sys.platform.startswith("linux") and not os.environ.get("DISPLAY"):
    # MuJoCo picks its OpenGL backend once, when first imported; without a display only an
    # off-screen one (EGL) can render. A backend the user chose is kept.
    os.environ.setdefault("MUJOCO_GL", "egl")

# Where each public name is defined.
_MODULES = {
    "fppo_jax.run.api": ("train",),
    "fppo_jax.store.checkpoint": ("ConfigMismatch", "DamagedCheckpoint"),
    "fppo_jax.store.checkpoint_writes": ("CheckpointNotWritten", "CheckpointsUnavailable"),
    "fppo_jax.core.config": ("Hyperparameters", "TrainConfig", "stack_hyperparameters"),
    "fppo_jax.core.resolution": ("hyperparameters", "objective"),
    "fppo_jax.run.divergence": ("TrainingDiverged",),
    "fppo_jax.envs": ("TASKS", "Environment", "make_env"),
    "fppo_jax.errors": (
        "FppoError",
        "InvalidInput",
        "MissingFile",
        "MissingPackage",
        "NotEnoughMemory",
    ),
    "fppo_jax.run.evaluation": ("evaluate",),
    "fppo_jax.store.files": ("IncompatibleFormat",),
    "fppo_jax.core.variants": ("VARIANTS", "negative_regions"),
    "fppo_jax.core.objectives": ("Objective", "stack"),
    "fppo_jax.run.options": ("Snapshot",),
    "fppo_jax.core.policy": ("Policy",),
    "fppo_jax.run.progress": ("Progress",),
    "fppo_jax.run.merge": ("merge",),
    "fppo_jax.run.results": ("SweepResult",),
    "fppo_jax.run.train_result": ("TrainResult",),
    "fppo_jax.store.saved_policy": ("load_policy",),
    "fppo_jax.analysis.studies": ("study",),
    "fppo_jax.analysis.study_files": ("StudyResult", "load_study"),
    "fppo_jax.core.surrogates": ("Surrogate",),
    "fppo_jax.core.own_surrogates": ("surrogate",),
    "fppo_jax.run.stop_signals": ("StoppedBySignal",),
    "fppo_jax.run.sweeps": ("expand_grid", "sweep"),
    "fppo_jax.core.trainer": ("METRICS", "Metrics", "Trainer", "TrainState", "make_train"),
    "fppo_jax.analysis.tuning": ("tune",),
    "fppo_jax.analysis.tune_files": ("TuneResult", "load_tune"),
}
_MODULE_OF = {name: module for module, names in _MODULES.items() for name in names}

__all__ = [
    "METRICS",
    "TASKS",
    "VARIANTS",
    "CheckpointNotWritten",
    "CheckpointsUnavailable",
    "ConfigMismatch",
    "DamagedCheckpoint",
    "Environment",
    "FppoError",
    "Hyperparameters",
    "IncompatibleFormat",
    "InvalidInput",
    "Metrics",
    "MissingFile",
    "MissingPackage",
    "NotEnoughMemory",
    "Objective",
    "Policy",
    "Progress",
    "Snapshot",
    "StoppedBySignal",
    "StudyResult",
    "Surrogate",
    "SweepResult",
    "TrainConfig",
    "TrainResult",
    "TrainState",
    "Trainer",
    "TrainingDiverged",
    "TuneResult",
    "evaluate",
    "expand_grid",
    "hyperparameters",
    "load_policy",
    "load_study",
    "load_tune",
    "make_env",
    "make_train",
    "merge",
    "negative_regions",
    "objective",
    "stack",
    "stack_hyperparameters",
    "study",
    "surrogate",
    "sweep",
    "train",
    "tune",
]


def __getattr__(name: str) -> Any:
    if name in _MODULE_OF:
        value = getattr(importlib.import_module(_MODULE_OF[name]), name)
    else:
        # A layer as an attribute (fppo_jax.stats), as when the package imported it.
        try:
            value = importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as error:
            if error.name != f"{__name__}.{name}":
                raise
            raise AttributeError(f"module {__name__!r} has no attribute {name!r}") from None
    globals()[name] = value  # looked up once
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
