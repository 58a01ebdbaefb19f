"""experiments/gpu_suite.py: every kind of part run tiny on the CPU (--smoke), and what it
refuses."""

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

EXPERIMENTS = Path(__file__).resolve().parent.parent / "experiments"
SUITE = EXPERIMENTS / "gpu_suite.py"


def recorded() -> dict[str, str]:
    """Every file of experiments/results and its SHA-256."""
    root = EXPERIMENTS / "results"
    return {
        str(path.relative_to(root)): hashlib.sha256(path.read_bytes()).hexdigest()
        for path in sorted(root.rglob("*"))
        if path.is_file()
    }


def _suite(*args: str, tmp: Path | None = None) -> subprocess.CompletedProcess:
    """The suite, run with `tmp` as its temporary directory where given: a smoke run's output
    goes there, and pytest removes it."""
    return subprocess.run(
        [sys.executable, str(SUITE), *args],
        capture_output=True,
        text=True,
        env={**os.environ, **({"TMPDIR": str(tmp)} if tmp else {})},
    )


def test_a_smoke_part_runs_and_is_recorded_in_a_temporary_directory(tmp_path):
    before = recorded()
    # No --results: a temporary directory.
    done = _suite("--smoke", "--parts", "table1-reacher", tmp=tmp_path)
    assert done.returncode == 0, done.stdout + done.stderr
    assert recorded() == before
    written = Path(done.stdout.split("wrote ")[-1].strip()).parent
    assert written.parent == tmp_path and written.name.startswith("fppo-gpu-suite-smoke-")
    record = json.loads((written / "gpu_suite_cpu.json").read_text())
    assert list(record) == ["table1-reacher"] and record["table1-reacher"]["status"] == "done"
    table = (written / "table1_mujoco_native.md").read_text()
    assert "Tasks done: reacher" in table and "ppo" in table and "fppo-lp" in table
    assert "| table1-reacher | done |" in (written / "gpu_suite_cpu.md").read_text()


@pytest.mark.slow  # about four minutes on a 2-core CPU: MJX and Brax's trainer compile there
def test_the_smoke_suite_runs_every_kind_of_part_into_a_temporary_directory(tmp_path):
    before = recorded()
    done = _suite("--smoke", tmp=tmp_path)  # no --results: a temporary directory, never the record
    assert done.returncode == 0, done.stdout + done.stderr
    assert recorded() == before
    written = Path(done.stdout.split("wrote ")[-1].strip()).parent
    assert written.parent == tmp_path and written.name.startswith("fppo-gpu-suite-smoke-")
    record = json.loads((written / "gpu_suite_cpu.json").read_text())
    assert list(record) == ["throughput-reacher", "table1-reacher", "ablation-reacher"]
    assert all(part["status"] == "done" for part in record.values())
    bench = (written / "bench_mujoco_reacher_16envs_cpu.md").read_text()
    for row in ("MJX (a) environment alone", "MJX (b) fppo-jax", "MJX (c) Brax `ppo.train`"):
        assert row in bench
    table = (written / "table1_mujoco_native.md").read_text()
    assert "Tasks done: reacher" in table and "ppo" in table and "fppo-lp" in table
    assert (written / "table1_mujoco_native" / "reacher" / "curves.csv").exists()
    ablation = written / "ablation_native"
    assert "Parts done: reacher alpha, reacher k;" in (ablation / "ablation.md").read_text()
    for part in ("alpha", "k"):
        assert (ablation / "reacher" / part / "curves.csv").exists()
    assert (ablation / "reacher.png").stat().st_size > 0
    assert "| table1-reacher | done |" in (written / "gpu_suite_cpu.md").read_text()


def test_without_a_gpu_the_full_suite_is_refused_and_unknown_parts_named(tmp_path):
    refused = _suite("--results", str(tmp_path))
    assert refused.returncode != 0 and "JAX sees no GPU here" in refused.stderr
    unknown = _suite("--parts", "table1-pong")
    assert unknown.returncode != 0 and "unknown part table1-pong; parts: " in unknown.stderr
    assert not list(tmp_path.iterdir())


def test_smoke_runs_never_write_into_the_record_and_scripts_refuse_to_replace_it(tmp_path):
    before = recorded()
    into = _suite("--smoke", "--results", str(EXPERIMENTS / "results" / "smoke"))
    assert into.returncode != 0 and "never writes into the recorded results" in into.stderr
    for script, *args in [
        ("studies/study.py", "--task", "hopper", "--seeds", "0:5"),
        ("paper/escape_speed.py", "--tasks", "cartpole", "--seeds", "1"),
        ("benchmarks/bench_logging.py", "--steps", "4096"),
    ]:
        done = subprocess.run(
            [sys.executable, str(EXPERIMENTS / script), *args],
            capture_output=True,
            text=True,
        )
        assert done.returncode != 0, script
        assert "is already recorded: pass --force to replace it, or --results DIR" in done.stderr
    assert recorded() == before
