"""fppo_jax.run.execution: the runs' keys, chunks of a run's metrics joined along updates, and
groups of runs joined along runs."""

import jax
import numpy as np

from fppo_jax.run.execution import concatenate, run_keys, updates_per_call


def test_run_keys_are_jax_keys_of_the_seeds_and_an_unsigned_seed_that_of_its_signed_equal():
    seeds = [0, 1, 7, -1, -(2**63), 2**31, 2**32 + 5, 2**63 - 1]
    expected = np.stack([jax.random.key_data(jax.random.key(seed)) for seed in seeds])
    np.testing.assert_array_equal(jax.random.key_data(run_keys(seeds)), expected)
    unsigned = jax.random.key_data(run_keys([2**63, 2**64 - 1]))
    signed = [jax.random.key_data(jax.random.key(seed)) for seed in (-(2**63), -1)]
    np.testing.assert_array_equal(unsigned, np.stack(signed))


def chunk(steps, returns):
    return {
        "env_steps": np.asarray(steps, np.int32),
        "average_return": np.asarray(returns, np.float32),
    }


def test_chunks_join_along_updates_and_a_column_one_lacks_is_nan_there():
    first = chunk([[1, 2], [1, 2]], [[0.5, 1.5], [2.5, 3.5]])
    second = {**chunk([[3], [3]], [[4.5], [5.5]]), "eval_return": np.float32([[7.0], [8.0]])}
    joined = concatenate([first, second])
    np.testing.assert_array_equal(joined["env_steps"], [[1, 2, 3], [1, 2, 3]])
    np.testing.assert_array_equal(joined["average_return"], [[0.5, 1.5, 4.5], [2.5, 3.5, 5.5]])
    np.testing.assert_array_equal(joined["eval_return"], [[np.nan, np.nan, 7], [np.nan, np.nan, 8]])
    assert joined["eval_return"].dtype == np.float32


def test_groups_join_along_runs_and_a_group_stopped_early_is_padded():
    whole = chunk([[1, 2, 3]], [[1.0, 2.0, 3.0]])
    stopped = chunk([[1], [1]], [[4.0], [5.0]])
    joined = concatenate([whole, stopped], axis=0)
    np.testing.assert_array_equal(joined["env_steps"], [[1, 2, 3], [1, -1, -1], [1, -1, -1]])
    np.testing.assert_array_equal(
        joined["average_return"], [[1, 2, 3], [4, np.nan, np.nan], [5, np.nan, np.nan]]
    )


def test_updates_per_call_splits_a_run_into_at_most_the_calls_asked():
    assert updates_per_call(488, 20) == 25  # 20 calls, the last short
    assert updates_per_call(10, 20) == 1
    assert updates_per_call(40, 20) == 2
