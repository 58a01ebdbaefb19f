"""The job script docs/devices.md gives for a split sweep does what it says: it trains its
part with the flags the command line takes, shares the compilation cache the safe way, and on
exit status 138 requeues its own task alone, in an array or not. So does the tune's of
docs/tuning.md, which also joins the shares as the job after the array, in a chain of an array
and its join per rung that a requeue holds up and a failed task stops until resubmitted. Run by
bash with stand-ins for SLURM's commands, and under -m slow on a real SLURM where one is
installed."""

import argparse
import os
import re
import shlex
import shutil
import stat
import subprocess
import textwrap
import time
from pathlib import Path

import pytest

from fppo_jax.cli import build_parser
from fppo_jax.cli.slurm import array_part
from fppo_jax.errors import InvalidInput

ROOT = Path(__file__).resolve().parents[1]


def template() -> str:
    """The script: the bash block that follows the words that name it."""
    text = (ROOT / "docs" / "devices.md").read_text()
    after = text[text.index("A split sweep's job script, `hopper.sbatch`") :]
    return re.search(r"```bash\n(.*?)```", after, re.DOTALL)[1]


def stand_in(where: Path, name: str, body: str) -> None:
    path = where / name
    path.write_text("#!/bin/bash\n" + textwrap.dedent(body))
    path.chmod(path.stat().st_mode | stat.S_IXUSR)


def resubmission() -> str:
    """The script as the docs say to resubmit some of a split's tasks: with their part spelled
    out in place of --part auto."""
    text = " ".join((ROOT / "docs" / "devices.md").read_text().split())
    spelled = re.search(r"`(--part [^`]+)` in place of `--part auto`", text)[1]
    return template().replace("--part auto", spelled)


def run_template(
    tmp_path: Path, status: int, script: str = "", **slurm: str
) -> tuple[int, list[str], dict]:
    """The script's exit status (the docs' own, or `script`), what it called (a line each,
    srun's as `srun ARGS`) and the environment srun saw, with srun standing in for the program
    and exiting with `status`."""
    bin_dir, calls = tmp_path / "bin", tmp_path / "calls"
    bin_dir.mkdir()
    stand_in(bin_dir, "srun", f'env > {tmp_path}/env\necho srun "$@" >> {calls}\nexit {status}\n')
    stand_in(bin_dir, "scontrol", f'echo scontrol "$@" >> {calls}\n')
    job = tmp_path / "job.sbatch"
    job.write_text(script or template())
    cluster = ("SLURM_", "JAX_", "FPPO_JAX_")
    env = {k: v for k, v in os.environ.items() if not k.startswith(cluster)}
    env |= {"PATH": f"{bin_dir}{os.pathsep}{env['PATH']}", "HOME": str(tmp_path), **slurm}
    done = subprocess.run(["bash", str(job)], env=env, cwd=tmp_path)
    seen = dict(
        line.split("=", 1) for line in (tmp_path / "env").read_text().splitlines() if "=" in line
    )
    return done.returncode, calls.read_text().splitlines(), seen


ARRAY_TASK = {
    "SLURM_JOB_ID": "108",  # the array's last task: its id is the array's own
    "SLURM_ARRAY_JOB_ID": "108",
    "SLURM_ARRAY_TASK_ID": "8",
    "SLURM_ARRAY_TASK_MIN": "1",
    "SLURM_ARRAY_TASK_MAX": "8",
    "SLURM_ARRAY_TASK_STEP": "1",
    "SLURM_ARRAY_TASK_COUNT": "8",
    "SLURM_CPUS_PER_TASK": "2",
}


def test_stopped_by_the_time_limit_an_array_task_requeues_itself_alone(tmp_path):
    status, calls, _ = run_template(tmp_path, 138, **ARRAY_TASK)
    assert status == 138
    assert calls[-1] == "scontrol requeue 108_8"  # not 108: every task of the array


def test_stopped_by_the_time_limit_a_job_that_is_no_array_requeues_itself(tmp_path):
    status, calls, _ = run_template(tmp_path, 138, SLURM_JOB_ID="42", SLURM_CPUS_PER_TASK="2")
    assert status == 138
    assert calls[-1] == "scontrol requeue 42"


@pytest.mark.parametrize("status", [0, 1, 2, 143])
def test_any_other_end_is_passed_on_without_a_requeue(tmp_path, status):
    ended, calls, _ = run_template(tmp_path, status, **ARRAY_TASK)
    assert ended == status
    assert [call.split()[0] for call in calls] == ["srun"]


def test_the_program_is_one_the_command_line_takes_with_the_cache_shared_safely(tmp_path):
    _, calls, env = run_template(tmp_path, 0, **ARRAY_TASK)
    srun = shlex.split(calls[0])
    program = srun.index("fppo-jax")
    assert srun[1:program] == ["--cpus-per-task=2"]
    args = build_parser().parse_args(srun[program + 1 :])
    assert (args.command, args.part, args.resume) == ("sweep", "auto", True)
    assert (args.output, args.checkpoint_dir) == (
        Path("runs/hopper/part-8"),
        Path("runs/hopper/ckpt-8"),
    )
    # The package's own variable, under which JAX locks each entry (fppo_jax/run/compile_cache.py);
    # JAX's own would leave JAX unbounded and unlocked.
    assert env["FPPO_JAX_CACHE_DIR"] == str(tmp_path / "fppo-jax-cache")
    assert "JAX_COMPILATION_CACHE_DIR" not in env


def test_a_resubmitted_task_trains_its_own_part_where_part_auto_would_refuse(tmp_path):
    # sbatch --array=2,5 of a split into 8 parts, as SLURM describes its task 5. --part auto
    # refuses that array; the part spelled out is the task's own.
    again = {**ARRAY_TASK, "SLURM_ARRAY_TASK_ID": "5", "SLURM_ARRAY_TASK_MIN": "2"}
    again |= {"SLURM_ARRAY_TASK_MAX": "5", "SLURM_ARRAY_TASK_COUNT": "2"}
    with pytest.raises(InvalidInput, match="not one evenly stepped range"):
        array_part({k: v for k, v in again.items() if k.startswith("SLURM_ARRAY_TASK")})
    _, calls, _ = run_template(tmp_path, 0, script=resubmission(), **again)
    srun = shlex.split(calls[0])
    args = build_parser().parse_args(srun[srun.index("fppo-jax") + 1 :])
    assert args.part == (5, 8) and args.output == Path("runs/hopper/part-5")


# On a real SLURM: an array of two tasks whose program stands in for fppo-jax; the last task
# (whose SLURM_JOB_ID is the array's) stops for its time limit once, after the first task has
# completed. A requeue of that task alone runs it again and leaves the first one done.
STOPS_ONCE = """\
    count=$PWD/count-$SLURM_ARRAY_TASK_ID
    echo run >> "$count"
    if [ "$SLURM_ARRAY_TASK_ID" = 2 ] && [ "$(wc -l < "$count")" = 1 ]; then
      until scontrol show job "${SLURM_ARRAY_JOB_ID}_1" | grep -q JobState=COMPLETED; do
        sleep 1
      done
      exit 138
    fi
"""


@pytest.mark.slow
@pytest.mark.skipif(
    shutil.which("sbatch") is None, reason="no SLURM here: sbatch is not on the PATH"
)
def test_on_slurm_a_requeued_array_task_runs_again_alone(tmp_path):
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    stand_in(bin_dir, "fppo-jax", STOPS_ONCE)
    (tmp_path / "job.sbatch").write_text(template())
    env = {**os.environ, "PATH": f"{bin_dir}{os.pathsep}{os.environ['PATH']}"}
    flags = ["--array=1-2", "--cpus-per-task=1", "--time=30", f"--output={tmp_path}/%A_%a.out"]
    submitted = subprocess.run(
        ["sbatch", "--parsable", f"--chdir={tmp_path}", *flags, str(tmp_path / "job.sbatch")],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    array = submitted.stdout.strip().split(";")[0]

    def runs(task: int) -> int:
        count = tmp_path / f"count-{task}"
        return len(count.read_text().splitlines()) if count.exists() else 0

    # Until the array has left the queue after the requeued task's second run (SLURM holds a
    # requeued job for a while before it starts it again).
    queued = ["squeue", "-h", "-j", array]
    while runs(2) < 2 or subprocess.run(queued, capture_output=True, text=True).stdout.strip():
        time.sleep(1)
    assert (runs(1), runs(2)) == (1, 2)


# The tune's job script and its submission (docs/tuning.md): the same script trains an array
# task's share of the next rung and, as the job after the array, joins the shares.
def tune_block(words: str) -> str:
    """The bash block of docs/tuning.md that follows `words`."""
    text = (ROOT / "docs" / "tuning.md").read_text()
    after = text[text.index(words) :]
    return re.search(r"```bash\n(.*?)```", after, re.DOTALL)[1]


def tune_template() -> str:
    return tune_block("A tune's job script,\n`tune.sbatch`")


def tune_chain() -> str:
    return tune_block("and its submission, a chain")


def tune_args(calls: list[str]) -> tuple[argparse.Namespace, list[str]]:
    """The fppo-jax command line of the script's srun call, parsed; and srun's own flags."""
    srun = shlex.split(calls[0])
    program = srun.index("fppo-jax")
    return build_parser().parse_args(srun[program + 1 :]), srun[1:program]


def test_the_tune_script_trains_a_share_as_an_array_task_and_joins_as_a_job_of_its_own(
    tmp_path,
):
    (tmp_path / "task").mkdir()
    _, calls, env = run_template(tmp_path / "task", 0, tune_template(), **ARRAY_TASK)
    share, srun = tune_args(calls)
    assert srun == ["--cpus-per-task=2"]
    assert (share.command, share.part, share.rungs) == ("tune", "auto", None)
    assert env["FPPO_JAX_CACHE_DIR"] == str(tmp_path / "task" / "fppo-jax-cache")
    (tmp_path / "join").mkdir()
    alone = {"SLURM_JOB_ID": "109", "SLURM_CPUS_PER_TASK": "2"}
    _, calls, _ = run_template(tmp_path / "join", 0, tune_template(), **alone)
    join, _ = tune_args(calls)
    assert (join.part, join.rungs) == (None, 0)
    # The same tune otherwise, whose plan the join checks: every other flag alike, a chunk given.
    flags = set(vars(share)) - {"part", "rungs", "commands"}  # commands: the parser's own
    assert {k: getattr(share, k) for k in flags} == {k: getattr(join, k) for k in flags}
    assert share.chunk == 28 and -(-2 * 27 * 2 // share.chunk) == 4  # 108 runs: --array=1-4


@pytest.mark.parametrize(
    "slurm, requeued", [(ARRAY_TASK, "108_8"), ({"SLURM_JOB_ID": "109"}, "109")]
)
def test_the_tune_script_requeues_its_own_task_on_138_and_passes_on_any_other_end(
    tmp_path, slurm, requeued
):
    for status in (138, 0, 2, 143):
        where = tmp_path / str(status)
        where.mkdir()
        ended, calls, _ = run_template(where, status, tune_template(), **slurm)
        assert ended == status
        requeues = [call for call in calls if call.startswith("scontrol")]
        assert requeues == ([f"scontrol requeue {requeued}"] if status == 138 else [])


def test_the_tune_chain_waits_for_each_join_and_each_array_in_turn(tmp_path):
    bin_dir, calls = tmp_path / "bin", tmp_path / "calls"
    bin_dir.mkdir()
    # sbatch --parsable prints the job's id: 1, 2, … in the order submitted.
    stand_in(bin_dir, "sbatch", f'echo "$@" >> {calls}\nwc -l < {calls}\n')
    env = {**os.environ, "PATH": f"{bin_dir}{os.pathsep}{os.environ['PATH']}"}
    subprocess.run(["bash", "-c", tune_chain()], env=env, cwd=tmp_path, check=True)
    submitted = [call.split() for call in calls.read_text().splitlines()]
    assert len(submitted) == 2 * 5  # an array and its join per round: 4 rungs and the race
    for job, flags in enumerate(submitted, 1):
        assert flags[-1] == "tune.sbatch" and "--parsable" in flags
        waits = [f for f in flags if f.startswith("--dependency=")]
        if job % 2:  # an array, after the join before it
            assert "--array=1-4" in flags
            assert waits == ([] if job == 1 else [f"--dependency=afterok:{job - 1}"])
        else:  # its join, after the whole array, logged under its own id
            assert not [f for f in flags if f.startswith("--array")]
            assert waits == [f"--dependency=afterok:{job - 1}"]
            assert "--output=logs/tune-%j.out" in flags
    assert (tmp_path / "logs").is_dir()


# On a real SLURM, the tune's chain with a stand-in for fppo-jax that keeps a tune's records: 3
# rounds of 4 shares, each share recorded once (a recorded one is not trained again), each join
# refused while a share is missing. Told to, a task stops once for its time limit (138) or fails
# once (2) before it records its share.
TUNE_STAND_IN = """\
    rounds=3
    done=$(cat rungs 2>/dev/null || echo 0)
    echo "${SLURM_ARRAY_TASK_ID:-join} $done" >> calls
    if [ "$done" -ge "$rounds" ]; then exit 0; fi
    if [ -n "$SLURM_ARRAY_TASK_ID" ]; then
      share=rung-$done-part-$SLURM_ARRAY_TASK_ID
      if [ -e "$share" ]; then exit 0; fi
      if [ -e "stops-$share" ]; then rm "stops-$share"; exit 138; fi
      if [ -e "fails-$share" ]; then rm "fails-$share"; exit 2; fi
      touch "$share"
      exit 0
    fi
    for part in 1 2 3 4; do [ -e "rung-$done-part-$part" ] || exit 2; done
    echo $((done + 1)) > rungs
"""


@pytest.mark.slow
@pytest.mark.skipif(
    shutil.which("sbatch") is None, reason="no SLURM here: sbatch is not on the PATH"
)
def test_on_slurm_the_tune_chain_survives_a_requeue_and_recovers_from_a_failed_task(tmp_path):
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    stand_in(bin_dir, "fppo-jax", TUNE_STAND_IN)
    # sbatch itself, noting each job it submits.
    stand_in(bin_dir, "sbatch", f'"{shutil.which("sbatch")}" "$@" | tee -a {tmp_path}/jobs\n')
    # A task of one core within the test's minutes, on a node of any size.
    script = tune_template().replace("--cpus-per-task=2", "--cpus-per-task=1")
    (tmp_path / "tune.sbatch").write_text(script.replace("--time=4:00:00", "--time=30"))
    (tmp_path / "stops-rung-0-part-2").touch()
    (tmp_path / "fails-rung-1-part-3").touch()
    env = {**os.environ, "PATH": f"{bin_dir}{os.pathsep}{os.environ['PATH']}"}

    def chain() -> list[str]:
        before = len(jobs()) if (tmp_path / "jobs").exists() else 0
        subprocess.run(["bash", "-c", tune_chain()], env=env, cwd=tmp_path, check=True)
        return jobs()[before:]

    def jobs() -> list[str]:
        return [line.split(";")[0] for line in (tmp_path / "jobs").read_text().split()]

    def queued(ids: list[str], field: str = "%i") -> list[str]:
        shown = ["squeue", "-h", "-o", field, "-j", ",".join(ids)]
        return subprocess.run(shown, capture_output=True, text=True).stdout.split()

    first = chain()
    # Round 1 joined once its requeued task ran again; round 2's join waits for ever.
    while "DependencyNeverSatisfied" not in queued(first[3:4], "%r"):
        time.sleep(1)
    assert (tmp_path / "rungs").read_text().strip() == "1"
    subprocess.run(["scancel", *queued(first)], check=True)
    second = chain()
    while queued(second):
        time.sleep(1)
    assert (tmp_path / "rungs").read_text().strip() == "3"
    calls = (tmp_path / "calls").read_text().splitlines()
    assert calls.count("2 0") == 2  # the task stopped once, requeued, trained its share
    assert not list(tmp_path.glob("stops-*")) and not list(tmp_path.glob("fails-*"))
