"""What the driver trains (fppo_jax.run.plan): a plan's checks, and the parts of a split sweep,
each whole groups of the sweep's runs."""

import jax
import numpy as np
import pytest

from fppo_jax.run.plan import Plan, part_bounds, part_runs


def test_parts_share_the_sweep_s_groups_in_run_order():
    assert [part_bounds((k, 3), 7) for k in (1, 2, 3)] == [(0, 3), (3, 5), (5, 7)]
    assert part_bounds((1, 1), 4) == (0, 4)
    assert part_bounds((np.int64(2), np.int64(3)), 7) == (3, 5)  # numpy integers are integers
    for bad in ((0, 2), (3, 2), (1.0, 2), "1/2", (1, 2, 3)):
        with pytest.raises(ValueError, match="part must be"):
            part_bounds(bad, 4)
    with pytest.raises(ValueError, match="only 2 runs to share"):
        part_bounds((1, 3), 2)
    # 7 runs in groups of 2 are 4 groups (the last padded): a part takes whole groups of them.
    assert [part_runs((k, 3), 7, 2) for k in (1, 2, 3)] == [(0, 4), (4, 6), (6, 7)]
    assert [part_runs((k, 4), 7, 2) for k in (1, 2, 3, 4)] == [(0, 2), (2, 4), (4, 6), (6, 7)]
    assert part_runs((1, 1), 7, 7) == (0, 7)
    with pytest.raises(
        ValueError,
        match=r"7 runs train as 3 groups of 3 .* at most 2, or split it into at most 3 parts$",
    ):
        part_runs((1, 4), 7, 3)
    with pytest.raises(
        ValueError,
        match=r"6 runs train as 2 groups of 4 .* at most 2, or split it into at most 2 parts$",
    ):
        part_runs((2, 3), 6, 4, across=2)
    with pytest.raises(ValueError, match=r"bit for bit\): split it into at most 2 parts$"):
        part_runs((2, 3), 6, 4, across=4)


def test_a_plan_names_each_run_of_a_sweep_and_trains_one_run_otherwise():
    keys = jax.random.split(jax.random.key(0), 2)
    one_run = {"setting": 0, "seed": 0}
    with pytest.raises(ValueError, match="a train plan trains one run, not 2"):
        Plan("train", None, keys, None, {}, "", "")
    with pytest.raises(ValueError, match="a sweep's plan names each of its runs"):
        Plan("sweep", None, keys, None, {}, "", "", runs=(one_run,))  # one name for two runs
    with pytest.raises(ValueError, match="only a sweep is split into parts"):
        Plan("train", None, keys[:1], None, {}, "", "", share=(1, 2))
    sweep = Plan("sweep", None, keys, None, {}, "", "", runs=(one_run, one_run))
    assert sweep.num_runs == 2 and sweep.along_runs is jax.vmap
