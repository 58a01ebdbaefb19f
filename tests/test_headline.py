"""The README's headline figure (experiments/headline.py, committed as
experiments/results/figures/headline.png): drawn from the recorded tuned verdict, its values
are the ones results/tuned.md records, what it plots are those values, and the committed image
is what the script draws now."""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import pytest
from helpers import run_script

ROOT = Path(__file__).resolve().parent.parent
EXPERIMENTS = ROOT / "experiments"
COMMITTED = EXPERIMENTS / "results" / "figures" / "headline.png"
LINE = re.compile(
    r"^(?P<task>\w+) (?P<candidate>[\w-]+): (?P<decision>\w+) at (?P<seeds>\d+) seeds, "
    r"P = (?P<interval>\d\.\d\d \[\d\.\d\d, \d\.\d\d\])$"
)


def tuned_rows() -> dict[tuple[str, str], tuple[str, int, str]]:
    """FPPO's rows of tuned.md's decisions against tuned PPO: (task, candidate) to the plan's
    family's decision, the seeds it holds and P(candidate > PPO) as printed."""
    rows = {}
    for line in (EXPERIMENTS / "results" / "tuned.md").read_text().splitlines():
        cells = [cell.strip() for cell in line.strip("|").split("|")]
        if len(cells) == 5 and cells[1] in ("fppo-lp", "fppo-qp") and cells[3].isdigit():
            rows[cells[0], cells[1]] = (cells[2].split(" ")[0], int(cells[3]), cells[4])
    return rows


@pytest.fixture(scope="module")
def drawn(tmp_path_factory) -> tuple[Path, str]:
    """The script run into a new temporary folder: that folder and what it printed."""
    out = tmp_path_factory.mktemp("figures")
    done = run_script(EXPERIMENTS / "headline.py", "--out", str(out), cwd=ROOT)
    assert done.returncode == 0, done.stdout + done.stderr
    return out, done.stdout


def test_the_figure_s_values_are_the_recorded_verdict_s(drawn):
    _, printed = drawn
    found = [m.groupdict() for line in printed.splitlines() if (m := LINE.match(line))]
    recorded = tuned_rows()
    assert len(recorded) == 12  # two candidates on each of the six tasks
    assert {(f["task"], f["candidate"]): (f["decision"], int(f["seeds"]), f["interval"])
            for f in found} == recorded  # fmt: skip
    assert [f["task"] for f in found][::2] == [
        "cartpole", "acrobot", "mountaincar", "hopper", "halfcheetah", "swimmer"
    ]  # fmt: skip


def test_the_committed_figure_is_what_the_script_draws(drawn):
    from matplotlib.testing.compare import compare_images

    out, _ = drawn
    assert compare_images(str(COMMITTED), str(out / "headline.png"), tol=0) is None


def test_each_row_plots_its_interval_and_point_in_its_decision_s_colour(monkeypatch):
    monkeypatch.syspath_prepend(str(EXPERIMENTS))
    headline = importlib.import_module("headline")
    found = [
        headline.Comparison("hopper", "fppo-lp", "worse", 20, (0.09, 0.01, 0.20)),
        headline.Comparison("hopper", "fppo-qp", "equivalent", 40, (0.51, 0.38, 0.65)),
        headline.Comparison("swimmer", "fppo-lp", "better", 50, (0.73, 0.61, 0.84)),
    ]
    figure = headline.draw(found, 0.2)
    ax = figure.axes[0]
    plotted = [line for line in ax.get_lines() if len(line.get_xdata()) in (1, 2)]
    plotted = [line for line in plotted if line.get_linestyle() != "--"]  # not ½'s line
    for row, one in zip([2, 1, 0], found, strict=True):
        point, low, high = one.probability
        interval = next(line for line in plotted if list(line.get_ydata()) == [row, row])
        dot = next(line for line in plotted if list(line.get_ydata()) == [row])
        assert list(interval.get_xdata()) == [low, high] and list(dot.get_xdata()) == [point]
        assert dot.get_color() == interval.get_color() == headline.COLOURS[one.decision]
    labels = {tick.get_position()[1]: tick.get_text() for tick in ax.get_yticklabels()}
    assert labels == {  # top to bottom in the order given
        2: "Hopper, FPPO-LP (20 seeds)",
        1: "Hopper, FPPO-QP (40 seeds)",
        0: "Swimmer, FPPO-LP (50 seeds)",
    }
