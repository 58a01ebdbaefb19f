"""The study's report notes: a cap many runs share, and an endpoint on which every run tied."""

import numpy as np

from fppo_jax.analysis.study_sections import _ceiling

PLAN = {"candidates": ["spo"], "baseline": "ppo"}


def test_a_cap_many_runs_share_is_noted_and_a_spread_is_not():
    capped = {
        "spo": {"final": np.array([200.0] * 6 + [150.0] * 4)},
        "ppo": {"final": np.array([200.0] * 3 + [120.0] * 7)},
    }
    note = " ".join(_ceiling(capped, PLAN, "final"))
    assert "6 of 10 runs of spo (60%) and 3 of 10 runs of ppo (30%) sit at 200" in note
    spread = {v: {"final": np.arange(10.0) + i} for i, v in enumerate(["spo", "ppo"])}
    assert _ceiling(spread, PLAN, "final") == []


def test_an_endpoint_on_which_every_run_tied_says_so_rather_than_calling_it_a_cap():
    floor = {v: {"final": np.full(10, -200.0)} for v in ["spo", "ppo"]}
    note = " ".join(_ceiling(floor, PLAN, "final"))
    assert note.strip().startswith("Every run scored -200 on final")
    assert "cap on the return), which no gain" not in note
