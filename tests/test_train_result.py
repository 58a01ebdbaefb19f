"""One run's result (fppo_jax.run.train_result): its summary, from the metrics and record alone,
and the summary file written whole."""

import numpy as np

from fppo_jax import METRICS, TrainResult, make_env


def result(returns, **fields) -> TrainResult:
    """A run of len(`returns`) updates of 8 × 16 samples, its average returns `returns`."""
    updates = len(returns)
    metrics = {name: np.full(updates, 0.5, np.float32) for name in METRICS}
    metrics.update(
        env_steps=np.arange(1, updates + 1) * 128, average_return=np.asarray(returns, float)
    )
    config = {
        "variant": "fppo-lp", "env": "cartpole", "alpha": 1.3, "epsilon": 0.2, "seed": 4,
        "num_envs": 8, "num_steps": 16, "preset": "paper",
    }  # fmt: skip
    fields = {"compile_seconds": 2.0, "train_seconds": 0.5, **fields}
    return TrainResult(metrics, {}, config, None, None, env=make_env("cartpole"), **fields)


def test_the_summary_names_the_run_its_speed_and_its_best_return():
    lines = result([np.nan, 10.0, 30.0, 20.0]).summary().splitlines()
    assert lines[0] == "fppo-lp on cartpole (alpha = 1.3, epsilon = 0.2), seed 4"
    assert lines[1] == "  updates   4 × 128 samples = 512 env steps (preset paper)"
    assert lines[2] == "  time      compile 2.0 s, train 0.5 s (1,024 env steps/s)"
    assert lines[3] == (
        "  return    final 20.0, max 30.0 at 384 steps (mean of the last 100 episodes)"
    )
    assert lines[4].startswith("  escape    in R+ ∪ R- after the update: 50.00% of samples")


def test_a_resumed_or_stopped_run_says_so_and_one_with_no_episode_finished_too():
    resumed = result([1.0, 2.0, 3.0], resumed_from=3, stopped_at=3).summary()
    assert "(preset paper), resumed at update 3, stopped by the callback at update 3" in resumed
    assert "(nothing left)" in resumed  # every update was trained before it resumed
    assert "  return    no episode finished" in result([np.nan, np.nan]).summary()


def test_the_summary_file_is_written_whole_in_a_directory_made_for_it(tmp_path):
    done = result([1.0, 2.0])
    done.write(tmp_path / "run")
    assert (tmp_path / "run" / "summary.txt").read_text() == done.summary() + "\n"
    assert [p.name for p in (tmp_path / "run").iterdir()] == ["summary.txt"]
