"""A study's report.md (fppo_jax.analysis.study_report): across the tasks, the probability of
improvement averaged over them and the IQM of normalised scores, normalised only where every
task can be."""

import numpy as np

from fppo_jax.stats import statistics


def _scores(rng, start: float, shift: float) -> dict:
    """A task's scores as a study holds them: 10 runs per setting, where they start, and
    their final, auc and max, the candidate's shifted by `shift`."""
    base = rng.normal(100.0, 10.0, 10)
    per = {"ppo": base, "spo": base + shift}
    return {
        v: {"final": x, "auc": x, "max": x, "start": np.full(10, start)} for v, x in per.items()
    }


def test_across_tasks_the_report_normalises_only_where_every_task_can_be(tmp_path):
    from fppo_jax.analysis.study_report import normalised_scores, write_report

    rng = np.random.default_rng(0)
    plan = {
        "tasks": ["a", "b"],
        "candidates": ["spo"],
        "baseline": "ppo",
        "primary_endpoint": "final",
        "secondary_endpoints": ["auc"],
        "looks": [10],
        "group_size": 10,
        "max_seeds": 10,
        "level": 0.05,
        "comparisons": [{"task": t, "candidate": "spo", "baseline": "ppo"} for t in "ab"],
        "rule": {"id": "sequential-mann-whitney-holm", "version": 1},
        "commit": "0" * 40,
    }
    rows = [
        {
            "task": t,
            "candidate": "spo",
            "baseline": "ppo",
            "decision": "undecided",
            "final": True,
            "seeds": 10,
            "reason": "r",
        }
        for t in "ab"
    ]
    scores = {"a": _scores(rng, 0.0, 5.0), "b": _scores(rng, 0.0, -5.0)}
    normalised = normalised_scores(plan, scores)
    ppo_a = scores["a"]["ppo"]["final"]
    np.testing.assert_allclose(normalised["ppo"][0], ppo_a / statistics.iqm(ppo_a))
    write_report(tmp_path / "report.md", plan, rows, scores, True)
    report = (tmp_path / "report.md").read_text()
    pairs = [(scores[t]["spo"]["final"], scores[t]["ppo"]["final"]) for t in "ab"]
    mean = "{:.2f} [{:.2f}, {:.2f}]".format(*statistics.aggregate_improvement(pairs))
    level = "{:.3f} [{:.3f}, {:.3f}]".format(*statistics.aggregate(normalised["spo"]))
    assert f"| spo | {mean} | {mean} | {level} |" in report  # the auc here is the final

    # A task whose runs end where they start (every return the same) has no scale.
    flat = {
        v: {**x, "final": np.full(10, -200.0), "start": np.full(10, -200.0)}
        for v, x in scores["b"].items()
    }
    assert normalised_scores(plan, {"a": scores["a"], "b": flat}) == {}
    # Nor one whose baseline ends below where its runs start: the scale would turn round.
    below = {v: {**x, "start": np.full(10, 500.0)} for v, x in scores["b"].items()}
    assert normalised_scores(plan, {"a": scores["a"], "b": below}) == {}
    write_report(tmp_path / "flat.md", plan, rows, {"a": scores["a"], "b": flat}, True)
    flat_report = (tmp_path / "flat.md").read_text()
    assert "Normalised scores: not reported" in flat_report and "| ppo | – | – |" in flat_report
