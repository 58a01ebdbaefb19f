import logging

import jax
import numpy as np
import pytest

from fppo_jax import METRICS, SweepResult, expand_grid, sweep, train

TINY = {"num_envs": 4, "num_steps": 32, "num_minibatches": 4, "num_epochs": 2, "total_steps": 256}


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


def test_a_sweep_run_equals_the_same_run_through_train(mixed):
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
        for name in METRICS:
            # Vmapped kernels round differently from unbatched ones: equal to float tolerance.
            np.testing.assert_allclose(
                mixed.metrics[name][run], alone.metrics[name], rtol=1e-4, atol=1e-6
            )


def test_mixed_variants_train_differently(mixed):
    losses = {tuple(np.round(mixed.metrics["policy_loss"][i], 6)) for i in (0, 2, 4)}
    assert len(losses) == 3


def test_chunked_sweep_matches_the_unchunked_one(mixed):
    chunked = sweep(
        "cartpole",
        {"variant": ["ppo", "fppo-lp", "tr-ppo"], "alpha": [1.5]},
        seeds=[0, 3],
        chunk=4,
        **FAST,
    )
    assert chunked.config["runs_per_call"] == 4 and mixed.config["runs_per_call"] == 6
    for name in METRICS:
        np.testing.assert_allclose(chunked.metrics[name], mixed.metrics[name], rtol=1e-4, atol=1e-6)


def compilations_of_the_training_program(caplog, grid):
    caplog.clear()
    with caplog.at_level(logging.WARNING), jax.log_compiles(True):
        sweep("cartpole", grid, seeds=1, **TINY)
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


def made_by_hand() -> SweepResult:
    """Three settings × three seeds, three updates of 128 env steps: two of ppo's runs diverged
    (their returns and fractions are far off, to show they are left out), and all of fppo-lp's."""
    settings = [
        {"variant": "ppo"},
        {"variant": "fppo-lp", "alpha": 1.3},
        {"variant": "tr-ppo", "delta": 0.02},
    ]
    runs = [{"setting": s, "seed": seed} for s in range(3) for seed in range(3)]
    metrics = {name: np.full((9, 3), 0.5) for name in METRICS}
    metrics["env_steps"] = np.tile(128 * np.arange(1, 4), (9, 1))
    metrics["average_return"] = np.array(
        [[10, 30, 20], [900, 900, 900], [900, 900, 900]]
        + [[np.nan, 1, 2]] * 3
        + [[10, 20, 30], [20, 40, 60], [30, 60, 90]],
        float,
    )
    metrics["negative_fraction_after"][1:3] = 1.0
    return SweepResult(
        settings=settings,
        seeds=[0, 1, 2],
        runs=runs,
        metrics=metrics,
        diverged=np.array([0, 3, 2, 4, 2, 3, 0, 0, 0]),
        config={"env": "cartpole"},
        compile_seconds=0.0,
        train_seconds=0.0,
    )


def test_the_table_counts_only_the_runs_that_did_not_diverge(tmp_path):
    result = made_by_hand()
    assert result.table().splitlines()[2:] == [
        "| ppo | 1 of 3 (2 diverged) | 30.0 ± 0.0 | 256 | 20.0 | 50.00% |",
        "| fppo-lp α=1.3 | 0 of 3 (3 diverged) | diverged at update 2 | – | – | – |",
        "| tr-ppo δ=0.02 | 3 | 60.0 ± 24.5 | 384 | 60.0 | 50.00% |",
    ]
    result.write(tmp_path)
    assert SweepResult.read(tmp_path).table() == result.table()


def test_a_sweep_whose_setting_diverges_shows_it():
    grid = {"variant": "ppo", "learning_rate": [3e-4, 1e30]}
    result = sweep("cartpole", grid, seeds=2, **TINY)
    assert result.diverged.tolist() == [0, 0, 1, 1]
    rows = result.table().splitlines()[2:]
    assert rows[0].startswith("| ppo learning_rate=0.0003 | 2 | ")
    assert rows[1] == (
        "| ppo learning_rate=1e+30 | 0 of 2 (2 diverged) | diverged at update 1 | – | – | – |"
    )
