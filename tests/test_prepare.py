"""fppo_jax.run.prepare: train's and sweep's settings split, checked and resolved once, before an
environment is built or anything compiles."""

import pytest

import fppo_jax.run.prepare
from fppo_jax.core.config import TrainConfig
from fppo_jax.core.resolution import HYPERPARAMETER_DEFAULTS
from fppo_jax.run.options import Options
from fppo_jax.run.prepare import prepare
from fppo_jax.store.record import RunRecord

SHAPE = {"num_envs": 4, "num_steps": 32, "num_minibatches": 4, "num_epochs": 2}


def prepared(env="cartpole", **settings):
    return prepare(
        env,
        settings,
        total_steps=None,
        preset="paper",
        backend="auto",
        hyperparameters=tuple(HYPERPARAMETER_DEFAULTS),
    )


def test_settings_are_split_into_shape_hyperparameters_and_options():
    run = prepared(**SHAPE, learning_rate=1e-3, keep=2, log_dir="out")
    assert run.config == TrainConfig(**SHAPE, total_steps=100_000)  # CartPole's budget
    assert run.hyperparameters == {"learning_rate": 1e-3}
    assert run.options == Options(keep=2, log_dir="out")
    assert (run.task, run.backend, run.why) == ("cartpole", "gymnax", "")


def test_an_unknown_setting_is_refused_listing_every_valid_one_before_building(monkeypatch):
    monkeypatch.setattr(fppo_jax.run.prepare, "make_env", lambda *_: pytest.fail("built"))
    with pytest.raises(ValueError, match="unknown setting num_env; valid: total_steps") as error:
        prepared(num_env=4)
    assert "learning_rate" in str(error.value) and "checkpoint_dir" in str(error.value)
    with pytest.raises(ValueError, match="unknown backend 'gpu'"):
        prepare("cartpole", {}, total_steps=None, preset="paper", backend="gpu", hyperparameters=())


def test_the_environment_is_built_once_on_first_use(monkeypatch):
    built = []
    real = fppo_jax.run.prepare.make_env
    monkeypatch.setattr(fppo_jax.run.prepare, "make_env", lambda *a: built.append(a) or real(*a))
    run = prepared(**SHAPE)
    assert built == []
    assert run.trainer.env is run.environment and run.name == "cartpole"
    assert built == [("cartpole", "gymnax")]  # with the backend chosen, not chosen again


def test_the_record_and_header_name_the_environment_backend_and_shape():
    run = prepared(**SHAPE, total_steps=1024)
    assert run.record() == RunRecord("cartpole", "gymnax", "paper", run.config)
    assert run.header("ppo on cartpole") == (
        "ppo on cartpole: preset paper, 8 updates × 128 samples (4 envs × 32 steps), "
        "4 minibatches × 2 epochs"
    )
