"""fppo_jax.study and ``fppo-jax study``: a tiny study on CartPole end to end, stopping early on
a comparison that is clearly decided, resuming after a stop without training again, and
refusing a changed plan; all in temporary directories."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from own_surrogates import frozen, my_ppo
from scipy import stats

import fppo_jax
from fppo_jax.analysis.preregistration import check_plan
from fppo_jax.analysis.study_runs import run_scores
from fppo_jax.cli import main
from fppo_jax.run.merge import merge
from fppo_jax.run.results import SweepResult
from fppo_jax.stats import statistics
from fppo_jax.stats.sequential import Design, decide

# PPO learns CartPole in this budget (its final return 57–106 over 8 seeds against 20–24 for
# `frozen`, which never moves its policy): 8 seeds a side are enough to decide at the first look.
# Eight runs per compiled call: the tests' groups, of 8 seeds per variant, share one program.
BUDGET = {"total_steps": 4096, "learning_rate": 0.003, "chunk": 8}
FLAGS = ["--steps", "4096", "--learning-rate", "0.003", "--chunk", "8", "--quiet"]


def test_a_study_stops_a_decided_comparison_resumes_and_refuses_a_changed_plan(
    tmp_path, tiny, capsys
):
    output = tmp_path / "study"
    settings = {**tiny, **BUDGET, "output": output, "max_seeds": 16, "group_size": 8}
    candidates = [frozen, "fppo-lp"]

    first = fppo_jax.study("cartpole", candidates, "ppo", groups=1, **settings)
    assert not first.finished
    plan = json.loads((output / "plan.json").read_text())
    assert plan["comparisons"] == [
        {"task": "cartpole", "candidate": "frozen", "baseline": "ppo"},
        {"task": "cartpole", "candidate": "fppo-lp", "baseline": "ppo"},
    ]
    assert (plan["primary_endpoint"], plan["secondary_endpoints"]) == ("final", ["auc"])
    assert (plan["level"], plan["looks"], plan["settings"]["learning_rate"]) == (
        0.05,
        [8, 16],
        0.003,
    )
    assert len(plan["commit"]) == 40 and "frozen" in plan["surrogates"]
    frozen_row, fppo_row = first.decisions
    assert (frozen_row["decision"], frozen_row["final"], frozen_row["seeds"]) == ("worse", True, 8)
    assert (fppo_row["final"], fppo_row["seeds"]) == (False, 8)
    assert not (output / "cartpole" / "group-2").exists()
    group_1 = output / "cartpole" / "group-1"
    curves = (group_1 / "curves.csv").read_bytes()
    report = (output / "report.md").read_text()
    assert "**Not finished**" in report and "| frozen | worse | 8 | z = -" in report
    assert "Planned in plan.json before any run (commit" in report
    assert "family-wise error at most 0.05 over the 2 comparisons." in report
    # The repeated CI at the first look, at the level its boundary of α/2 sets, is wider than
    # the unadjusted interval beside it.
    level = 2 * stats.norm.cdf(plan["boundaries_if_none_decided"][0]) - 1
    for variant in ("frozen", "fppo-lp"):
        row = next(r for r in report.splitlines() if r.startswith(f"| {variant} | "))
        repeated, unadjusted = row.split(" | ")[4:6]
        scores = [run_scores(first.results["cartpole"], v, "final")[:8] for v in (variant, "ppo")]
        repeat = statistics.compare(*scores, confidence=level)["probability_of_improvement"]
        plain = statistics.compare(*scores)["probability_of_improvement"]
        assert repeated == "{:.2f} [{:.2f}, {:.2f}]".format(*repeat)
        assert unadjusted == "{:.2f} [{:.2f}, {:.2f}]".format(*plain)
        assert repeat[1] <= plain[1] and plain[2] <= repeat[2]
    assert level > 0.99 and repeat[2] - repeat[1] > plain[2] - plain[1]  # fppo-lp's is wider
    for figure in ("curves.png", "improvement.png"):  # beside the report, drawn
        assert (output / figure).read_bytes().startswith(b"\x89PNG")
    # The task's runs so far as one sweep beside its groups.
    assert (output / "cartpole" / "curves.csv").read_bytes() == curves

    with pytest.raises(ValueError, match="planned with max_seeds = 16, not 24"):
        fppo_jax.study("cartpole", candidates, "ppo", **{**settings, "max_seeds": 24})
    with pytest.raises(ValueError, match=r"settings\.learning_rate = 0\.003, not 0\.001"):
        fppo_jax.study("cartpole", candidates, "ppo", **{**settings, "learning_rate": 0.001})

    planned_at = "0" * 40  # as if the plan had been made by an earlier commit
    (output / "plan.json").write_text(json.dumps({**plan, "commit": planned_at}))
    capsys.readouterr()
    resumed = fppo_jax.study("cartpole", candidates, "ppo", progress=True, **settings)
    assert resumed.finished
    # With progress: the plan, then each look's task and seeds, and each decision as it is made.
    said = [line for line in capsys.readouterr().err.splitlines() if line.startswith("study: ")]
    assert said[0] == (
        "study: plan: 2 looks; better or worse when |z| reaches the look's boundary (level "
        "0.025 while no comparison is decided):"
    )
    assert said[1:3] == [
        "study:   look 1, 8 seeds per setting: ±3.34",  # 8 a side reach |z| = 3.36
        "study:   look 2, 16 seeds per setting: ±2.25",
    ]
    assert said[3:] == [
        "study: look 1 of 2, cartpole: seeds 0–7 of frozen, fppo-lp, ppo recorded already",
        f"study: cartpole: frozen against ppo: worse with 8 seeds ({frozen_row['reason']})",
        "study: look 2 of 2, cartpole: training seeds 8–15 of fppo-lp, ppo",
        f"study: cartpole: fppo-lp against ppo: {resumed.decisions[1]['decision']} with 16 "
        f"seeds ({resumed.decisions[1]['reason']})",
    ]
    assert f"before any run (commit {planned_at})" in (output / "report.md").read_text()
    assert (group_1 / "curves.csv").read_bytes() == curves  # the first group was not trained again
    group_2 = SweepResult.read(output / "cartpole" / "group-2")
    # The decided candidate stopped: the second group is fppo-lp and its baseline only.
    assert [s["variant"] for s in group_2.settings] == ["fppo-lp", "ppo"]
    assert group_2.seeds == list(range(8, 16))
    assert resumed.decisions[0] == frozen_row
    assert resumed.decisions[1]["seeds"] == 16 and resumed.decisions[1]["final"]
    # The decisions are the rule's on the recorded scores, as one uninterrupted study makes them.
    merged = resumed.results["cartpole"]
    scores = [
        (run_scores(merged, v, "final"), run_scores(merged, "ppo", "final"))
        for v in ("frozen", "fppo-lp")
    ]
    expected = decide(scores, Design(8, 16))
    assert [row["decision"] for row in resumed.decisions] == [d.decision for d in expected]
    recorded = json.loads((output / "decisions.json").read_text())
    assert recorded["finished"] and recorded["comparisons"] == resumed.decisions
    assert [(g["group"], g["seeds"][0]) for g in recorded["groups"]] == [(1, 0), (2, 8)]

    # One curves.csv for the task, merged over its groups: its runs numbered once, not again
    # from 0 in each group's.
    whole = SweepResult.read(output / "cartpole")
    assert len(whole.runs) == 24 + 16 and whole.seeds == list(range(16))
    groups = [SweepResult.read(output / "cartpole" / f"group-{k}") for k in (1, 2)]
    np.testing.assert_array_equal(whole.metrics["average_return"], merged.metrics["average_return"])
    assert whole.runs == merge(groups).runs
    merged_curves = (output / "cartpole" / "curves.csv").read_bytes()

    again = fppo_jax.study("cartpole", candidates, "ppo", **settings)  # nothing left to train
    assert again.decisions == resumed.decisions
    assert sorted(p.name for p in (output / "cartpole").iterdir()) == [
        "curves.csv",
        "group-1",
        "group-2",
        "sweep.json",
    ]
    assert (output / "cartpole" / "curves.csv").read_bytes() == merged_curves
    report = (output / "report.md").read_text()
    assert "Secondary endpoint, auc" in report and "of the baseline's IQM" in report
    assert "| frozen | 8 | 0 | not reached | 0 | not reached |" in report  # never learns


def test_the_command_decides_at_the_first_look_and_refuses_a_changed_plan(tmp_path, capsys):
    output = tmp_path / "study"
    common = ["study", "--candidates", "own_surrogates:frozen", "--baseline", "ppo"]
    common += ["--tasks", "cartpole", "--group-size", "8", "--output", str(output), *FLAGS]
    common += ["--num-envs", "4", "--num-steps", "32", "--minibatches", "4", "--epochs", "2"]
    assert main([*common, "--max-seeds", "16"]) == 0
    out = capsys.readouterr().out
    assert "cartpole: frozen against ppo: worse with 8 seeds (z = -" in out
    assert "not finished" not in out
    assert not (output / "cartpole" / "group-2").exists()  # decided: no second group
    assert json.loads((output / "decisions.json").read_text())["finished"]

    assert main([*common, "--max-seeds", "32"]) == 2
    assert "planned with max_seeds = 16, not 32" in capsys.readouterr().err
    assert main([*common[:2], "ppo", *common[3:], "--max-seeds", "16"]) == 2
    assert "the baseline ppo is also a candidate" in capsys.readouterr().err
    # --groups 0 trains nothing: it decides on what is recorded, and reports it again.
    report = (output / "report.md").read_bytes()
    assert main([*common, "--max-seeds", "16", "--groups", "0"]) == 0
    assert "frozen against ppo: worse with 8 seeds" in capsys.readouterr().out
    assert (output / "report.md").read_bytes() == report
    # With its progress (no --quiet) the decision is said once, on stderr as it is made.
    shown = [flag for flag in common if flag != "--quiet"]
    assert main([*shown, "--max-seeds", "16", "--groups", "0"]) == 0
    said = capsys.readouterr()
    assert said.err.count("frozen against ppo: worse with 8 seeds") == 1
    assert "against" not in said.out and f"wrote {output}/plan.json" in said.out
    with pytest.raises(SystemExit) as refused:
        main([*common, "--max-seeds", "16", "--groups", "-1"])
    assert refused.value.code == 2
    assert "expected a count of looks, 0 or more, got '-1'" in capsys.readouterr().err


def test_a_study_decides_on_evaluations_when_its_plan_asks_for_them(tmp_path, capsys):
    output = tmp_path / "study"
    common = ["study", "--candidates", "own_surrogates:frozen", "--tasks", "cartpole"]
    common += ["--max-seeds", "8", "--group-size", "8", "--output", str(output), *FLAGS]
    common += ["--num-envs", "4", "--num-steps", "32", "--minibatches", "4", "--epochs", "2"]
    assert main([*common, "--endpoint", "eval"]) == 2  # nothing evaluates the runs
    assert "give eval_every (--eval-every)" in capsys.readouterr().err
    assert not output.exists()

    assert main([*common, "--endpoint", "eval", "--eval-every", "16", "--eval-episodes", "3"]) == 0
    plan = json.loads((output / "plan.json").read_text())
    assert (plan["primary_endpoint"], plan["secondary_endpoints"]) == ("eval", ["final", "auc"])
    assert (plan["settings"]["eval_every"], plan["settings"]["eval_episodes"]) == (16, 3)
    result = SweepResult.read(output / "cartpole" / "group-1")
    for variant in ("frozen", "ppo"):  # decided on each run's last evaluation
        runs = [
            i
            for i, run in enumerate(result.runs)
            if result.settings[run["setting"]]["variant"] == variant
        ]
        last = result.metrics["eval_return"][runs][:, -1]
        assert np.all(np.isfinite(last))
        np.testing.assert_array_equal(run_scores(result, variant, "eval"), last)
    report = (output / "report.md").read_text()
    assert "Primary endpoint, eval: tested; the decision column is the test's." in report
    assert "over the 1 comparison." in report  # frozen against ppo alone
    assert "Secondary endpoint, final" in report and "Secondary endpoint, auc" in report
    assert "Each run's best, max: reported, not tested" in report
    # Recorded runs without evaluations are not taken for a study that evaluates: trained.
    shape = [*FLAGS, "--num-envs", "4", "--num-steps", "32", "--minibatches", "4", "--epochs", "2"]
    pool, again = tmp_path / "recorded", tmp_path / "again"
    assert main(["sweep", "--variant", "ppo", "--seeds", "8", "--output", str(pool), *shape]) == 0
    evaluated = [*common[:5], "--max-seeds", "8", "--group-size", "8", "--output", str(again)]
    evaluated += [*shape, "--endpoint", "eval", "--eval-every", "16", "--eval-episodes", "3"]
    assert main([*evaluated, "--reuse", str(pool)]) == 0
    groups = json.loads((again / "decisions.json").read_text())["groups"]
    assert [g.get("reused") for g in groups] == [None] and len(groups[0]["commit"]) == 40
    capsys.readouterr()
    # The evaluations are part of the plan: another count of episodes is another study.
    assert main([*common, "--endpoint", "eval", "--eval-every", "16"]) == 2
    assert "planned with settings.eval_episodes = 3, not 10" in capsys.readouterr().err


def test_no_group_writes_the_plan_alone_and_a_bad_setting_writes_nothing(tmp_path, tiny):
    output = tmp_path / "study"
    with pytest.raises(ValueError, match="one setting per variant: give alpha one value each"):
        fppo_jax.study("cartpole", "fppo-lp", output=output, alpha=[1.1, 1.3], **tiny)
    with pytest.raises(ValueError, match="no variant of the grid \\(spo, ppo\\) takes k"):
        fppo_jax.study("cartpole", "spo", output=output, k=0.3, **tiny)
    with pytest.raises(ValueError, match="unknown setting num_envz"):
        fppo_jax.study("cartpole", "spo", output=output, num_envz=3)
    assert not output.exists()  # refused before the plan was written

    planned = fppo_jax.study(
        ["cartpole", "acrobot"], ["spo", "dpo"], output=output, groups=np.int64(0)
    )
    plan = json.loads((output / "plan.json").read_text())
    assert len(plan["comparisons"]) == 4 and plan["looks"] == [5, 10, 15, 20, 25, 30]
    # Holm's first level, 0.05 / 4, spent over six looks: the last boundary above the one of a
    # single look at that level (2.498).
    assert plan["boundaries_if_none_decided"][-1] == pytest.approx(2.551, abs=1e-3)
    assert not planned.finished and not planned.results
    assert [row["seeds"] for row in planned.decisions] == [0, 0, 0, 0]
    assert sorted(p.name for p in output.iterdir()) == [
        ".lock",
        "decisions.json",
        "plan.json",
        "report.md",
    ]
    assert "No group recorded yet." in (output / "report.md").read_text()


REPOSITORY = Path(__file__).resolve().parent.parent
RECORDED = REPOSITORY / "experiments" / "results" / "study"


def test_the_report_aggregates_over_tasks_the_recorded_seed_study_unchanged(tmp_path):
    tasks = ["hopper", "swimmer"]
    done = fppo_jax.study(
        tasks,
        ["fppo-lp", "fppo-qp"],
        "ppo",
        output=tmp_path,
        reuse=[RECORDED / task for task in tasks],
        groups=0,
        max_seeds=20,
        group_size=20,
        backend="native",
        progress=False,
    )
    assert done.finished and not list(tmp_path.glob("*/group-*"))  # every run taken, none trained
    report = (tmp_path / "report.md").read_text()
    assert "## Across the 2 tasks" in report
    means = []
    for endpoint in ("final", "auc"):  # the primary, then the secondary
        pairs = [
            (
                run_scores(done.results[t], "fppo-qp", endpoint),
                run_scores(done.results[t], "ppo", endpoint),
            )
            for t in tasks
        ]
        means.append("{:.2f} [{:.2f}, {:.2f}]".format(*statistics.aggregate_improvement(pairs)))
    assert f"| fppo-qp | {means[0]} | {means[1]} | " in report
    assert (tmp_path / "profiles.png").read_bytes().startswith(b"\x89PNG")


def test_a_study_of_identical_settings_is_decided_equivalent_within_its_margin(tmp_path, tiny):
    # my-ppo is PPO's objective written again: the same runs, P(my-ppo > ppo) = 1/2. One look
    # of 16 seeds a side, margin 0.2: the interval 1/2 ± 1.645·se (se = 0.105 at its floor)
    # fits within 1/2 ± 0.2.
    output = tmp_path / "study"
    settings = {**tiny, **BUDGET, "output": output, "max_seeds": 16, "group_size": 16}
    done = fppo_jax.study("cartpole", my_ppo, "ppo", margin=0.2, **settings)
    assert done.finished
    (row,) = done.decisions
    assert (row["decision"], row["seeds"]) == ("equivalent", 16)
    low, high = row["interval"]
    assert 0.3 <= low < 0.5 < high <= 0.7 and "within 1/2 ± 0.2 at look 1" in row["reason"]
    plan = json.loads((output / "plan.json").read_text())
    assert plan["margin"] == 0.2 and plan["rule"]["id"] == "sequential-mann-whitney-holm"
    recorded = json.loads((output / "decisions.json").read_text())
    assert recorded["margin"] == 0.2 and recorded["comparisons"] == done.decisions
    report = (output / "report.md").read_text()
    assert "| my-ppo | equivalent | 16 | P = 0.50, its repeated CI" in report
    assert "Equivalence margin 0.2: `equivalent` means P(candidate > ppo) shown within" in report
    # Without the margin, another plan: refused, naming it.
    plain = {k: v for k, v in settings.items() if k != "output"}
    with pytest.raises(ValueError, match=r"planned with margin = 0\.2, not none"):
        fppo_jax.study("cartpole", my_ppo, "ppo", output=output, **plain)


def test_the_command_states_what_each_look_can_decide_and_records_the_margin(tmp_path, capsys):
    output = tmp_path / "study"
    common = ["study", "--candidates", "spo,dpo", "--tasks", "cartpole", "--output", str(output)]
    # The study prints its plan on stderr with its progress; told to be quiet, the command
    # prints it on stdout instead: once either way.
    assert main([*common, "--margin", "0.2", "--groups", "0"]) == 0
    captured = capsys.readouterr()
    shown = [line[len("study: ") :] for line in captured.err.splitlines()]
    assert "plan:" not in captured.out and shown[0].startswith("plan: 6 looks")
    assert main([*common, "--margin", "0.2", "--groups", "0", "--quiet"]) == 0
    captured = capsys.readouterr()
    out = captured.out.splitlines()
    assert out[: len(shown)] == shown and "plan:" not in captured.err
    assert out[0].startswith("plan: 6 looks; better or worse when |z| reaches the look's")
    assert "(level 0.025 while no comparison is decided)" in out[0]
    assert out[1] == (
        "  look 1, 5 seeds per setting: ±6.01 (warning: cannot decide, |z| is at most 2.61 "
        "with 5 seeds; reaching ±6.01 takes at least 25 seeds per setting)"
    )
    assert out[2].endswith(
        "±4.17 (warning: cannot decide, |z| is at most 3.78 with 10 seeds; reaching ±4.17 "
        "takes at least 13 seeds per setting)"
    )
    assert out[3] == "  look 3, 15 seeds per setting: ±3.35"
    assert out[6] == "  look 6, 30 seeds per setting: ±2.31"
    assert out[7] == (
        "  equivalent (P(candidate > baseline) within 1/2 ± 0.2): reachable from 25 seeds per "
        "setting"
    )
    assert json.loads((output / "plan.json").read_text())["margin"] == 0.2
    assert json.loads((output / "decisions.json").read_text())["margin"] == 0.2
    assert main([*common, "--groups", "0"]) == 2
    assert "planned with margin = 0.2, not none" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main([*common, "--margin", "0.5"])
    assert (
        "the equivalence margin (a distance from 1/2 of P(candidate > baseline)) must be in "
        "(0, 0.5), got 0.5" in capsys.readouterr().err
    )


def test_a_study_recorded_before_margins_reads_and_decides_as_it_did(tmp_path, monkeypatch):
    # The library's study of the seed study's classic tasks, recorded with a plan that has no
    # margin: asked again (nothing trained), it accepts its plan and writes the same decisions;
    # the plan's absent margin is no margin, and a margin now is another plan.
    recorded = REPOSITORY / "experiments" / "results" / "study-command" / "classic"
    output = tmp_path / "classic"
    shutil.copytree(recorded, output)
    monkeypatch.chdir(REPOSITORY)  # the plan names the parts' folder from here
    tasks = ["cartpole", "acrobot", "mountaincar"]
    done = fppo_jax.study(
        tasks,
        ["fppo-lp", "fppo-qp"],
        "ppo",
        output=output,
        reuse="experiments/results/study",
        groups=0,
        max_seeds=50,
        group_size=50,
        progress=False,
    )
    assert done.finished
    for name in ("plan.json", "decisions.json"):
        assert (output / name).read_bytes() == (recorded / name).read_bytes()
    assert "Equivalence margin" not in (output / "report.md").read_text()
    plan = json.loads((recorded / "plan.json").read_text())
    with pytest.raises(ValueError, match=r"planned with margin = none, not 0\.2"):
        check_plan(
            output,
            {**plan, "margin": 0.2, "equivalence_test": "two one-sided tests"},
            "a study",
            "plan.json",
        )
