"""experiments/: what the scripts advise when they refuse, and their helpers on every space."""

import importlib
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
