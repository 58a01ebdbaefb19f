"""The host-side driver that ``train`` and ``sweep`` share.

It runs a batch of runs along a leading run axis (:mod:`fppo_jax.run.plan`; a single run is a
batch of one): checks the host-side options, opens the checkpoints and compares their record
with the run, checks the log directory, chooses the group size (a part of a split sweep then
takes its groups), restores, compiles once, then trains the groups chunk by chunk
(:mod:`fppo_jax.run.training`).
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any, cast

import jax
from jax.sharding import Mesh

from fppo_jax.envs import resets_itself
from fppo_jax.errors import InvalidInput
from fppo_jax.run.distributed import is_main_process, make_mesh, on_main_process
from fppo_jax.run.execution import Program, compile_program, first_run, updates_per_call
from fppo_jax.run.memory import check_host_memory, host_run_bytes, runs_per_call
from fppo_jax.run.options import Options
from fppo_jax.run.plan import Outcome, Plan, group_inputs, group_size, part_plan
from fppo_jax.run.progress import PROGRESS_LINES, reporter
from fppo_jax.run.stop_signals import STOP_SIGNALS, StoppedBySignal, caught
from fppo_jax.run.training import Training
from fppo_jax.store.checkpoint import (
    CheckpointRecord,
    Checkpoints,
    Restored,
    check_same_run,
    open_checkpoints,
)
from fppo_jax.store.checkpoint_writes import CheckpointsUnavailable
from fppo_jax.store.metric_log import prepare_log_dir
from fppo_jax.store.record import RunRecord

HOST_BYTES_SHOWN = 2**30  # host-stepped environments' memory, said before compiling from here


def drive(plan: Plan, options: Options) -> Outcome:
    """Train `plan` as `options` say; see the module's docstring."""
    # Without checkpoints a signal's default (the end of the process) loses nothing more than
    # stopping would. Joined processes would each see a signal at another chunk: there JAX's
    # preemption service holds SIGTERM (from C, where Python cannot see it to put it back) and
    # names the chunk at which all stop together (:func:`_preempted`). Caught from the start, a
    # signal that comes while compiling stops the run once it has compiled rather than ending
    # it there, so that the requeued run finds the program in the compilation cache (where
    # it can be cached) instead of compiling again into the next time limit.
    catch = options.checkpoint_dir is not None and not jax.distributed.is_initialized()
    with caught(STOP_SIGNALS if catch else ()) as signalled:
        return _drive(plan, options, signalled)


def _drive(plan: Plan, options: Options, signalled: list[int]) -> Outcome:
    mesh = make_mesh(_devices(plan, options), plan.trainer.config.num_envs, plan.data_parallel)
    main = is_main_process()
    checkpoints: Checkpoints | None = None

    def open_on_main() -> CheckpointRecord | None:
        nonlocal checkpoints
        checkpoints, newest = open_checkpoints(
            options.checkpoint_dir, options.resume, options.keep, plan.kind, plan.record
        )
        return newest

    # Process 0 alone holds the checkpoints; the others learn the newest one's record (None if
    # there is none), or the error met.
    checkpointed = on_main_process(open_on_main)
    outputs, failed = None, True
    try:
        if options.log_dir is not None and main:
            resumed = None
            if options.resume:  # the run checkpointed, or this one if nothing was yet
                resumed = plan.record
                if checkpointed is not None:
                    resumed = RunRecord.from_json(checkpointed["config"], "the checkpoint's record")
            outputs = prepare_log_dir(options.log_dir, resumed)
        # The group size is the whole sweep's, chosen before a part takes its groups of it.
        size = group_size(plan, mesh, checkpointed, options.checkpoint_dir)
        if plan.runs_per_call is None and checkpointed is None:
            runs, data = (mesh.shape["runs"], mesh.shape["data"]) if mesh else (1, 1)
            key, hp = jax.eval_shape(first_run, (plan.keys, plan.hps))
            size = runs_per_call(plan.trainer, key, hp, size, runs, data)
        if plan.share is not None:
            plan = part_plan(plan, size, mesh.shape["runs"] if mesh else 1)
            _check_runs(plan, options)
        restored = None
        if checkpointed is not None:
            like = jax.eval_shape(_init(plan), *group_inputs(plan, 0, size))
            restored = on_main_process(lambda: _restore(cast(Checkpoints, checkpoints), like, plan))
        if options.progress is True and main:
            where = f" on {mesh.size} devices" if mesh else ""
            print(f"{plan.header}{where}; compiling…", file=sys.stderr, flush=True)
        program = _compile(plan, options, mesh, size, main)
        if signalled:
            update = 0 if restored is None else restored.point().update
            directory = cast(str | Path, options.checkpoint_dir)  # else nothing is caught
            raise StoppedBySignal(signalled[0], update, directory, trained=False)
        with (
            reporter(options.progress if main else False, plan.description) as report,
            Training(
                plan, options, program, size, checkpoints, outputs, restored, report, main
            ) as chunks,
        ):
            outcome = chunks.train(signalled)
        failed = False
        return outcome
    finally:
        if checkpoints:
            checkpoints.close(quiet=failed)
        if outputs:
            outputs.release()


def _devices(plan: Plan, options: Options) -> int | None:
    """The devices asked for, checked against what the environment allows (host-stepped
    environments run on one device, in one process, with runs it can make)."""
    env, devices = plan.trainer.env, options.devices
    if resets_itself(env):
        if devices not in (None, 1) or jax.process_count() > 1:
            raise InvalidInput(
                "native MuJoCo and Gymnasium step their environments on this host, for one "
                "device: devices must be 1, in a single process"
            )
        devices = 1
    if plan.share is None:  # a part's runs are known once their group size is
        _check_runs(plan, options)
    return devices


def _check_runs(plan: Plan, options: Options) -> None:
    """What a vector environment instance cannot serve (its `check_runs`) is refused."""
    check_runs = getattr(plan.trainer.env, "check_runs", None)
    if check_runs is not None:
        check_runs(plan.num_runs, options.eval_every is not None)


def _compile(plan: Plan, options: Options, mesh: Mesh | None, size: int, main: bool) -> Program:
    """The program of groups of `size` runs, once their memory is checked."""
    trainer = plan.trainer
    check_host_memory(trainer, size)
    host = host_run_bytes(trainer) * size
    if options.progress is True and main and host >= HOST_BYTES_SHOWN:
        # Making that many Python environments, at the first reset, takes minutes.
        print(
            f"{getattr(trainer.env, 'name', 'the environment')}: "
            f"{size * trainer.config.num_envs:,} environments, made on the host at the first "
            f"reset, take about {host / 2**30:.1f} GiB there",
            file=sys.stderr,
            flush=True,
        )
    per_call = _updates_per_call(options, trainer.config.num_updates)
    return compile_program(trainer, *group_inputs(plan, 0, size), plan.along_runs, per_call, mesh)


def _restore(checkpoints: Checkpoints, like: Any, plan: Plan) -> Restored:
    """The newest intact checkpoint of this run, or an error: never a silent fresh start."""
    directory = checkpoints.directory
    restored = checkpoints.restore(
        like, lambda r: check_same_run(r, plan.kind, plan.record, directory)
    )
    if restored is None:
        raise CheckpointsUnavailable(
            f"no checkpoint in {directory} is intact (each was moved to {directory / 'damaged'}"
            "); nothing was restored. To start afresh, remove the directory or choose another"
        )
    return restored


def _init(plan: Plan) -> Callable[..., Any]:
    return plan.along_runs(plan.trainer.init)


def _updates_per_call(options: Options, num_updates: int) -> int:
    """Checkpoints, logs, evaluations, callbacks and progress happen between compiled calls:
    a call runs up to the next of them (one call for the whole run if none is asked for)."""
    if options.checkpoint_every is not None:
        per_call = min(options.checkpoint_every, num_updates)
    elif (
        any(
            (options.checkpoint_dir, options.progress, options.log_dir, options.callback),
        )
        or options.wandb_project
    ):
        per_call = updates_per_call(num_updates, PROGRESS_LINES)
    else:
        per_call = num_updates
    if options.eval_every is not None:
        per_call = math.gcd(per_call, min(options.eval_every, num_updates))
    return per_call
