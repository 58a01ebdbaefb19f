import os

import pytest

# MuJoCo chooses its OpenGL backend when first imported: off-screen EGL unless one was chosen.
os.environ.setdefault("MUJOCO_GL", "egl")
# Two test processes share the machine: neither takes most of an accelerator's memory up front.
os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")
# A few updates of a small batch: enough to exercise every part of an update quickly.
TINY = {"num_envs": 4, "num_steps": 32, "num_minibatches": 4, "num_epochs": 2}


@pytest.fixture
def tiny() -> dict:
    return dict(TINY)


@pytest.fixture(scope="session")
def saved_policies(tmp_path_factory) -> dict:
    """A discrete policy (CartPole, observations normalised) and a continuous one (Pendulum,
    raw observations, its head scaled up so that its actions often reach their bounds), each
    trained briefly and saved: {"discrete": dir, "continuous": dir}."""
    import dataclasses

    import jax

    from fppo_jax import train
    from fppo_jax.saved_policy import save_policy

    where = tmp_path_factory.mktemp("policies")
    discrete = train("cartpole", "fppo-lp", total_steps=512, **TINY)
    continuous = train(
        "gymnax/Pendulum-v1", "ppo", total_steps=512, normalize_observations=False, **TINY
    )
    params = jax.tree_util.tree_map_with_path(
        lambda path, x: x * 1000 if "Dense_2" in jax.tree_util.keystr(path) else x,
        continuous.policy.params,
    )
    bold = dataclasses.replace(continuous.policy, params=params)
    return {
        "discrete": discrete.save(where / "discrete"),
        "continuous": save_policy(where / "continuous", bold, {"config": continuous.config}),
    }
