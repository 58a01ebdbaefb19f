"""The loop of a batch of runs (fppo_jax.run.training): a callback that sees every chunk and may
stop the run, evaluations between chunks, a sweep's curves written as each group finishes, and
a run stopped where its output or checkpoint directory is lost."""

import csv
import json
import shutil

import numpy as np
import pytest
from conftest import IN_CHUNKS, TINY
from helpers import assert_bitwise_equal

import fppo_jax
from fppo_jax import evaluate, make_env, sweep, train

# As tests/test_driver.py's run, whose program the compilation cache shares.
RUN = {"env": "cartpole", "variant": "fppo-lp", "seed": 1, "total_steps": 128 * 12, **TINY}


def test_a_callback_sees_every_chunk_and_stops_the_run_checkpointed(tmp_path):
    seen = []

    def callback(snapshot: fppo_jax.Snapshot) -> bool:
        seen.append(snapshot)
        return snapshot.update < 6

    stopped = train(**RUN, checkpoint_dir=tmp_path, checkpoint_every=3, callback=callback)
    assert [s.update for s in seen] == [3, 6]
    assert seen[-1].metrics["env_steps"].tolist() == [128 * u for u in range(1, 7)]
    assert isinstance(seen[-1].policy, fppo_jax.Policy) and seen[-1].runs == range(1)
    assert stopped.stopped_at == 6 and len(stopped.metrics["env_steps"]) == 6
    assert "stopped by the callback at update 6" in stopped.summary()
    # The checkpoint holds update 6: resuming finishes the run as if it had never stopped.
    resumed = train(**RUN, checkpoint_dir=tmp_path, checkpoint_every=3, resume=True)
    whole = train(**RUN, checkpoint_every=3, checkpoint_dir=tmp_path / "whole")
    assert resumed.resumed_from == 6
    assert_bitwise_equal(resumed.metrics, whole.metrics)
    assert_bitwise_equal(resumed.params, whole.params)


def test_periodic_evaluation_records_the_deterministic_return():
    result = train(**RUN, eval_every=5, eval_episodes=3)
    returns = result.metrics["eval_return"]
    assert np.isfinite(returns[[4, 9, 11]]).all()  # updates 5, 10 and the last, 12
    assert np.isnan(np.delete(returns, [4, 9, 11])).all()
    final = evaluate(make_env("cartpole"), result.policy, 3, deterministic=True)
    assert returns[-1] == pytest.approx(final.mean(), rel=1e-6)
    # Evaluating does not change training (in the same chunks: chunks change nothing either).
    plain = train(**RUN, **IN_CHUNKS)
    assert_bitwise_equal(plain.params, result.params)


def test_a_callback_can_stop_a_sweep():
    def callback(snapshot):
        assert snapshot.metrics["env_steps"].shape[0] == 2  # [run, update]
        return snapshot.update < 2

    result = sweep(
        "cartpole", {"variant": "ppo"}, seeds=2, total_steps=128 * 4, **TINY, callback=callback
    )
    assert result.metrics["env_steps"].shape == (2, 2)


def test_a_numpy_boolean_stops_and_anything_but_a_boolean_or_none_is_named(tmp_path):
    every = {"checkpoint_dir": tmp_path / "a", "checkpoint_every": 3}
    # The README's pattern: a comparison of numpy metrics gives numpy's bool.
    below = train(**RUN, **every, callback=lambda s: s.metrics["env_steps"][-1] < 0)
    assert below.stopped_at == 3
    every["checkpoint_dir"] = tmp_path / "b"
    quiet = train(**RUN, **every, callback=lambda s: None)
    assert quiet.stopped_at is None and len(quiet.metrics["env_steps"]) == 12
    for i, answer in enumerate((0, "stop", np.array([True]))):
        every["checkpoint_dir"] = tmp_path / f"c{i}"
        with pytest.raises(TypeError, match=r"the callback returned .* it must return True or"):
            train(**RUN, **every, callback=lambda s, a=answer: a)


def test_a_sweep_writes_its_curves_as_each_group_finishes(tmp_path):
    seen = []

    def callback(snapshot):
        if snapshot.runs == range(1, 2):  # the second group: the first one's curves are there
            seen.extend(csv.DictReader(open(tmp_path / "curves.csv")))
            return False

    result = sweep(
        "cartpole",
        {"variant": "ppo"},
        seeds=2,
        chunk=1,
        total_steps=128 * 4,
        **TINY,
        log_dir=tmp_path,
        callback=callback,
    )
    assert [(r["run"], int(r["env_steps"])) for r in seen] == [("0", 128 * u) for u in range(1, 5)]
    assert [float(r["policy_loss"]) for r in seen] == result.metrics["policy_loss"][0].tolist()
    # Once stopped, the second group's run is there too, as far as it went.
    rows = list(csv.DictReader(open(tmp_path / "curves.csv")))
    assert [int(r["env_steps"]) for r in rows if r["run"] == "1"] == [128, -1, -1, -1]
    assert json.loads((tmp_path / "sweep.json").read_text())["runs"] == result.runs


def test_an_output_directory_removed_mid_run_stops_it_checkpointed_and_says_so(tmp_path):
    logs, checkpoints = tmp_path / "logs", tmp_path / "ckpt"

    def remove_logs(snapshot):
        if snapshot.update == 3:
            shutil.rmtree(logs)

    every = {"checkpoint_dir": checkpoints, "checkpoint_every": 3, "log_dir": logs}
    with pytest.raises(ValueError, match=rf"{logs}, where this run writes a run's outputs, vanish"):
        train(**RUN, **every, callback=remove_logs)
    assert not logs.exists()
    resumed = train(**RUN, checkpoint_dir=checkpoints, resume=True)
    assert resumed.resumed_from == 6  # the checkpoint after the loss was still written


def test_a_checkpoint_directory_replaced_by_a_file_mid_run_stops_it_at_once(tmp_path):
    checkpoints = tmp_path / "ckpt"

    def replace(snapshot):
        if snapshot.update != 3:
            return
        stand_in = tmp_path / "stand-in"
        stand_in.write_text("not a directory")
        for attempt in range(100):  # moved away whole, while orbax may still write in it
            if checkpoints.is_dir():
                checkpoints.rename(tmp_path / f"moved-{attempt}")
            try:
                stand_in.rename(checkpoints)
                return
            except IsADirectoryError:  # orbax's background save made the directory again
                continue
        pytest.fail(f"orbax kept making {checkpoints} again")

    with pytest.raises(ValueError, match=rf"{checkpoints}, where this run writes checkpoints"):
        train(**RUN, checkpoint_dir=checkpoints, checkpoint_every=3, callback=replace)
