import dataclasses
import importlib.util
import os
import subprocess
import sys
import warnings
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pytest
from helpers import sweep_by_hand
from matplotlib.figure import Figure

from fppo_jax import VARIANTS
from fppo_jax.analysis.plots import (
    plot_ablation,
    plot_curves,
    plot_escape_speed,
    plot_improvement,
    plot_objective,
    plot_objectives,
    plot_profiles,
    plot_sweep,
    plot_tuning_curves,
)
from fppo_jax.core.trainer import METRICS
from fppo_jax.run.results import SweepResult

REPO = Path(__file__).resolve().parent.parent
ESCAPE = np.random.default_rng(1).uniform(0, 0.05, size=(2, 3, 4))  # [state, variant, epoch]


@pytest.fixture
def result() -> SweepResult:
    """A made-up sweep: PPO and FPPO-LP at two αs, 2 seeds, 4 updates."""
    settings = [
        {"variant": "ppo"},
        {"variant": "fppo-lp", "alpha": 1.1},
        {"variant": "fppo-lp", "alpha": 1.5},
    ]
    runs = [{"setting": s, "seed": seed} for s in range(3) for seed in range(2)]
    metrics = {name: np.random.default_rng(0).uniform(size=(6, 4)) for name in METRICS}
    metrics["env_steps"] = np.tile(2048 * np.arange(1, 5), (6, 1))
    metrics["average_return"][:, 0] = np.nan  # no episode finished in the first update
    return SweepResult(
        settings=settings,
        seeds=[0, 1],
        runs=runs,
        metrics=metrics,
        diverged=np.zeros(6, int),
        config={"env": "cartpole"},
        compile_seconds=0.0,
        train_seconds=0.0,
    )


@pytest.fixture(autouse=True)
def close_figures():
    yield
    plt.close("all")


def test_each_plot_returns_a_new_figure(result):
    figures = [
        plot_objective(),
        plot_objective(-1.0, slope=True, variants=["ppo", "fppo-qp"]),
        plot_objectives(),
        plot_curves(result),
        plot_curves(result, "negative_fraction_after"),
        plot_ablation(result),
        plot_escape_speed(ESCAPE, ["ppo", "fppo-lp", "fppo-qp"]),
        plot_curves(result, band="iqm"),
        plot_profiles({"ppo": np.arange(5.0), "fppo-lp": np.arange(5.0) + 1}),
        plot_improvement({"fppo-lp, hopper": (0.6, 0.4, 0.8)}, "ppo"),
    ]
    assert all(isinstance(fig, Figure) for fig in figures)
    assert len(set(map(id, figures))) == len(figures)


def test_each_plot_draws_on_the_axes_it_is_given(result):
    for draw in (
        lambda ax: plot_objective(ax=ax),
        lambda ax: plot_curves(result, ax=ax),
        lambda ax: plot_ablation(result, axes=[ax]),
        lambda ax: plot_escape_speed(ESCAPE, ["ppo", "fppo-lp", "fppo-qp"], ax=ax),
        lambda ax: plot_profiles({"ppo": np.arange(3.0)}, ax=ax),
        lambda ax: plot_improvement({"a": (0.5, 0.4, 0.6)}, "ppo", ax=ax),
    ):
        fig, ax = plt.subplots()
        assert draw(ax) is fig and ax.lines
    fig, axes = plt.subplots(2, 2)
    assert plot_objectives(axes=axes) is fig
    assert all(len(ax.lines) == len(VARIANTS) for ax in axes.flat)  # one per variant


def test_runs_that_diverged_are_left_out_of_the_curves_and_counted_as_the_table_counts_them():
    result = sweep_by_hand()  # ppo: 2 of 3 runs diverged; fppo-lp: all 3; tr-ppo: none
    ax = plot_curves(result).axes[0]
    lines = {line.get_label(): line for line in ax.lines}
    assert list(lines) == [
        "ppo, seeds 1 of 3 (2 diverged)",
        "fppo-lp α=1.3, seeds 0 of 3 (3 diverged)",
        "tr-ppo δ=0.02",
    ]
    assert [text.get_text() for text in ax.get_legend().get_texts()] == list(lines)
    # The run that did not diverge alone, not its diverged runs' 900s.
    np.testing.assert_array_equal(lines["ppo, seeds 1 of 3 (2 diverged)"].get_ydata(), [10, 30, 20])
    assert len(lines["fppo-lp α=1.3, seeds 0 of 3 (3 diverged)"].get_xdata()) == 0
    np.testing.assert_array_equal(lines["tr-ppo δ=0.02"].get_ydata(), [20, 40, 60])
    for index in range(3):
        row = result.table().splitlines()[2 + index]
        assert row.split(" | ")[1] == result.setting_seeds(index)


def test_curves_take_the_names_they_are_given_and_still_say_their_seeds():
    ax = plot_curves(sweep_by_hand(), names=["a", "b", "c"]).axes[0]
    assert [text.get_text() for text in ax.get_legend().get_texts()] == [
        "a, seeds 1 of 3 (2 diverged)",
        "b, seeds 0 of 3 (3 diverged)",
        "c",
    ]


def test_settings_with_fewer_seeds_say_how_many_in_the_legend_and_the_title():
    whole = sweep_by_hand()
    kept = list(range(8))  # tr-ppo's last seed not run
    result = dataclasses.replace(
        whole,
        runs=whole.runs[:8],
        metrics={k: v[kept] for k, v in whole.metrics.items()},
        diverged=whole.diverged[kept],
    )
    ax = plot_curves(result).axes[0]
    assert [line.get_label() for line in ax.lines][-1] == "tr-ppo δ=0.02, seeds 2"
    assert ax.get_title().endswith("over each setting's seeds")
    assert plot_curves(whole).axes[0].get_title().endswith("over 3 seeds")


def test_curve_bands_are_the_sample_std_or_a_bootstrap_interval():
    result = sweep_by_hand()  # tr-ppo's three runs: [10, 20, 30], [20, 40, 60], [30, 60, 90]
    ax = plot_curves(result).axes[0]
    band = ax.collections[-1].get_paths()[0].vertices[:, 1]
    assert "mean ± sample std" in ax.get_title()
    assert band.max() == pytest.approx(60 + np.std([30, 60, 90], ddof=1))
    ax = plot_curves(result, band="median", confidence=0.9).axes[0]
    assert "median, 90% bootstrap CI" in ax.get_title()
    lines = {line.get_label(): line for line in ax.lines}
    np.testing.assert_array_equal(lines["tr-ppo δ=0.02"].get_ydata(), [20, 40, 60])
    band = ax.collections[-1].get_paths()[0].vertices[:, 1]
    assert band.min() >= 10 and band.max() <= 90  # resampled runs stay within the runs
    with pytest.raises(ValueError, match="unknown statistic 'sd'"):
        plot_curves(result, band="sd")


def test_a_profile_falls_from_every_run_to_none():
    scores = {"ppo": np.array([0.0, 0.5, 1.0])}
    ax = plot_profiles(scores, thresholds=np.array([-1, 0.5, 2])).axes[0]
    np.testing.assert_array_equal(ax.lines[0].get_ydata(), [1.0, 1 / 3, 0.0])
    # In words: no symbol a user's hyperparameter could be named (tau, shown as τ).
    assert (ax.get_xlabel(), ax.get_ylabel()) == (
        "threshold on the normalised score",
        "fraction of runs above the threshold",
    )
    from fppo_jax.analysis.study_figures import profile_label

    label = profile_label("final", "ppo")
    assert label == "threshold on the normalised final (1 = ppo's IQM on the task)"
    assert "τ" not in label + ax.get_ylabel()
    ax = plot_improvement({"x": (0.7, 0.6, 0.8), "y": (0.3, 0.1, 0.5)}, "ppo").axes[0]
    ticks = dict(zip([t.get_text() for t in ax.get_yticklabels()], ax.get_yticks(), strict=True))
    assert ticks == {"x": 1, "y": 0}  # the first on top
    assert "P(setting > ppo)" in ax.get_xlabel()


def test_runs_that_diverged_are_left_out_of_the_ablation_chart(result):
    result.diverged[3] = 2  # α = 1.1's second seed; its return, far off, is to be left out
    result.metrics["average_return"][3] = 1e6
    ax = plot_ablation(result).axes[0]
    (bars,) = ax.containers
    assert bars.get_label() == "fppo-lp, 1 of 4 runs diverged"
    line = bars.lines[0]
    best = [result.metrics["average_return"][2, 1:].max()]  # α = 1.1: its one seed left
    best.append(np.nanmax(result.metrics["average_return"][4:].mean(axis=0)))
    np.testing.assert_allclose(line.get_ydata(), best)


def curve_of(bests, steps=120_000):
    """An arm's results as the tuning curves read them: its best score at each rung."""
    curve = [{"env_steps": steps * (r + 1), "best": best} for r, best in enumerate(bests)]
    return {"curve": curve, "expected_best": None}


def test_tuning_curves_write_env_steps_short_enough_not_to_run_together():
    figure = plot_tuning_curves({"cartpole": {"ppo": curve_of([50.0, 120.0, 180.0])}})
    figure.canvas.draw()
    labels = [t.get_text() for t in figure.axes[0].get_xticklabels() if t.get_text()]
    assert labels and all(len(label) <= 4 for label in labels), labels  # 240k, not 240000
    assert "240k" in labels


def test_tuning_curves_of_a_task_where_no_trial_scored_say_so_without_a_warning():
    nothing = {"ppo": curve_of([None, None]), "spo": curve_of([None, None])}
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # matplotlib's "No artists with labels" among them
        figure = plot_tuning_curves({"mountaincar": nothing, "cartpole": {"ppo": curve_of([9.0])}})
    empty, scored = figure.axes
    assert empty.get_legend() is None and scored.get_legend() is not None
    assert [text.get_text() for text in empty.texts] == [
        "no trial scored: each diverged\nor finished no episode"
    ]


def test_tuning_curves_end_in_the_validation_race_each_finalists_and_the_chosen_score():
    race = {"finalists": [4, 2], "validation_scores": [150.0, 90.0], "default_score": 100.0}
    arm = {**curve_of([50.0, 180.0]), "env_steps": 300_000, "race": {**race, "chosen": 4}}
    ax = plot_tuning_curves({"cartpole": {"ppo": arm}}).axes[0]
    finalists, chosen = ax.collections
    assert finalists.get_offsets().tolist() == [[300_000, 150.0], [300_000, 90.0]]
    assert chosen.get_offsets().tolist() == [[300_000, 150.0]]
    kept = {**arm, "race": {**race, "chosen": 0}}  # the default stayed: its score is the chosen
    (_, chosen) = plot_tuning_curves({"cartpole": {"ppo": kept}}).axes[0].collections
    assert chosen.get_offsets().tolist() == [[300_000, 100.0]]


def test_importing_plots_leaves_the_backend_alone():
    code = "import matplotlib, fppo_jax.analysis.plots; print(matplotlib.get_backend())"
    env = {**os.environ, "MPLBACKEND": "svg"}
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == "svg"


def test_plot_sweep_writes_the_pngs_and_closes_its_figures(result, tmp_path):
    paths = plot_sweep(result, tmp_path)
    assert paths == [tmp_path / "curves.png", tmp_path / "ablation.png"]
    assert all(path.read_bytes()[:4] == b"\x89PNG" for path in paths)
    assert not plt.get_fignums()


def test_fppo_jax_plot_without_a_display(result, tmp_path):
    result.write(tmp_path, metrics=("env_steps", "average_return"))
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "MPLBACKEND")}
    subprocess.run([sys.executable, "-m", "fppo_jax", "plot", str(tmp_path)], env=env, check=True)
    assert (tmp_path / "curves.png").read_bytes()[:4] == b"\x89PNG"


def test_figures_script_draws_from_the_recorded_results(tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(REPO / "experiments"))  # as the script puts it
    script = REPO / "experiments" / "paper" / "figures.py"
    spec = importlib.util.spec_from_file_location("figures", script)
    figures = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(figures)
    monkeypatch.setattr(sys, "argv", ["figures.py", "--out", str(tmp_path / "now")])
    figures.main()
    assert {path.name for path in (tmp_path / "now").iterdir()} == {
        "objectives.png",
        "escape_speed.png",
    }
    earlier = REPO / "experiments" / "results" / "earlier-protocol"
    argv = ["figures.py", "--records", str(earlier), "--out", str(tmp_path / "earlier")]
    monkeypatch.setattr(sys, "argv", argv)
    figures.main()
    written = {path.name: path.stat().st_size for path in (tmp_path / "earlier").iterdir()}
    assert set(written) == {
        "objectives.png",
        "table1_classic.png",
        "table1_mujoco.png",
        "ablation.png",
    }
    assert all(size < 200_000 for size in written.values())
    missing = tmp_path / "no-records"
    argv = ["figures.py", "--records", str(missing), "--out", str(tmp_path / "none")]
    monkeypatch.setattr(sys, "argv", argv)
    with pytest.raises(SystemExit) as refused:
        figures.main()
    assert refused.value.code == 2 and not (tmp_path / "none").exists()
