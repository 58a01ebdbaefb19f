import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import jax
import numpy as np
import pytest
from distributed_workers import SMALL, flat

import fppo_jax
from fppo_jax.cli import main

WORKERS = Path(__file__).parent / "distributed_workers.py"


def run_worker(mode: str, out: Path, **env: str) -> subprocess.Popen:
    variables = {**os.environ, **env}
    return subprocess.Popen(
        [sys.executable, str(WORKERS), mode, str(out)],
        env=variables,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )


def finish(worker: subprocess.Popen) -> None:
    output, _ = worker.communicate()
    assert worker.returncode == 0, output[-3000:]


@pytest.fixture(scope="module")
def four_devices(tmp_path_factory) -> dict[str, np.ndarray]:
    out = tmp_path_factory.mktemp("devices") / "results.npz"
    flags = "--xla_force_host_platform_device_count=4"
    finish(run_worker("devices", out, XLA_FLAGS=flags))
    return dict(np.load(out))


def test_four_devices_learn_as_one_does(four_devices):
    r = four_devices
    assert "spec=P('data',)" in str(r["train4_obs_sharding"])  # environments split
    assert "'data': 4" in str(r["train4_obs_sharding"])
    # Not bit for bit: the batch means (gradient, statistics) are summed in another order when
    # each device holds a quarter of the batch. Within float32 rounding otherwise.
    np.testing.assert_allclose(r["train4_loss"], r["train1_loss"], rtol=1e-4, atol=1e-6)
    np.testing.assert_allclose(r["train4_return"], r["train1_return"], rtol=1e-5)
    params = sorted(k for k in r if k.startswith("train1_param"))
    for key in params:
        np.testing.assert_allclose(r[key.replace("train1", "train4")], r[key], rtol=1e-4, atol=1e-6)


@pytest.mark.parametrize("sharded", ["sweep4", "sweep2x2"])
def test_a_sharded_sweep_equals_the_unsharded_one(four_devices, sharded):
    r = four_devices
    # 6 runs: padded to 8 per call over 4 devices, or to 6 over 2 (each run on 2 devices).
    assert int(r[f"{sharded}_runs_per_call"]) == {"sweep4": 8, "sweep2x2": 6}[sharded]
    for metric in fppo_jax.METRICS:
        a, b = r[f"sweep1_{metric}"], r[f"{sharded}_{metric}"]
        assert a.shape == b.shape == (6, 4)
        np.testing.assert_allclose(b, a, rtol=1e-4, atol=1e-6, err_msg=metric)


def test_bad_device_counts_are_refused_with_the_reason(four_devices):
    errors = [str(e) for e in four_devices["errors"]]
    assert errors[0] == "devices=5, but JAX sees 4 cpu devices"
    assert errors[1] == "num_envs (8) must be divisible by the devices each run is split over (3)"
    assert errors[2] == "data_parallel must divide the devices (4), got 3"


def test_more_devices_than_there_are_is_an_error_here_too(capsys):
    count = len(jax.devices())
    with pytest.raises(ValueError, match=f"devices={count + 1}, but JAX sees {count} "):
        fppo_jax.train("cartpole", total_steps=4096, devices=count + 1)
    assert main(["train", "--devices", str(count + 1), "--steps", "4096"]) == 2
    assert f"but JAX sees {count}" in capsys.readouterr().err


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def train_in_two_processes(where: Path, **env: str) -> list[subprocess.Popen]:
    """Two processes of one jax.distributed group training one run (see
    distributed_workers.process), writing where/process0.npz and where/process1.npz."""
    where.mkdir(parents=True, exist_ok=True)
    group = {
        "JAX_COORDINATOR_ADDRESS": f"127.0.0.1:{free_port()}",
        "JAX_NUM_PROCESSES": "2",
        "XLA_FLAGS": "--xla_force_host_platform_device_count=1",
    }
    return [
        run_worker("process", where / f"process{i}.npz", JAX_PROCESS_ID=str(i), **group, **env)
        for i in range(2)
    ]


def results_of(where: Path, workers: list[subprocess.Popen]) -> list[dict[str, np.ndarray]]:
    for worker in workers:
        finish(worker)
    return [dict(np.load(where / f"process{i}.npz")) for i in range(2)]


def killed_then_resumed(tmp_path: Path) -> list[dict[str, np.ndarray]]:
    """Two processes checkpointing every update, both killed after update 3, then two new
    ones resuming from the checkpoints to the end."""
    checkpoints = str(tmp_path / "checkpoints")
    killed = train_in_two_processes(tmp_path / "killed", CHECKPOINTS=checkpoints, KILL_AT="3")
    for worker in killed:
        output, _ = worker.communicate()
        assert worker.returncode != 0, output[-3000:]  # killed, not finished
    steps = sorted(int(p.name) for p in Path(checkpoints).iterdir() if p.name.isdigit())
    assert steps and steps[-1] >= 2, steps  # one writer: process 0's checkpoints, complete
    resumed = train_in_two_processes(tmp_path / "resumed", CHECKPOINTS=checkpoints)
    return results_of(tmp_path / "resumed", resumed)


# Over a minute on 2 cores, with -m slow; the SIGTERM test below resumes two processes from
# their checkpoints in the default run.
@pytest.mark.slow
def test_two_processes_killed_resume_from_checkpoints_to_identical_parameters(tmp_path):
    first, second = killed_then_resumed(tmp_path)
    assert (int(first["process"]), int(second["process"])) == (0, 1)
    assert int(first["devices"]) == int(second["devices"]) == 2  # one per process
    assert int(first["resumed_from"]) == int(second["resumed_from"]) >= 2
    assert first.keys() == second.keys()
    for key in first:
        if key != "process":
            np.testing.assert_array_equal(first[key], second[key], err_msg=key)
    # And the same learning as one process on one device, to float32 rounding.
    alone = fppo_jax.train("cartpole", "fppo-lp", total_steps=256 * 6, **SMALL)
    np.testing.assert_allclose(first["policy_loss"], alone.metrics["policy_loss"], atol=1e-6)
    for i, leaf in enumerate(flat(alone.params)):
        np.testing.assert_allclose(first[f"arr_{i}"], leaf, rtol=1e-4, atol=1e-6)


def test_sigterm_to_one_of_two_processes_stops_both_at_one_checkpoint_to_resume_from(tmp_path):
    checkpoints = tmp_path / "checkpoints"
    long = {"CHECKPOINTS": str(checkpoints), "UPDATES": "12"}
    preempted = train_in_two_processes(tmp_path / "stopped", TERM_AT="2", **long)
    stopped = results_of(tmp_path / "stopped", preempted)  # each raised StoppedBySignal
    assert [int(s["signal"]) for s in stopped] == [signal.SIGTERM] * 2
    at = int(stopped[0]["stopped_at"])
    assert int(stopped[1]["stopped_at"]) == at and 2 <= at < 12  # together, before the end
    steps = sorted(int(p.name) for p in checkpoints.iterdir() if p.name.isdigit())
    assert steps[-1] == at  # the checkpoint of the update they stopped after, complete
    first, second = results_of(
        tmp_path / "resumed",
        train_in_two_processes(tmp_path / "resumed", **long),
    )
    assert int(first["resumed_from"]) == int(second["resumed_from"]) == at
    np.testing.assert_array_equal(first["policy_loss"], second["policy_loss"])
    assert len(first["policy_loss"]) == 12


@pytest.mark.slow
def test_two_processes_killed_and_resumed_end_as_if_never_stopped(tmp_path):
    whole = train_in_two_processes(tmp_path / "whole")
    resumed = killed_then_resumed(tmp_path)
    uninterrupted = results_of(tmp_path / "whole", whole)
    for after, before in zip(resumed, uninterrupted, strict=True):
        for key in before:
            if key != "resumed_from":
                np.testing.assert_array_equal(after[key], before[key], err_msg=key)


def test_distributed_without_a_coordinator_is_one_line_saying_what_to_set(tmp_path):
    cluster = ("JAX_", "SLURM_", "OMPI_", "PMI_", "KUBERNETES_")
    alone = {k: v for k, v in os.environ.items() if not k.startswith(cluster)}
    done = subprocess.run(
        [sys.executable, "-m", "fppo_jax", "train", "--distributed", "--quiet"],
        env={**alone, "PYTHONPATH": str(Path(fppo_jax.__file__).parent.parent)},
        cwd=tmp_path,
        capture_output=True,
        text=True,
    )
    assert done.returncode == 2, done.stderr
    assert done.stderr.startswith("fppo-jax: error: cannot join a multi-process run: ")
    assert "set JAX_COORDINATOR_ADDRESS" in done.stderr and len(done.stderr.splitlines()) == 1
