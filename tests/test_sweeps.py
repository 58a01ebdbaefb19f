import dataclasses
import logging
import subprocess
import sys

import jax
import numpy as np
import pytest
from conftest import IN_CHUNKS
from helpers import sweep_by_hand

import fppo_jax
from fppo_jax import METRICS, VARIANTS, SweepResult, expand_grid, merge, sweep, train
from fppo_jax.cli import main

TINY_SHAPE = {"num_envs": 4, "num_steps": 32, "num_minibatches": 4, "num_epochs": 2}
TINY = {**TINY_SHAPE, "total_steps": 256}


def test_grid_drops_values_a_variant_does_not_take():
    settings = expand_grid({"variant": ["ppo", "fppo-lp"], "alpha": [1.1, 1.3]})
    assert settings == [
        {"variant": "ppo"},
        {"variant": "fppo-lp", "alpha": 1.1},
        {"variant": "fppo-lp", "alpha": 1.3},
    ]
    assert expand_grid({"variant": "fppo-qp"}, task="cartpole") == [
        {"variant": "fppo-qp", "k": 0.4}
    ]
    assert (
        len(
            expand_grid(
                {"variant": ["tr-ppo"], "delta": [0.01, 0.02], "learning_rate": [1e-4, 3e-4]}
            )
        )
        == 4
    )


@pytest.mark.parametrize(
    "grid, match",
    [
        ({"lr": [1e-3]}, "cannot sweep lr; sweepable: variant, epsilon"),
        ({"variant": ["ppo", "sppo"]}, "unknown variant 'sppo'"),
        ({"alpha": []}, "the grid gives alpha no values"),
        (
            {"epsilon": [i / 200 for i in range(1, 101)], "learning_rate": [1e-4] * 101},
            "the grid gives 10,100 combinations of values, more than 10,000",
        ),
    ],
)
def test_bad_grids_are_named(grid, match):
    with pytest.raises(ValueError, match=match):
        expand_grid(grid)


def test_out_of_range_settings_fail_before_compiling():
    with pytest.raises(ValueError, match="alpha must be >= 1 for fppo-lp"):
        sweep("cartpole", {"variant": ["fppo-lp"], "alpha": [0.9, 1.2]}, **TINY)
    with pytest.raises(ValueError, match="alpha given both in the grid and as a fixed value"):
        sweep("cartpole", {"alpha": [1.2]}, alpha=1.3, **TINY)


# A large learning rate, so that ratios leave the clip range and the variants really differ.
FAST = {**TINY, "learning_rate": 0.01}


@pytest.fixture(scope="module")
def mixed():
    grid = {"variant": ["ppo", "fppo-lp", "tr-ppo"], "alpha": [1.5]}
    return sweep("cartpole", grid, seeds=[0, 3], **FAST)


def test_a_sweep_run_follows_the_same_run_through_train_over_its_first_updates(mixed):
    assert [mixed.settings[r["setting"]]["variant"] for r in mixed.runs] == [
        "ppo",
        "ppo",
        "fppo-lp",
        "fppo-lp",
        "tr-ppo",
        "tr-ppo",
    ]
    for run, variant, alpha in [(3, "fppo-lp", 1.5), (4, "tr-ppo", None)]:
        assert mixed.runs[run]["seed"] == (3 if run == 3 else 0)
        alone = train("cartpole", variant, alpha, seed=mixed.runs[run]["seed"], **FAST)
        # Vmapped kernels round differently from unbatched ones and training amplifies the
        # difference: the runs agree to float tolerance over their first updates only (on
        # CartPole at this learning rate, about six), so two are compared.
        first = slice(0, 2)
        for name in METRICS:
            np.testing.assert_allclose(
                mixed.metrics[name][run, first], alone.metrics[name][first], rtol=1e-4, atol=1e-6
            )


def test_mixed_variants_train_differently(mixed):
    losses = {tuple(np.round(mixed.metrics["policy_loss"][i], 6)) for i in (0, 2, 4)}
    assert len(losses) == 3


def test_chunked_sweep_matches_the_unchunked_one(mixed):
    chunked = sweep(
        "cartpole",
        {"variant": ["ppo", "fppo-lp", "tr-ppo"], "alpha": [1.5]},
        seeds=[0, 3],
        chunk=2,
        **FAST,
        **IN_CHUNKS,  # two runs in chunks of updates: the program of other tests' sweeps
    )
    assert chunked.config["runs_per_call"] == 2 and mixed.config["runs_per_call"] == 6
    for name in METRICS:
        np.testing.assert_allclose(chunked.metrics[name], mixed.metrics[name], rtol=1e-4, atol=1e-6)


def compilations_of_the_training_program(caplog, grid):
    caplog.clear()
    # A shape no other test trains, so that no program compiled earlier in the process is reused.
    with caplog.at_level(logging.WARNING), jax.log_compiles(True):
        sweep("cartpole", grid, seeds=1, **{**TINY, "num_epochs": 3})
    return sum(
        "Finished XLA compilation of jit(run)" in r.getMessage()
        or "Finished XLA compilation of jit(init)" in r.getMessage()
        for r in caplog.records
    )


def test_growing_the_grid_adds_no_compilation(caplog):
    small = compilations_of_the_training_program(caplog, {"variant": ["ppo", "fppo-lp"]})
    large = compilations_of_the_training_program(
        caplog,
        {
            "variant": ["ppo", "fppo-qp", "tr-ppo"],
            "epsilon": [0.1, 0.2],
            "learning_rate": [1e-4, 3e-4],
        },
    )
    assert small == large == 2  # the initialisation and the chunk of updates


def test_written_results_read_back(mixed, tmp_path):
    mixed.write(tmp_path)
    back = SweepResult.read(tmp_path)
    assert back.settings == mixed.settings and back.runs == mixed.runs
    for name in METRICS:
        np.testing.assert_allclose(back.metrics[name], mixed.metrics[name], rtol=1e-6)
    table = back.table()
    assert table == mixed.table()
    assert [line.split(" | ")[0] for line in table.splitlines()[2:]] == [
        "| ppo",
        "| fppo-lp α=1.5",
        "| tr-ppo",
    ]
    with pytest.raises(FileNotFoundError, match="not a sweep's output"):
        SweepResult.read(tmp_path / "missing")


def test_the_table_counts_only_the_runs_that_did_not_diverge(tmp_path):
    result = sweep_by_hand()
    header, _, *rows = result.table().splitlines()
    assert "| max average return ± sample std |" in header  # the table says what its ± is
    assert rows == [
        "| ppo | 1 of 3 (2 diverged) | 30.0 | 256 | 20.0 | 50.00% |",
        "| fppo-lp α=1.3 | 0 of 3 (3 diverged) | diverged at update 2 | – | – | – |",
        "| tr-ppo δ=0.02 | 3 | 60.0 ± 30.0 | 384 | 60.0 | 50.00% |",  # sample std
    ]
    result.write(tmp_path)
    assert SweepResult.read(tmp_path).table() == result.table()


def test_a_sweep_whose_setting_diverges_shows_it():
    grid = {"variant": "ppo", "learning_rate": [3e-4, 1e30]}
    # Two runs per call in one-update chunks: the program of the driver's tests' sweeps.
    result = sweep("cartpole", grid, seeds=2, chunk=2, **TINY, **IN_CHUNKS)
    assert result.diverged.tolist() == [0, 0, 1, 1]
    rows = result.table().splitlines()[2:]
    assert rows[0].startswith("| ppo learning_rate=0.0003 | 2 | ")
    assert rows[1] == (
        "| ppo learning_rate=1e+30 | 0 of 2 (2 diverged) | diverged at update 1 | – | – | – |"
    )


def test_every_variant_trains_with_continuous_actions():
    # Pendulum: a diagonal Gaussian policy and its exact KL, for every variant, in seconds.
    result = sweep(
        "gymnax/Pendulum-v1", {"variant": list(VARIANTS)}, seeds=1, **{**TINY, "total_steps": 256}
    )
    m = result.metrics
    assert m["env_steps"].shape == (len(VARIANTS), 2) and not result.diverged.any()
    for name in ("policy_loss", "value_loss", "entropy", "approx_kl"):
        assert np.isfinite(m[name]).all(), name
    assert (m["approx_kl"][:, -1] > 0).all()  # every variant moved its policy


@pytest.mark.parametrize("grid", [None, [("alpha", 1.1)], "alpha"])
def test_a_grid_that_is_not_a_mapping_is_refused_saying_what_one_is(grid):
    with pytest.raises(ValueError, match=r"a grid maps names to values, such as \{'alpha'"):
        sweep("cartpole", grid)


# Two processes at once, with -m slow; parts merging into the unsplit sweep bit for bit are
# test_a_split_sweep_merges_into_the_unsplit_sweep_bit_for_bit's in the default run, and
# --part's shares tests/test_studies.py's.
@pytest.mark.slow
def test_two_parts_in_two_processes_merge_into_the_one_process_sweep(tmp_path, capsys):
    flags = ["--env", "cartpole", "--variant", "ppo,fppo-lp", "--seeds", "3", "--steps", "256"]
    flags += ["--num-envs", "4", "--num-steps", "32", "--minibatches", "4", "--epochs", "2"]
    flags += ["--chunk", "3"]
    command = [sys.executable, "-m", "fppo_jax", "sweep", *flags]
    processes = [
        subprocess.Popen(
            [*command, "--part", f"{k}/2", "--output", str(tmp_path / f"part{k}")],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        for k in (1, 2)
    ]
    outputs = [p.communicate()[0] for p in processes]
    assert [p.returncode for p in processes] == [0, 0], outputs
    assert "3 runs (part 1 of 2) on cartpole" in outputs[0]
    assert "sweep on cartpole: 2 settings × 3 seeds = 6 runs, part 2 of 2" in outputs[1]
    part2 = SweepResult.read(tmp_path / "part2")
    assert part2.config["part"] == [2, 2] and part2.seeds == [0, 1, 2]
    assert [(r["setting"], r["seed"]) for r in part2.runs] == [(1, 0), (1, 1), (1, 2)]

    missing = r"part 2 of 2 \(--part 2/2\) is missing: the sweep's runs fppo-lp"
    with pytest.raises(ValueError, match=missing):
        merge([SweepResult.read(tmp_path / "part1")])
    parts = [str(tmp_path / "part1"), str(tmp_path / "part2")]
    assert main(["merge", *parts, "--output", str(tmp_path / "whole")]) == 0
    merged = SweepResult.read(tmp_path / "whole")
    assert "part" not in merged.config
    whole = sweep(
        "cartpole", {"variant": ["ppo", "fppo-lp"]}, seeds=3, chunk=3, total_steps=256, **TINY_SHAPE
    )
    assert merged.runs == whole.runs and merged.settings == whole.settings
    for name in METRICS:  # the one sweep's groups, bit for bit
        np.testing.assert_array_equal(merged.metrics[name], whole.metrics[name], err_msg=name)
    other = dataclasses.replace(part2, config={**part2.config, "part": [2, 3]})
    with pytest.raises(ValueError, match="not shares of one split: their parts are 1 of 2, 2 of 3"):
        merge([SweepResult.read(tmp_path / "part1"), other])


@pytest.mark.parametrize("chunk, splits", [(2, (2, 3)), (4, (2,))])
def test_a_split_sweep_merges_into_the_unsplit_sweep_bit_for_bit(tmp_path, chunk, splits):
    # 6 runs in groups of 2 (3 groups), or of 4 (2 groups, the last padded by repeating the
    # sweep's last run): each part trains whole groups of the sweep, each as the unsplit sweep
    # trains it, so the merged parts are the sweep's bytes, not merely close to them.
    grid = {"variant": ["ppo", "fppo-lp"]}
    whole = sweep("cartpole", grid, seeds=3, chunk=chunk, **TINY)
    whole.write(tmp_path / "whole")
    for count in splits:
        parts = [
            sweep("cartpole", grid, seeds=3, chunk=chunk, part=(k, count), **TINY)
            for k in range(1, count + 1)
        ]
        assert [p.config["runs_per_call"] for p in parts] == [chunk] * count
        merged = merge(parts[::-1])  # in any order
        merged.write(tmp_path / f"merged-{count}")
        assert merged.runs == whole.runs and merged.config["runs_per_call"] == chunk
        assert sorted(merged.metrics) == sorted(whole.metrics)
        for name, values in whole.metrics.items():
            assert np.array_equal(merged.metrics[name], values, equal_nan=True), name
        curves = (tmp_path / f"merged-{count}" / "curves.csv").read_bytes()
        assert curves == (tmp_path / "whole" / "curves.csv").read_bytes()


def test_a_split_into_more_parts_than_the_sweep_has_groups_is_refused():
    grid = {"variant": ["ppo", "fppo-lp"]}
    with pytest.raises(ValueError, match=r"part 1 of 3: the sweep's 6 runs train as 2 groups .*"):
        sweep("cartpole", grid, seeds=3, chunk=4, part=(1, 3), **TINY)
    # By default, a group is as many of the whole sweep's runs as fit, here all of them.
    with pytest.raises(
        ValueError,
        match=r"4 runs train as 1 group of 4 .* at most 3, or split it into at most 1 part$",
    ):
        sweep("cartpole", grid, seeds=2, part=(2, 2), **TINY)


def test_a_part_s_checkpoint_is_not_resumed_as_another_part(tmp_path):
    shape = {**TINY, "checkpoint_dir": tmp_path, "chunk": 2}
    sweep("cartpole", {"variant": "ppo"}, seeds=4, part=(1, 2), **shape)
    with pytest.raises(fppo_jax.ConfigMismatch, match="part"):
        sweep("cartpole", {"variant": "ppo"}, seeds=4, part=(2, 2), resume=True, **shape)


def test_a_stopped_part_resumes_from_its_checkpoint_as_if_never_stopped(tmp_path):
    grid, shape = {"variant": ["ppo", "fppo-lp"]}, {**TINY, "total_steps": 128 * 4, "chunk": 2}
    whole = sweep("cartpole", grid, seeds=2, part=(2, 2), **shape, **IN_CHUNKS)
    stopped = sweep(
        "cartpole",
        grid,
        seeds=2,
        part=(2, 2),
        checkpoint_dir=tmp_path,
        callback=lambda snapshot: snapshot.update < 2,  # preempted after update 2
        **shape,
    )
    assert stopped.metrics["env_steps"].shape[1] == 2
    resumed = sweep(
        "cartpole", grid, seeds=2, part=(2, 2), checkpoint_dir=tmp_path, resume=True, **shape
    )
    assert resumed.runs == whole.runs and resumed.config["part"] == [2, 2]
    for name, values in whole.metrics.items():
        np.testing.assert_array_equal(resumed.metrics[name], values, err_msg=name)
