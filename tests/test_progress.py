"""fppo_jax.run.progress: what a progress report holds, its lines, its bar and its ETA."""

import math
import sys

import numpy as np
import pytest

from fppo_jax import train
from fppo_jax.run.progress import Progress, ProgressBar, format_seconds, print_progress, reporter

TINY = {"num_envs": 4, "num_steps": 32, "num_minibatches": 4, "num_epochs": 2}
RUN = {"env": "cartpole", "variant": "fppo-qp", "seed": 3, "total_steps": 128 * 20, **TINY}

# After update 3 of 20, 2.31 s in: 1,234.4 steps per second, 185 s left.
REPORT = Progress(
    update=3,
    num_updates=20,
    env_steps=384,
    total_steps=2560,
    average_return=21.456,
    steps_per_second=1234.4,
    elapsed=2.31,
    compile_seconds=1.0,
    eta=185.0,
)


def test_progress_reports_an_eta_and_a_bar_only_on_a_terminal(monkeypatch):
    from fppo_jax.run.progress import ProgressBar, format_seconds, print_progress, reporter

    assert [format_seconds(s) for s in (4.4, 185, 7620, float("nan"))] == [
        "4 s",
        "3 min 05 s",
        "2 h 07 min",
        "-",
    ]
    monkeypatch.setattr(sys.stderr, "isatty", lambda: False, raising=False)
    with reporter(True, "run") as report:
        assert report is print_progress
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True, raising=False)
    assert isinstance(reporter(True, "run"), ProgressBar)
    with reporter(False, "run") as report:
        assert report is None
    seen = []
    train(**RUN, progress=seen.append)
    assert np.isnan(seen[0].eta)  # before any update has run
    etas = np.array([p.eta for p in seen[1:]])
    assert (etas[:-1] > 0).all() and np.isfinite(etas).all() and etas[-1] == 0


@pytest.mark.parametrize(
    "seconds, text",
    [
        (0, "0 s"),
        (0.4, "0 s"),
        (59.4, "59 s"),
        (59.6, "1 min 00 s"),  # rounded to the second first
        (60, "1 min 00 s"),
        (605, "10 min 05 s"),
        (3599, "59 min 59 s"),
        (3600, "1 h 00 min"),
        (3600 + 59 * 60 + 59, "1 h 59 min"),  # whole minutes, not rounded up
        (90_061, "25 h 01 min"),  # hours do not roll over into days
        (math.inf, "-"),
        (-math.inf, "-"),
        (math.nan, "-"),
    ],
)
def test_format_seconds(seconds, text):
    assert format_seconds(seconds) == text


def test_print_progress_writes_one_line_per_report_on_stderr(capsys):
    print_progress(REPORT)
    print_progress(REPORT._replace(average_return=math.nan, eta=math.nan))
    out, err = capsys.readouterr()
    assert out == ""
    assert err.splitlines() == [
        "update     3/20  steps        384/2,560      1,234 steps/s  average return     21.5  "
        "(2.3 s, ETA 3 min 05 s)",
        "update     3/20  steps        384/2,560      1,234 steps/s  average return        -  "
        "(2.3 s, ETA -)",
    ]


def test_the_first_report_says_compiled_loaded_reused_or_resumed(capsys):
    first = REPORT._replace(update=0, env_steps=0, elapsed=0.0, eta=math.nan)
    print_progress(first._replace(compile_seconds=12.34))
    print_progress(first._replace(compile_seconds=2.6, loaded=True))
    print_progress(first._replace(compile_seconds=0.0))
    print_progress(first._replace(update=5, compile_seconds=3.0))
    assert capsys.readouterr().err.splitlines() == [
        "compiled in 12.3 s",
        "loaded from the compilation cache in 2.6 s",
        "reusing the compiled program",
        "compiled in 3.0 s; resuming at update 5",
    ]


def test_reporter_passes_a_callable_through():
    def mine(p: Progress) -> None:
        pass

    with reporter(mine, "run") as report:
        assert report is mine


def test_the_bar_shows_steps_speed_return_and_eta(capsys, monkeypatch):
    monkeypatch.setenv("COLUMNS", "200")  # wide enough not to shorten the fields
    with ProgressBar("fppo-qp on cartpole") as bar:
        bar(REPORT._replace(update=0, env_steps=0, elapsed=0.0, average_return=math.nan))
        bar(REPORT)
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert last.startswith("fppo-qp on cartpole")
    assert last.endswith("384/2560 steps  1,234/s  average return 21.5  ETA 3 min 05 s")


def test_the_counter_counts_env_steps_of_groups_of_runs_done_one_after_another():
    from fppo_jax.run.progress import Counter

    # 5 runs of 10 updates of 128 steps, 2 at a time: groups of runs 0-1, 2-3 and 4.
    counter = Counter(5, 2, 10, 128, compile_seconds=3.0)
    assert counter.steps(0, 0) == 0
    assert counter.steps(0, 4) == 2 * 4 * 128
    assert counter.steps(1, 10) == 4 * 10 * 128
    assert counter.steps(2, 3) == (4 * 10 + 1 * 3) * 128  # the last group holds one run
    assert counter.steps(3, 0) == 5 * 10 * 128  # every run done
    first = counter.progress(0, 0)  # before training: no clock, no speed, no ETA
    assert first[:4] == (0, 10, 0, 6400) and first.elapsed == 0.0
    assert first.compile_seconds == 3.0 and first.steps_per_second == 0.0
    assert math.isnan(first.average_return) and math.isnan(first.eta)
    resumed = Counter(5, 2, 10, 128, compile_seconds=0.0, group=1, update=5)
    assert resumed.progress(1, 5).env_steps == (2 * 10 + 2 * 5) * 128


def test_the_counter_measures_speed_and_eta_over_the_steps_this_call_ran():
    from fppo_jax.run.progress import Counter

    counter = Counter(5, 2, 10, 128, compile_seconds=0.0, group=1, update=5)
    counter.began -= 1000.0  # as if it had run 1000 s, for 2 × 5 updates of 128 steps
    p = counter.progress(1, 10, np.array([20.0, np.nan]))
    assert p.env_steps == 4 * 10 * 128 and p.elapsed == pytest.approx(1000.0, rel=1e-2)
    assert p.steps_per_second == pytest.approx(2 * 5 * 128 / 1000.0, rel=1e-2)
    assert p.eta == pytest.approx((6400 - 5120) / 1.28, rel=1e-2)
    assert p.average_return == 20.0  # the mean over runs of those with a return yet
    assert math.isnan(counter.progress(1, 10, np.array([np.nan, np.nan])).average_return)
