"""``train`` (fppo_jax.run.api): every argument checked before anything compiles, each refusal
naming what was wrong, and a run's result with its summary written beside its logs."""

import pytest
from conftest import TINY

import fppo_jax.run.driver
from fppo_jax import TrainResult, train
from fppo_jax.errors import InvalidInput


@pytest.mark.parametrize(
    "arguments, message",
    [
        ({"learning_rat": 1e-3}, "unknown setting learning_rat; valid: total_steps, num_envs"),
        (
            {"variant": "ppo", "alpha": 1.5},
            "ppo has no hyperparameter alpha \\(it takes: epsilon\\)",
        ),
        ({"variant": "fppo-lp", "k": 2.0}, "fppo-lp has no hyperparameter k"),
        ({"env": "cartpol"}, "unknown environment 'cartpol'; registered: cartpole"),
        ({"total_steps": 0}, "total_steps must be a positive integer, got 0"),
        ({"num_envs": 0}, "num_envs must be a positive integer, got 0"),
        ({"epsilon": -0.1}, "epsilon must be in \\(0, 1\\), got -0.1"),
        ({"progress": "yes"}, "progress must be True, False or a callable, got 'yes'"),
    ],
)
def test_train_s_arguments_are_refused_before_compiling(arguments, message, monkeypatch):
    monkeypatch.setattr(fppo_jax.run.driver, "compile_program", lambda *_: pytest.fail("compiled"))
    with pytest.raises(InvalidInput, match=message):
        train(**arguments)


def test_a_run_returns_its_result_and_writes_its_summary_beside_its_logs(tmp_path):
    result = train("cartpole", "ppo", total_steps=256, seed=3, log_dir=tmp_path, **TINY)
    assert isinstance(result, TrainResult)
    assert result.metrics["env_steps"].tolist() == [128, 256]  # one row per update, unbatched
    assert (result.config["variant"], result.config["seed"]) == ("ppo", 3)
    assert result.resumed_from == 0 and result.stopped_at is None
    summary = (tmp_path / "summary.txt").read_text()
    assert summary == result.summary() + "\n"
    assert summary.startswith("ppo on cartpole (epsilon = 0.2), seed 3")
