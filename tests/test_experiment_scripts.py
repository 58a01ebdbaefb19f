"""experiments/: what the scripts advise when they refuse, and their helpers on every space."""

import importlib
import json
import subprocess
import sys
from pathlib import Path

import gymnasium
import numpy as np

EXPERIMENTS = Path(__file__).resolve().parent.parent / "experiments"


def test_table1_classic_advises_its_own_flags_when_a_result_is_recorded(tmp_path):
    recorded = tmp_path / "table.md"
    recorded.write_text("recorded\n")
    done = subprocess.run(
        [sys.executable, str(EXPERIMENTS / "table1_classic.py"), "--output", str(recorded)],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=EXPERIMENTS,
    )
    assert done.returncode != 0 and "is already recorded" in done.stderr
    assert "--output FILE and --curves DIR to record elsewhere" in done.stderr
    assert "--results" not in done.stderr
    assert recorded.read_text() == "recorded\n"


def test_bench_gymnasium_draws_random_actions_of_discrete_and_box_spaces(monkeypatch):
    monkeypatch.syspath_prepend(str(EXPERIMENTS))  # the scripts import their common.py
    bench_gymnasium = importlib.import_module("bench_gymnasium")
    steps = 8 * bench_gymnasium.NUM_ENVS
    discrete = bench_gymnasium.random_actions(gymnasium.spaces.Discrete(3, start=-1), steps)
    assert discrete.shape == (8, bench_gymnasium.NUM_ENVS)
    assert set(np.unique(discrete)) == {-1, 0, 1}
    box = gymnasium.spaces.Box(-2.0, 2.0, (2,), np.float32)
    actions = bench_gymnasium.random_actions(box, steps)
    assert actions.shape == (8, bench_gymnasium.NUM_ENVS, 2) and actions.dtype == np.float32
    assert (np.abs(actions) <= 2).all()
    env = gymnasium.make("CartPole-v1")
    env.reset(seed=0)
    for action in bench_gymnasium.random_actions(env.action_space, steps)[:, 0]:
        env.step(action)  # the actions a Discrete environment takes
    assert bench_gymnasium.gymnasium_alone("CartPole-v1", steps) > 0


def _planned_verdict(*args):
    return subprocess.run(
        [sys.executable, str(EXPERIMENTS / "planned_verdict.py"), *map(str, args)],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=EXPERIMENTS,
    )


def test_a_planned_verdict_waits_for_every_comparison_naming_what_is_missing(tmp_path):
    report = tmp_path / "verdict.md"
    done = _planned_verdict("plans/spo-dpo.json", "--results", tmp_path, "--output", report)
    assert done.returncode == 1 and not report.exists()
    assert "no verdict yet" in done.stderr
    assert "cartpole: ppo 0 of 50, spo 0 of 50, dpo 0 of 50 seeds" in done.stderr
    assert "ant: ppo 0 of 20, spo 0 of 20, dpo 0 of 20 seeds" in done.stderr


def test_a_planned_verdict_tests_the_family_on_the_recorded_parts(tmp_path):
    plan = json.loads((EXPERIMENTS / "plans" / "spo-dpo.json").read_text())
    plan["tasks"] = ["cartpole", "reacher"]  # recorded in full
    (tmp_path / "two.json").write_text(json.dumps(plan))
    report = tmp_path / "verdict.md"
    done = _planned_verdict(tmp_path / "two.json", "--output", report)
    assert done.returncode == 0, done.stderr
    rows = [line.split(" | ") for line in report.read_text().splitlines()]
    rows = [row for row in rows if len(row) > 2 and row[1] == "spo"]
    assert [row[0] for row in rows] == ["| cartpole", "| reacher"]
    holm = [float(row[6]) for row in rows]
    raw = [float(row[5]) for row in rows]
    assert all(h >= p for h, p in zip(holm, raw, strict=True))  # adjusted over the family
