"""fppo_jax.analysis.population: a window of runs of several arms trains as one program per
group shape; its shares, trained apart and put together, are the window trained whole, bit for
bit, whichever arms fall in a group; its state goes on where it stopped; a window says what it
goes on from."""

import numpy as np
import pytest
from conftest import TINY

from fppo_jax.analysis.population import Population, Window, load_state, save_leaves
from fppo_jax.core.resolution import resolve
from fppo_jax.errors import InvalidInput
from fppo_jax.run.prepare import prepare

ARMS = [resolve("ppo"), resolve("spo")]
SETTINGS = {"ppo": [{}, {"learning_rate": 1e-3}], "spo": [{}]}
# spo's run last: the last group of 2 holds it alone (filled up with itself).
RUNS = (("ppo", 0, 5), ("ppo", 1, 5), ("ppo", 0, 6), ("spo", 0, 5), ("spo", 0, 6))


def _population(chunk):
    prepared = prepare("cartpole", TINY, (), total_steps=4 * 128, preset="paper", backend="auto")
    return Population(prepared, ARMS, SETTINGS, 1, chunk, lambda line: None)


def test_shares_of_a_window_are_the_window_trained_whole_whichever_arms_a_group_holds(tmp_path):
    window = Window(RUNS, 0, 2)
    # In groups of 2, as the shares train (XLA rounds a program by its run count).
    split = _population(2)
    assert [group.tolist() for group in split.groups(window)] == [[0, 1], [2, 3], [4, 4]]
    whole = split.share(window, (1, 1), None, True, "whole")
    assert whole.runs == list(RUNS) and whole.last.shape == (5,)
    shares = [split.share(window, (k, 2), None, True, f"part {k}") for k in (1, 2)]
    assert [run for share in shares for run in share.runs] == list(RUNS)
    assert np.array_equal(np.concatenate([s.last for s in shares]), whole.last)
    for leaf, *parts in zip(whole.leaves, *(s.leaves for s in shares), strict=True):
        assert np.array_equal(np.concatenate(parts), leaf)
    # The window after goes on from the state saved, as a run that never stopped.
    save_leaves(tmp_path / "state.npz", whole.leaves)
    later = Window(RUNS, 2, 4, tuple(range(5)))
    went_on = split.share(later, (1, 1), tmp_path / "state.npz", False, "later")
    straight = split.share(Window(RUNS, 0, 4), (1, 1), None, False, "straight")
    assert np.array_equal(went_on.last, straight.last) and went_on.leaves == []


def test_a_window_of_several_run_shapes_trains_each_shape_whole_as_its_own_population():
    # Trial 1 of ppo trains 16 steps per rollout: twice the updates of the task's 32, whole.
    settings = {"ppo": [{}, {"learning_rate": 1e-3, "num_steps": 16}], "spo": [{}]}
    runs = (("ppo", 1, 5), ("ppo", 0, 5), ("spo", 0, 5), ("ppo", 1, 6))

    def shaped(shape):
        return prepare(
            "cartpole", {**TINY, **dict(shape)}, (), total_steps=512, preset="paper", backend="auto"
        )

    task = shaped(())
    mixed = Population(task, ARMS, settings, 1, None, lambda line: None, shaped=shaped)
    window = Window(runs, 0, task.config.num_updates)
    assert [group.tolist() for group in mixed.groups(window)] == [[0, 3], [1, 2]]
    trained = mixed.share(window, (1, 1), None, False, "mixed")
    assert trained.positions.tolist() == [0, 3, 1, 2]
    # Each shape alone, as a population of its own, gives the same numbers.
    short = shaped((("num_steps", 16),))
    assert short.config.num_updates == 2 * task.config.num_updates
    alone = Population(
        short, ARMS, {"ppo": [{}, {"learning_rate": 1e-3}], "spo": [{}]}, 1, None, print
    )
    first = alone.share(
        Window((runs[0], runs[3]), 0, short.config.num_updates), (1, 1), None, False, ""
    )
    assert np.array_equal(trained.last[:2], first.last)
    with pytest.raises(InvalidInput, match="trains whole runs alone"):
        mixed.share(Window(runs, 0, 1), (1, 1), None, False, "part of a run")


def test_a_state_of_another_window_is_refused(tmp_path):
    population = _population(None)
    whole = population.share(Window(RUNS[:2], 0, 1), (1, 1), None, True, "two runs")
    save_leaves(tmp_path / "state.npz", whole.leaves)
    with pytest.raises(InvalidInput, match="does not hold this tune's state"):
        population.share(
            Window(RUNS, 1, 2, tuple(range(5))), (1, 1), tmp_path / "state.npz", False, ""
        )
    with pytest.raises(InvalidInput, match="does not hold this tune's state"):
        load_state(tmp_path / "state.npz", {"x": np.zeros(2)}, np.arange(2), 2)


def test_a_window_says_what_it_goes_on_from():
    with pytest.raises(InvalidInput, match="goes on from saved state, and only it"):
        Window((("ppo", 0, 0),), 4, 8)
    with pytest.raises(InvalidInput, match="one saved state for each of its runs"):
        Window((("ppo", 0, 0), ("ppo", 1, 0)), 4, 8, (0,))
