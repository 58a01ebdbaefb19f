"""fppo_jax.run.memory: how much memory a run needs, estimated from shapes, and how many runs fit in
one compiled call."""

import os
import re

import jax
import pytest

import fppo_jax
from fppo_jax.core.config import preset_config
from fppo_jax.envs import make_env
from fppo_jax.run import memory

MiB, GiB = 2**20, 2**30


@pytest.fixture
def sizes(monkeypatch):
    """Set what one run needs and what is free, in bytes: sizes(need, free)."""

    def set_sizes(need: float, free: float) -> None:
        monkeypatch.setattr(memory, "run_bytes", lambda *_: need)
        monkeypatch.setattr(memory, "free_bytes", lambda: free)
        monkeypatch.setattr(memory, "host_run_bytes", lambda _: 0)  # a device-stepped env

    return set_sizes


def fit(wanted: int, across: int = 1, split: int = 1) -> int:
    return memory.runs_per_call(None, None, None, wanted, across=across, split=split)


def test_all_runs_in_one_call_when_they_fit_in_half_the_free_memory(sizes):
    sizes(100, 2000)  # 10 runs fit in the 1000 bytes that half of 2000 leaves
    assert fit(1) == 1 and fit(7) == 7 and fit(10) == 10
    assert fit(11) == 10 and fit(64) == 10  # else the most that fit


def test_runs_shared_by_devices_are_a_multiple_of_the_devices(sizes):
    sizes(100, 700)  # 3 runs fit on each device
    assert fit(100, across=2) == 6 and fit(100, across=4) == 12
    assert fit(5, across=2) == 5  # all of them fit: all of them
    # A run whose environments are split over 2 devices needs half as much on each.
    assert fit(100, split=2) == 7 and fit(100, across=2, split=2) == 14


def test_one_run_that_just_fits_and_one_that_does_not(sizes):
    sizes(1000, 2000)
    assert fit(5) == 1 and fit(5, across=3) == 3
    sizes(3 * GiB, 4 * GiB + 2)
    message = (
        "one run needs about 3.00 GiB and 2.00 GiB (half the free memory of a device) is "
        "available: lower num_envs, num_steps, resets_per_rollout or hidden_sizes"
    )
    with pytest.raises(MemoryError, match=re.escape(message)):
        fit(1)
    assert fit(1, split=2) == 1  # split over two devices, it fits


def estimate(config) -> int:
    trainer = fppo_jax.make_train(config, make_env("cartpole"))
    return memory.run_bytes(trainer, jax.random.key(0), fppo_jax.hyperparameters())


def test_the_estimate_is_what_the_compiled_program_was_measured_to_need():
    # The module's measurement: CartPole with the paper preset needs 2.6 MiB a run.
    paper = estimate(preset_config("paper"))
    assert 2.6 * MiB <= paper <= 2.9 * MiB
    # Fewer reset states, smaller layers or fewer steps: less; more environments: more.
    assert estimate(preset_config("paper", resets_per_rollout=1)) < paper
    assert estimate(preset_config("paper", hidden_sizes=(16,))) < paper
    assert estimate(preset_config("paper", num_steps=128, total_steps=2048)) < paper
    assert estimate(preset_config("paper", num_envs=16, total_steps=4096)) > 1.8 * paper


def test_free_memory_is_the_allocators_limit_or_the_hosts_available_memory():
    free = memory.free_bytes()
    stats = jax.local_devices()[0].memory_stats() or {}
    if "bytes_limit" in stats:
        assert 0 < free <= stats["bytes_limit"]
    else:
        assert 0 < free <= os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
