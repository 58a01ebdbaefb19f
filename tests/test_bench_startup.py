"""experiments/benchmarks/bench_startup.py: its smoke run measures every arm and writes its table
into a temporary directory, never into the recorded results."""

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest
from test_gpu_suite import recorded

EXPERIMENTS = Path(__file__).resolve().parent.parent / "experiments"
SCRIPT = EXPERIMENTS / "benchmarks" / "bench_startup.py"


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
    assert "- Command: `python experiments/benchmarks/bench_startup.py --smoke`" in table
    assert "- Machine: " in table and "- Load average (1 min)" in table
    for arm in ("import jax", "import fppo_jax", "from fppo_jax import train", "fppo-jax --help"):
        assert re.search(rf"\| `{arm}` \| [\d.]+ \| [+-][\d.]+ \|", table), arm
    for run in ("cold", "warm", "another budget", "cache off"):
        assert re.search(rf"\| {run} \| [\d.]+ \| [\d.]+ s \| [\d.]+ \|", table), run


def test_the_smoke_run_refuses_the_recorded_results():
    into = bench("--smoke", "--results", str(EXPERIMENTS / "results"))
    assert into.returncode != 0 and "never writes into the recorded results" in into.stderr


def test_the_benchmark_s_own_load_does_not_count_as_other_work(monkeypatch):
    monkeypatch.syspath_prepend(str(EXPERIMENTS))  # as the script puts it
    spec = importlib.util.spec_from_file_location("bench_startup", SCRIPT)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    assert not script.shared_machine(0.6, 1.1, cores=2)  # quiet: the load after is its own
    assert script.shared_machine(5.1, 4.3, cores=2)  # busy before and after
    assert script.shared_machine(0.2, 2.5, cores=2)  # other work came while it ran
    assert not script.shared_machine(0.2, 2.5, cores=8)
