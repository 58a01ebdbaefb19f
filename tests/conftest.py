import os

import pytest

# MuJoCo chooses its OpenGL backend when first imported: off-screen EGL unless one was chosen.
os.environ.setdefault("MUJOCO_GL", "egl")
# A few updates of a small batch: enough to exercise every part of an update quickly.
TINY = {"num_envs": 4, "num_steps": 32, "num_minibatches": 4, "num_epochs": 2}


@pytest.fixture
def tiny() -> dict:
    return dict(TINY)
