"""experiments/studies/study.py and verdict.py: parts recorded whole, never replaced unasked,
merged into the verdict; all in a temporary directory."""

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
from helpers import run_script

from fppo_jax import SweepResult, merge
from fppo_jax.stats import statistics

EXPERIMENTS = Path(__file__).resolve().parent.parent / "experiments"
# Six runs per compiled call in every test's sweeps of the paper's shape: one program for all.
SHARED = ["--chunk", "6"]


def _run(script: str, *args: str) -> subprocess.CompletedProcess:
    return run_script(EXPERIMENTS / "studies" / script, *args, cwd=EXPERIMENTS)


def test_parts_are_recorded_refused_twice_and_merged_into_the_verdict(tmp_path):
    tiny = ["--task", "cartpole", "--steps", "4096", *SHARED, "--results", str(tmp_path)]
    for seeds in ("0:3", "3:6"):
        done = _run("study.py", *tiny, "--seeds", seeds, "--variants", "ppo", "fppo-lp")
        assert done.returncode == 0, done.stdout + done.stderr
    parts = tmp_path / "study" / "cartpole" / "paper"
    assert sorted(p.name for p in parts.iterdir()) == [
        "seeds-0-2_ppo+fppo-lp",
        "seeds-3-5_ppo+fppo-lp",
    ]
    record = json.loads((parts / "seeds-3-5_ppo+fppo-lp" / "run.json").read_text())
    assert record["protocol"] == "paper" and "--seeds 3:6" in record["command"]
    curves = (parts / "seeds-0-2_ppo+fppo-lp" / "curves.csv").read_bytes()

    again = _run("study.py", *tiny, "--seeds", "0:3", "--variants", "ppo", "fppo-lp")
    assert again.returncode != 0 and "is already recorded" in again.stderr
    assert (parts / "seeds-0-2_ppo+fppo-lp" / "curves.csv").read_bytes() == curves

    overlap = _run("study.py", *tiny, "--seeds", "2:4", "--variants", "fppo-lp", "--force")
    assert overlap.returncode != 0 and "holds these runs already" in overlap.stderr
    assert "seeds-0-2_ppo+fppo-lp (fppo-lp at seeds 2)" in overlap.stderr
    assert "seeds-3-5_ppo+fppo-lp (fppo-lp at seeds 3)" in overlap.stderr
    assert sorted(p.name for p in parts.iterdir()) == [
        "seeds-0-2_ppo+fppo-lp",
        "seeds-3-5_ppo+fppo-lp",
    ]

    # Another grid, of the same shape (6 runs): the program compiled for the first is reused.
    other = _run("study.py", *tiny, "--seeds", "0:3", "--variants", "tr-ppo", "ppo-rb")
    assert other.returncode == 0, other.stdout + other.stderr

    verdict = _run("verdict.py", "--results", str(tmp_path))
    assert verdict.returncode == 0, verdict.stdout + verdict.stderr
    text = (tmp_path / "study.md").read_text()
    assert "### cartpole, paper protocol" in text
    assert "3 parts, 18 runs of 4,096 env steps" in text
    assert "| fppo-lp α=1.3 | 0." in text  # its probability of improvement over ppo
    tr_ppo = [line.split(" | ") for line in text.splitlines() if line.startswith("| tr-ppo")]
    assert tr_ppo[0][1] == "3" and tr_ppo[1][3] == "–"  # 3 runs; exploratory, no Holm p
    assert "Exploratory, where time allowed (tr-ppo and ppo-rb at 10 seeds" in text
    # One of the paper protocol's 18 planned comparisons recorded: Holm multiplies its p by 18.
    merged = merge([SweepResult.read(d) for d in sorted(parts.iterdir())])
    final, variants = merged.scores("final"), [s["variant"] for s in merged.settings]
    p = statistics.improvement_test(final[variants.index("fppo-lp")], final[variants.index("ppo")])
    assert "the Holm-adjusted p over the 18 of the paper protocol" in text
    row = next(line for line in text.splitlines() if line.startswith("| fppo-lp α=1.3 | 0."))
    assert row.split(" | ")[3] == f"{min(1.0, 18 * p):.2f}"
    assert "cartpole (paper): fppo-lp 6 of 50 seeds" in text
    assert "hopper (paper): not started" in text
    assert (tmp_path / "study" / "curves_paper.png").stat().st_size > 0
    # The body is the library's report of each family, which takes a group only whole: 6 of 50
    # seeds are none, and nothing is trained.
    classic = tmp_path / "study-command" / "classic"
    library = (classic / "report.md").read_text().splitlines()[1:]
    assert "\n".join(f"##{line}" if line.startswith("#") else line for line in library) in text
    assert "#### cartpole\n\nNo group recorded yet." in text
    assert not list(classic.glob("*/group-*"))


def test_a_dose_response_is_one_sweep_whose_controls_train_as_ppo_and_its_report(tmp_path):
    tiny = ["--task", "cartpole", "--steps", "4096", *SHARED, "--results", str(tmp_path)]
    report = ["--results", str(tmp_path), "--tasks", "cartpole"]
    # Two parts of the same shape (60 runs), so that the second compiles nothing.
    done = _run("study.py", *tiny, "--seeds", "0:5", "--plan", "plans/dose-response.json")
    assert done.returncode == 0, done.stdout + done.stderr
    part = tmp_path / "dose_response" / "cartpole" / "paper" / "seeds-0-4_dose-response"
    result = SweepResult.read(part)
    assert len(result.settings) == 12 and len(result.runs) == 60
    index = {tuple(sorted(s.items())): i for i, s in enumerate(result.settings)}
    ppo = result.setting_metrics(index[(("variant", "ppo"),)])
    for control in ((("alpha", 1.0), ("variant", "fppo-lp")), (("k", 0.0), ("variant", "fppo-qp"))):
        metrics = result.setting_metrics(index[control])
        for name in ppo:  # the same objective in the same program: bit for bit
            np.testing.assert_array_equal(metrics[name], ppo[name], err_msg=f"{control} {name}")
    strongest = result.setting_metrics(index[(("k", 2.0), ("variant", "fppo-qp"))])
    assert not np.array_equal(strongest["average_return"], ppo["average_return"])

    early = _run("dose_response.py", *report)  # the planned test is over 10 seeds of each dose
    assert early.returncode == 1 and "cartpole: ppo 5, fppo-lp α=1 5," in early.stderr
    assert not (tmp_path / "dose_response.md").exists()

    more = _run("study.py", *tiny, "--seeds", "5:10", "--plan", "plans/dose-response.json")
    assert more.returncode == 0, more.stdout + more.stderr
    study = tmp_path / "study" / "cartpole" / "paper"
    study.mkdir(parents=True)  # stands in for the seed study's PPO runs: the sweep's own
    shutil.copytree(part, study / part.name)
    done = _run("dose_response.py", *report)
    assert done.returncode == 0, done.stdout + done.stderr
    text = (tmp_path / "dose_response.md").read_text()
    assert (
        "fppo-lp at α = 1: identical to the sweep's PPO run on every recorded metric in 10 of 10"
        in text
    )
    assert "fppo-qp at k = 0: identical" in text and "in 10 of 10 seeds" in text
    assert "the same learning curve in 5 of 5 seeds" in text  # the seeds the stand-in holds
    merged = merge([SweepResult.read(d) for d in sorted(part.parent.iterdir())])
    final = merged.scores("final")
    doses = {
        "fppo-lp": ("alpha", [1.0, 1.1, 1.3, 1.5, 2.0, 3.0]),
        "fppo-qp": ("k", [0, 0.2, 0.4, 1, 2]),
    }
    groups = {
        v: [final[merged.settings.index({"variant": v, name: d})] for d in values]
        for v, (name, values) in doses.items()
    }
    p = [statistics.trend_test(doses[v][1], groups[v]) for v in doses]
    holm = statistics.holm(p)  # the family here: cartpole's 2 trends
    for (variant, (_, values)), p_raw, p_holm in zip(doses.items(), p, holm, strict=True):
        rho = statistics.dose_trend(values, groups[variant])[0]
        row = next(
            line for line in text.splitlines() if line.startswith(f"| cartpole | {variant} |")
        )
        cells = row.split(" | ")
        assert cells[3].startswith(f"{rho:.2f} [") and cells[4:6] == [
            f"{p_raw:.2f}",  # to the precision its Monte Carlo error allows
            f"{p_holm:.2f}",
        ]
    assert text.count("| fppo-qp k=") == 5 and "| fppo-lp α=3 | 10 |" in text
    assert (tmp_path / "dose_response" / "dose_response.png").stat().st_size > 0
    again = _run("dose_response.py", *report)
    assert again.returncode != 0 and "is already recorded" in again.stderr


def test_a_planned_part_trains_the_plan_s_settings_and_is_compared_with_the_study(tmp_path):
    tiny = ["--task", "cartpole", "--steps", "4096", *SHARED, "--results", str(tmp_path)]
    done = _run("study.py", *tiny, "--seeds", "0:50", "--plan", "plans/baseline-shape.json")
    assert done.returncode == 0, done.stdout + done.stderr
    part = tmp_path / "baseline_shape" / "cartpole" / "paper" / "seeds-0-49_baseline-shape"
    result = SweepResult.read(part)
    assert [s["variant"] for s in result.settings] == ["ppo"]
    assert (result.config["num_envs"], result.config["num_steps"]) == (1, 2048)
    assert (
        "--plan plans/baseline-shape.json" in json.loads((part / "run.json").read_text())["command"]
    )

    plan = json.loads((EXPERIMENTS / "plans" / "baseline-shape.json").read_text())
    plan["tasks"] = ["cartpole"]  # 50 seeds planned on a classic task
    (tmp_path / "baseline-shape.json").write_text(json.dumps(plan))
    verdict = [str(tmp_path / "baseline-shape.json"), "--results", str(tmp_path)]
    early = _run("planned_verdict.py", *verdict, "--output", str(tmp_path / "v.md"))
    assert early.returncode == 1 and "cartpole: ppo 8×256 0 of 50 seeds" in early.stderr

    baseline = _run("study.py", *tiny, "--seeds", "0:50", "--variants", "ppo")
    assert baseline.returncode == 0, baseline.stdout + baseline.stderr
    done = _run("planned_verdict.py", *verdict, "--output", str(tmp_path / "v.md"))
    assert done.returncode == 0, done.stdout + done.stderr
    row = next(r for r in (tmp_path / "v.md").read_text().splitlines() if r.startswith("| cart"))
    ours = SweepResult.read(tmp_path / "study" / "cartpole" / "paper" / "seeds-0-49_ppo")
    wide, long = ours.scores("final")[0], result.scores("final")[0]
    p = statistics.improvement_test(long, wide)
    assert row.startswith(f"| cartpole | ppo 1×2048 | {statistics.iqm(long):.1f} [")
    shown = f"{p:.1e}" if p < 0.001 else f"{p:.3f}"  # one comparison: Holm's p is the p
    assert f"| {statistics.iqm(wide):.1f} | " in row and f"| {shown} | {shown} |" in row

    plan["baseline"]["num_envs"] = 4  # a baseline the recorded runs are not
    (tmp_path / "baseline-shape.json").write_text(json.dumps(plan))
    wrong = _run("planned_verdict.py", *verdict, "--output", str(tmp_path / "w.md"))
    assert wrong.returncode != 0 and "recorded runs are 8×256" in wrong.stderr
    assert "baseline is 4×256" in wrong.stderr and not (tmp_path / "w.md").exists()
