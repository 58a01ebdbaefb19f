"""A study report's task section (fppo_jax.analysis.study_sections): its notes of a cap many runs
share, of an endpoint on which every run tied, of ties and of boundaries Holm's procedure moved."""

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


def test_the_report_notes_ceilings_ties_and_boundaries_that_holm_moved(tmp_path):
    # Task a decided worse at its first look; task b, CartPole-like, most runs tied at the
    # return's cap of 200, then tested at the whole α that a's decision passed on.
    from fppo_jax.analysis.study_report import write_report
    from fppo_jax.stats.spending import boundaries

    rng = np.random.default_rng(1)
    fractions = (0.5, 1.0)
    plan = {
        "tasks": ["a", "b"],
        "candidates": ["spo"],
        "baseline": "ppo",
        "primary_endpoint": "final",
        "secondary_endpoints": ["auc"],
        "looks": [10, 20],
        "group_size": 10,
        "max_seeds": 20,
        "level": 0.05,
        "boundaries_if_none_decided": list(boundaries(0.025, fractions)),
        "comparisons": [{"task": t, "candidate": "spo", "baseline": "ppo"} for t in "ab"],
        "rule": {"id": "sequential-mann-whitney-holm", "version": 1},
        "commit": "0" * 40,
    }
    moved = boundaries(0.05, fractions)[1]
    rows = [
        {
            "task": "a",
            "candidate": "spo",
            "baseline": "ppo",
            "decision": "worse",
            "final": True,
            "seeds": 10,
            "boundary": plan["boundaries_if_none_decided"][0],
            "reason": "r",
        },
        {
            "task": "b",
            "candidate": "spo",
            "baseline": "ppo",
            "decision": "undecided",
            "final": True,
            "seeds": 20,
            "boundary": moved,
            "reason": f"z stayed within ±{moved:.2f}",
        },
    ]

    def task(candidate: np.ndarray, baseline: np.ndarray) -> dict:
        per = {"spo": candidate, "ppo": baseline}
        return {
            v: {"final": x, "auc": x, "max": x, "start": np.zeros(x.size)} for v, x in per.items()
        }

    capped = task(
        np.concatenate([np.full(12, 200.0), rng.uniform(100, 190, 8)]),
        np.concatenate([np.full(15, 200.0), rng.uniform(100, 190, 5)]),
    )
    plain = task(rng.normal(50, 5, 10), rng.normal(80, 5, 10))
    write_report(tmp_path / "report.md", plan, rows, {"a": plain, "b": capped}, True)
    report = (tmp_path / "report.md").read_text()
    a, b = report.split("\n## a\n")[1].split("\n## b\n")
    b = b.split("\n## Across")[0]
    assert "Ceiling" not in a and "Ties" not in a and "Holm's procedure" not in a
    ceiling = (
        "Ceiling on final: 12 of 20 runs of spo (60%) and 15 of 20 runs of ppo (75%) sit at "
        "200, the best any run recorded on this task, tied there"
    )
    assert ceiling in b and "Ceiling on auc: 12 of 20 runs" in b  # on each endpoint's table
    assert "what it 'rules out' above the cap is no evidence" in b
    # Ties: 12 × 15 of the 400 pairs, on the primary endpoint alone.
    assert "Ties on final, the primary endpoint, among the pairs of runs (candidate, ppo) " in b
    assert "each decision used: spo, 180 of 400 pairs (45%). A tie counts ½" in b
    assert b.count("Ties on") == 1
    assert f"{moved:.2f} {plan['boundaries_if_none_decided'][1]:.2f}" == "1.97 2.25"
    assert (
        "Boundaries moved by Holm's procedure: spo's boundary, ±1.97 at look 2 (20 seeds), is "
        "not plan.json's ±2.25 (boundaries_if_none_decided, level 0.025 = α/2): Holm's "
        "procedure passed on the share of α of 1 comparison decided better or worse (decided: spo "
        "on a, worse), so it was tested at level 0.05 = α/1, whose boundary is lower."
    ) in b
