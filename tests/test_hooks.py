"""The work between compiled chunks (fppo_jax.run.hooks), one hook at a time on a chunk made by
hand: the groups finished so far, the user's callback and what its answer means, and the
progress report."""

import numpy as np
import pytest

from fppo_jax.run.hooks import Chunk, Finished, ProgressReport, UserCallback
from fppo_jax.run.progress import Counter


def chunk(runs: int = 2, updates: int = 3) -> Chunk:
    """A chunk of `runs` runs after `updates` updates: average returns 10·run + update, and a
    state and policy that are arrays along runs (what a hook passes on, it does not read)."""
    returns = np.arange(runs)[:, None] * 10.0 + np.arange(1, updates + 1)
    metrics = {
        "average_return": returns,
        "env_steps": np.tile(np.arange(1, updates + 1), (runs, 1)),
    }
    return Chunk(0, range(runs), updates, np.arange(runs) + 100, np.arange(runs) + 200, metrics)


def test_finished_groups_join_along_runs_with_the_update_each_diverged_at():
    finished = Finished()
    assert finished.joined() == {} and finished.diverged.size == 0
    finished.add({"env_steps": np.tile([32, 64, 96], (2, 1))}, np.array([0, 2]))
    finished.add({"env_steps": np.array([[32, 64]])}, np.array([1]))  # a group stopped early
    joined = finished.joined()["env_steps"]
    assert joined.tolist() == [[32, 64, 96], [32, 64, 96], [32, 64, -1]]  # padded
    assert finished.diverged.tolist() == [0, 2, 1]


def test_a_callback_sees_one_run_without_its_axis_and_false_stops_training():
    seen = []
    hook = UserCallback(lambda snapshot: seen.append(snapshot) or None, single_run=True)
    assert hook.after_chunk(chunk(runs=1)) is False  # None goes on
    (snapshot,) = seen
    assert snapshot.update == 3 and snapshot.runs == range(1)
    assert snapshot.metrics["average_return"].tolist() == [1.0, 2.0, 3.0]
    assert (int(snapshot.state), int(snapshot.policy)) == (100, 200)

    sweep = UserCallback(lambda snapshot: seen.append(snapshot) or np.False_, single_run=False)
    assert sweep.after_chunk(chunk(runs=2)) is True  # numpy's False stops
    assert seen[-1].metrics["average_return"].shape == (2, 3)  # a sweep's group, along runs
    assert seen[-1].state.tolist() == [100, 101]
    with pytest.raises(TypeError, match="the callback returned 1 \\(int\\)"):
        UserCallback(lambda _: 1, single_run=True).after_chunk(chunk(runs=1))


def test_the_progress_report_counts_the_steps_and_averages_the_latest_returns():
    reported = []
    counter = Counter(num_runs=2, group_size=2, num_updates=6, samples=32, compile_seconds=1.5)
    assert ProgressReport(reported.append, counter).after_chunk(chunk(runs=2)) is False
    (progress,) = reported
    assert (progress.update, progress.num_updates) == (3, 6)
    assert (progress.env_steps, progress.total_steps) == (2 * 3 * 32, 2 * 6 * 32)
    assert progress.average_return == pytest.approx((3.0 + 13.0) / 2)  # each run's latest
    assert progress.compile_seconds == 1.5
