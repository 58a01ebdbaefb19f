"""fppo_jax.analysis.study_looks: a look split over array tasks is refused while a share is
missing, joined once every share is recorded, and decided as the look trained whole."""

import json

import pytest
from own_surrogates import frozen

import fppo_jax
from fppo_jax.analysis.preregistration import commit
from fppo_jax.analysis.study_runs import run_scores
from fppo_jax.run.merge import merge
from fppo_jax.run.results import SweepResult
from fppo_jax.stats.sequential import Design, decide

# As tests/test_studies.py's: PPO learns CartPole in this budget, eight runs per compiled call.
BUDGET = {"total_steps": 4096, "learning_rate": 0.003, "chunk": 8}
HEAD = commit()


def test_a_look_split_over_array_tasks_is_joined_and_decided_by_the_job_after(tmp_path, tiny):
    output = tmp_path / "study"
    settings = {**tiny, **BUDGET, "output": output, "max_seeds": 16, "group_size": 8}
    candidates = [frozen, "fppo-lp"]

    first = fppo_jax.study("cartpole", candidates, "ppo", part=(1, 2), **settings)
    group_1 = output / "cartpole" / "group-1"
    assert sorted(p.name for p in group_1.iterdir()) == ["part-1"]
    assert not first.finished and not (output / "decisions.json").exists()  # nothing decided
    missing = r"holds shares of its runs .* not all of them: .*part"
    with pytest.raises(ValueError, match=missing):
        fppo_jax.study("cartpole", candidates, "ppo", **settings)  # never trained whole over them
    with pytest.raises(ValueError, match=missing):  # nor decided without them
        fppo_jax.study("cartpole", candidates, "ppo", groups=0, **settings)
    assert sorted(p.name for p in group_1.iterdir()) == ["part-1"]

    fppo_jax.study("cartpole", candidates, "ppo", part=(2, 2), groups=1, **settings)
    shares = [SweepResult.read(group_1 / f"part-{k}") for k in (1, 2)]
    # 3 settings × 8 seeds in the sweep's 3 groups of 8 runs (chunk): the first share takes 2.
    assert [len(s.runs) for s in shares] == [16, 8]
    # The group's record of a run of it whole, cut short, beside the shares: they finish it.
    cut = merge(shares)
    cut = SweepResult(**{**cut.__dict__, "runs": cut.runs[:5], "diverged": cut.diverged[:5]})
    cut.metrics = {name: values[:5] for name, values in cut.metrics.items()}
    cut.write(group_1)
    joined = fppo_jax.study("cartpole", candidates, "ppo", groups=0, **settings)
    merged = joined.results["cartpole"]
    assert len(merged.runs) == 24 and merged.seeds == list(range(8))
    scores = [
        (run_scores(merged, v, "final"), run_scores(merged, "ppo", "final"))
        for v in ("frozen", "fppo-lp")
    ]
    expected = decide(scores, Design(8, 16))
    assert [row["decision"] for row in joined.decisions] == ["worse", "undecided"]
    assert [d.decision for d in expected] == ["worse", None]  # fppo-lp awaits the next look
    record = json.loads((output / "decisions.json").read_text())
    assert record["comparisons"] == joined.decisions
    # A share writes no decision: the join records the commit each share trained at.
    (group,) = record["groups"]
    assert group == {"task": "cartpole", "group": 1, "seeds": list(range(8)), "shares": [HEAD] * 2}
    (group_1 / "part-2" / "share.json").unlink()  # a share trained before shares recorded one
    fppo_jax.study("cartpole", candidates, "ppo", groups=0, **settings)
    (group,) = json.loads((output / "decisions.json").read_text())["groups"]
    assert group["shares"] == [HEAD, ""]
