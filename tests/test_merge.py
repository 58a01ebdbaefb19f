"""merge (fppo_jax.run.merge): a sweep's parts, other seeds, other settings or a split sweep's
shares, joined into the sweep trained whole, and what is not one sweep's parts refused."""

import dataclasses

import numpy as np
import pytest
from conftest import IN_CHUNKS
from helpers import two_settings

from fppo_jax import METRICS, SweepResult, sweep
from fppo_jax.cli import main
from fppo_jax.run.merge import merge
from fppo_jax.store.machine import describe_machine

TINY = {"num_envs": 4, "num_steps": 32, "num_minibatches": 4, "num_epochs": 2, "total_steps": 256}


def test_parts_of_one_sweep_merge_into_the_one_process_sweep(tmp_path):
    grid = {"variant": ["ppo", "fppo-qp"]}
    # Two runs per call in one-update chunks: the program of the driver's tests' sweeps.
    shape = {**TINY, "chunk": 2, **IN_CHUNKS}
    whole = sweep("cartpole", grid, seeds=[0, 1, 2], **shape)
    parts = [sweep("cartpole", grid, seeds=s, **shape) for s in ([0, 2], [1])]
    merged = merge(parts)
    assert merged.settings == whole.settings
    assert sorted(map(tuple, (r.values() for r in merged.runs))) == sorted(
        map(tuple, (r.values() for r in whole.runs))
    )
    assert merged.seeds == [0, 2, 1] and merged.config["seeds"] == [0, 2, 1]
    for i, run in enumerate(merged.runs):
        j = whole.runs.index(run)
        for name in METRICS:  # float tolerance over the first updates, as sweep and train
            np.testing.assert_allclose(
                merged.metrics[name][i, :2], whole.metrics[name][j, :2], rtol=1e-4, atol=1e-6
            )
    merged.write(tmp_path / "merged")
    back = SweepResult.read(tmp_path / "merged")
    assert back.table("iqm") == merged.table("iqm")
    # Each sweep names the machine its seconds are of; the merge, each of its parts' once.
    assert whole.machines == merged.machines == back.machines == [describe_machine()]


def test_merge_refuses_other_protocols_and_repeated_runs():
    a, b = two_settings(), two_settings()
    with pytest.raises(ValueError, match="ppo seed 0, ppo seed 1"):
        merge([a, b])
    other = dataclasses.replace(b, config={**b.config, "normalize_rewards": False})
    with pytest.raises(
        ValueError,
        match=r"sweep 2 .* sweep 1: normalize_rewards: false in sweep 2, true in sweep 1$",
    ):
        merge([a, other])
    with pytest.raises(ValueError, match="at least one"):
        merge([])


def one_variant(result: SweepResult, variant: str, grid: dict) -> SweepResult:
    """`result`'s runs of `variant` alone, as a sweep of `grid` would have recorded them."""
    index = [s["variant"] for s in result.settings].index(variant)
    kept = [i for i, run in enumerate(result.runs) if run["setting"] == index]
    return dataclasses.replace(
        result,
        settings=[result.settings[index]],
        runs=[{**result.runs[i], "setting": 0} for i in kept],
        metrics={k: v[kept] for k, v in result.metrics.items()},
        diverged=np.asarray(result.diverged)[kept],
        config={**result.config, "grid": grid},
    )


def test_parts_that_ran_other_settings_merge_and_their_grids_join():
    both = two_settings()
    ppo = one_variant(both, "ppo", {"variant": ["ppo"]})
    lp = one_variant(both, "fppo-lp", {"variant": ["fppo-lp"], "alpha": [1.3]})
    merged = merge([ppo, lp])
    assert merged.settings == both.settings
    assert merged.config["grid"] == {"variant": ["ppo", "fppo-lp"], "alpha": [1.3]}
    assert merged.table("iqm") == both.table("iqm")
    assert merged.compare("ppo") == both.compare("ppo")
    shares = [
        dataclasses.replace(p, config={**p.config, "part": [k, 2]})
        for k, p in enumerate([ppo, lp], start=1)
    ]
    with pytest.raises(ValueError, match="not shares of one split: their grids differ"):
        merge(shares)


def shares(whole: SweepResult, count: int, size: int = 1) -> list[SweepResult]:
    """`whole`'s runs split as ``sweep(..., part=(K, count), chunk=size)`` splits them, K = 1 …
    count: whole groups of `size` runs each."""
    from fppo_jax.run.plan import part_runs

    whole = dataclasses.replace(whole, config={**whole.config, "runs_per_call": size})
    made = []
    for k in range(1, count + 1):
        kept = list(range(*part_runs((k, count), len(whole.runs), size)))
        runs = [whole.runs[i] for i in kept]
        made.append(
            dataclasses.replace(
                whole,
                runs=runs,
                metrics={name: values[kept] for name, values in whole.metrics.items()},
                diverged=np.asarray(whole.diverged)[kept],
                config={**whole.config, "part": [k, count]},
            )
        )
    return made


def test_merge_orders_the_parts_of_a_split_by_their_number(tmp_path, capsys):
    whole = two_settings()
    whole.write(tmp_path / "whole")
    for k, part in enumerate(shares(whole, 11), start=1):
        part.write(tmp_path / f"part-{k}")
    named = sorted(str(path) for path in tmp_path.glob("part-*"))  # as a shell lists them
    assert named[:3] == [str(tmp_path / f"part-{k}") for k in (1, 10, 11)]
    assert main(["merge", *named, "--output", str(tmp_path / "merged")]) == 0
    merged = (tmp_path / "merged" / "curves.csv").read_bytes()
    assert merged == (tmp_path / "whole" / "curves.csv").read_bytes()
    assert SweepResult.read(tmp_path / "merged").runs == whole.runs

    capsys.readouterr()
    assert main(["merge", *named[2:], "--output", str(tmp_path / "partial")]) == 2
    error = capsys.readouterr().err
    assert "parts 1, 10 of 11 (--part 1/11, --part 10/11) are missing" in error


def test_merge_refuses_shares_of_a_split_trained_in_groups_of_other_sizes():
    first, second = shares(two_settings(), 2, size=4)
    other = dataclasses.replace(second, config={**second.config, "runs_per_call": 8})
    with pytest.raises(
        ValueError, match=r"runs_per_call .* differ \(part 1 of 2: 4, part 2 of 2: 8\)"
    ):
        merge([other, first])
    assert merge([second, first]).config["runs_per_call"] == 4


def test_merge_joins_settings_and_seeds_from_the_command_line(tmp_path, capsys):
    first = two_settings()
    second = dataclasses.replace(
        first,
        seeds=[8, 9],
        runs=[{"setting": 0, "seed": 8}, {"setting": 1, "seed": 9}],
        metrics={k: v[:2] for k, v in first.metrics.items()},
        diverged=np.zeros(2, np.int64),
        config={**first.config, "seeds": [8, 9], "runs_per_call": 2},
    )
    first.write(tmp_path / "a")
    second.write(tmp_path / "b")
    out = tmp_path / "merged"
    assert main(["merge", str(tmp_path / "a"), str(tmp_path / "b"), "--output", str(out)]) == 0
    assert "merged 2 sweeps: 18 runs (2 settings, 10 seeds)" in capsys.readouterr().out
    merged = SweepResult.read(out)
    assert [merged.setting_seeds(i) for i in range(2)] == ["9", "9"]
    assert main(["merge", str(tmp_path / "a"), "--output", str(out)]) == 2
    assert "already holds a sweep" in capsys.readouterr().err
    assert main(["table", str(out), "--stat", "median", "--endpoint", "max", "--ci", "0.8"]) == 0
    assert "median of the max score [80% CI]" in capsys.readouterr().out
    assert main(["compare", str(out), "--baseline", "fppo-lp"]) == 0
    # ppo's finals 0…7 and 0 against fppo-lp's 100…107 and 1: 6 pairs above, 1 tie, of 81
    assert f"| ppo | 9 | {6.5 / 81:.2f} [" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        main(["table", str(out), "--ci", "95"])
    assert "the confidence level must be in (0, 1), got 95.0" in capsys.readouterr().err


def test_a_merge_into_a_directory_another_merge_writes_is_refused(tmp_path, capsys):
    from fppo_jax.store.files import DirectoryLock

    two_settings().write(tmp_path / "a")
    out = tmp_path / "merged"
    out.mkdir()
    merging = DirectoryLock(out, "a merged sweep")  # another merge, between its check and write
    assert main(["merge", str(tmp_path / "a"), "--output", str(out)]) == 2
    assert f"is writing a merged sweep in {out}" in capsys.readouterr().err
    assert not (out / "sweep.json").exists()
    merging.release()
    assert main(["merge", str(tmp_path / "a"), "--output", str(out)]) == 0
    assert main(["merge", str(tmp_path / "a"), "--output", str(out)]) == 2
    assert "already holds a sweep" in capsys.readouterr().err
