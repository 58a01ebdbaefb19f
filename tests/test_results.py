"""A sweep's results (fppo_jax.run.results): its statistics tables and comparisons against a
baseline, written and read back by the command line."""

import numpy as np
import pytest
from helpers import sweep_by_hand, two_settings

from fppo_jax.cli import main
from fppo_jax.run.results import max_average_return


def test_the_paper_statistic_shows_the_sample_std():
    returns = np.array([[0.0, 10.0], [0.0, 20.0], [0.0, 60.0]])
    best, std, at = max_average_return(returns)
    assert (best, at) == (30.0, 1)
    assert std == pytest.approx(np.std([10, 20, 60], ddof=1))


def test_an_interval_table_gives_each_setting_its_statistic_and_interval():
    result = two_settings()
    rows = result.table("iqm", "final").splitlines()
    assert rows[0] == "| setting | seeds | IQM of the final score [95% CI] | sample std |"
    ppo, lp = rows[2].split(" | "), rows[3].split(" | ")
    assert ppo[:2] == ["| ppo", "8"] and lp[:2] == ["| fppo-lp α=1.3", "8"]
    assert ppo[2].startswith("3.5 [") and lp[2].startswith("103.5 [")  # IQM of 0…7 is 3.5
    assert ppo[3] == f"{np.std(np.arange(8), ddof=1):.1f} |"
    assert result.table("mean", "auc", 0.9).splitlines()[0].endswith("[90% CI] | sample std |")
    with pytest.raises(ValueError, match="unknown statistic 'mode'"):
        result.table("mode")
    for level in ("0.9", None, 1.5):  # refused before a header is formatted with it
        with pytest.raises(ValueError, match="the confidence level must be in"):
            result.table("iqm", confidence=level)
        with pytest.raises(ValueError, match="the confidence level must be in"):
            result.compare(confidence=level)


def test_a_table_leaves_diverged_runs_out_of_the_interval():
    rows = sweep_by_hand().table("mean").splitlines()[2:]
    assert rows[0].startswith("| ppo | 1 of 3 (2 diverged) | 20.0 [20.0, 20.0] |")
    assert rows[1] == "| fppo-lp α=1.3 | 0 of 3 (3 diverged) | – | – |"


def test_compare_against_a_baseline():
    text = two_settings().compare("ppo")
    assert "Against ppo (8 seeds), final return" in text
    row = text.splitlines()[-1].split(" | ")
    assert row[:3] == ["| fppo-lp α=1.3", "8", "1.00 [1.00, 1.00]"]  # every pair improves
    point, interval = row[3].split(" [")
    low, high = map(float, interval.rstrip("] |").split(", "))
    assert float(point) == 100.0 and low < 100 < high
    close = two_settings(shift=0.5).compare("fppo-lp")  # ppo against fppo-lp, a near tie
    point, interval = close.splitlines()[-1].split(" | ")[2].split(" [")
    low, high = map(float, interval.rstrip("]").split(", "))
    assert float(point) < 0.5 and low < 0.5 < high
    with pytest.raises(ValueError, match="no setting of the sweep called 'tr-ppo'"):
        two_settings().compare("tr-ppo")


def test_table_and_compare_warn_of_an_interval_one_seed_cannot_give(tmp_path, capsys):
    two_settings(seeds=1).write(tmp_path / "one")
    two_settings(seeds=2).write(tmp_path / "two")
    warning = "fppo-jax: warning: {} has 1 run with a final score: its confidence interval cannot"
    for command in (["table", "--stat", "iqm"], ["compare", "--baseline", "ppo"]):
        assert main([command[0], str(tmp_path / "one"), *command[1:]]) == 0
        err = capsys.readouterr().err
        assert warning.format("ppo") in err and warning.format("fppo-lp α=1.3") in err
        assert main([command[0], str(tmp_path / "two"), *command[1:]]) == 0
        assert capsys.readouterr().err == ""
    assert main(["table", str(tmp_path / "one")]) == 0  # the paper's statistic: no interval
    assert capsys.readouterr().err == ""
