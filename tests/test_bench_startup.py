"""experiments/bench_startup.py: its smoke run measures every arm and writes its table into a
temporary directory, never into the recorded results."""

import re
import subprocess
import sys
from pathlib import Path

import pytest
from test_gpu_suite import recorded

SCRIPT = Path(__file__).resolve().parent.parent / "experiments" / "bench_startup.py"


def bench(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(SCRIPT), *args], capture_output=True, text=True)


# Every arm in fresh processes, about a minute on 2 cores: with -m slow.
@pytest.mark.slow
def test_the_smoke_run_measures_every_arm_into_a_temporary_directory():
    before = recorded()
    done = bench("--smoke")
    assert done.returncode == 0, done.stdout + done.stderr
    assert recorded() == before
    written = Path(done.stdout.split("wrote ")[-1].strip())
    assert written.parent.name.startswith("fppo-bench-startup-smoke-")
    table = written.read_text()
    assert "- Command: `python experiments/bench_startup.py --smoke`" in table
    assert "- Machine: " in table and "- Load average (1 min)" in table
    for arm in ("import jax", "import fppo_jax", "from fppo_jax import train", "fppo-jax --help"):
        assert re.search(rf"\| `{arm}` \| [\d.]+ \| [+-][\d.]+ \|", table), arm
    for run in ("cold", "warm", "cache off"):
        assert re.search(rf"\| {run} \| [\d.]+ \| [\d.]+ s \| [\d.]+ \|", table), run


def test_the_smoke_run_refuses_the_recorded_results():
    into = bench("--smoke", "--results", str(SCRIPT.parent / "results"))
    assert into.returncode != 0 and "never writes into the recorded results" in into.stderr
