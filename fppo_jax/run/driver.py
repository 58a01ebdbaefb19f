"""The host-side driver that ``train`` and ``sweep`` share.

It runs a batch of runs along a leading run axis (a single run is a batch of one): checks the
host-side options, opens the checkpoints and compares their record with the run, checks the log
directory, restores, compiles once, then calls the program in chunks of updates. After each
chunk it stops a single run that diverged, evaluates, then hands the chunk to the hooks the
options ask for (:mod:`fppo_jax.run.hooks`: checkpoint, output directory, logs, callback, progress),
and stops on a signal. A sweep's runs train in groups of one size, so every group reuses the one
compiled program. The groups are the whole sweep's: a part of a split sweep trains whole groups
of them, so that each run is computed by the same program, at the same place in its group, as
in the unsplit sweep.
"""

from __future__ import annotations

import dataclasses
import math
import signal
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any, cast

import jax
import numpy as np
from jax.sharding import Mesh

from fppo_jax.core.checks import check_part
from fppo_jax.core.config import Hyperparameters
from fppo_jax.core.policy import make_policy
from fppo_jax.core.trainer import Trainer, TrainState
from fppo_jax.envs import resets_itself
from fppo_jax.errors import FppoError, InvalidInput
from fppo_jax.run.distributed import (
    fetch,
    is_main_process,
    make_mesh,
    on_main_process,
)
from fppo_jax.run.execution import (
    Program,
    compile_program,
    concatenate,
    first_run,
    one_run,
    run_chunks,
    updates_per_call,
)
from fppo_jax.run.hooks import (
    Checkpoint,
    Chunk,
    Evaluation,
    Finished,
    Hook,
    ProgressReport,
    UserCallback,
)
from fppo_jax.run.memory import check_host_memory, host_run_bytes, runs_per_call
from fppo_jax.run.options import Options
from fppo_jax.run.progress import PROGRESS_LINES, Counter, Progress, reporter
from fppo_jax.run.stop_signals import STOP_SIGNALS, caught
from fppo_jax.store.checkpoint import (
    Checkpoints,
    CheckpointsUnavailable,
    ConfigMismatch,
    Restored,
    RunKind,
    check_same_run,
    open_checkpoints,
)
from fppo_jax.store.files import DirectoryLock
from fppo_jax.store.metric_log import LoggedRuns, open_logs, prepare_log_dir
from fppo_jax.store.record import RunRecord


class TrainingDiverged(FppoError, FloatingPointError):
    """The loss or the parameters became NaN or infinite."""

    def __init__(
        self,
        update: int,
        env_steps: int,
        checkpoint: str | None = None,
        surrogate: str | None = None,
    ):
        """`update` counts from 1, as the progress lines do; `checkpoint` says where the last
        good checkpoint is, if any; `surrogate` names the run's surrogate if it is one's own."""
        self.update, self.env_steps = update, env_steps
        kept = f" {checkpoint}." if checkpoint else ""
        advice = "Lower the learning rate, or check the environment's observations and rewards"
        if surrogate:  # its declaration tried it on ratios 0.25 … 4 only: training reaches others
            advice = (
                "Lower the learning rate, check the environment's observations and rewards, or "
                f"check the surrogate {surrogate!r}: its value or slope may not be finite at "
                "ratios or advantages that training reaches beyond those its declaration tried"
            )
        super().__init__(
            f"training diverged at update {update} (after {env_steps:,} env steps): the loss or "
            f"the parameters became NaN or infinite.{kept} {advice}."
        )


HOST_BYTES_SHOWN = 2**30  # host-stepped environments' memory, said before compiling from here


class StoppedBySignal(Exception):
    """A checkpointed run stopped on SIGTERM or SIGUSR1 at the end of a chunk of updates, its
    checkpoint written, or before training if the signal came while it started or compiled
    (`trained` False), with nothing new checkpointed: resuming goes on from `update` (the
    newest checkpoint's, 0 if none)."""

    def __init__(
        self, signal_number: int, update: int, checkpoint_dir: str | Path, trained: bool = True
    ):
        self.signal = signal.Signals(signal_number)
        self.update, self.trained = update, trained
        where = Path(checkpoint_dir).absolute()
        if trained:
            said = f"after update {update}, checkpointed in {where}; resume (--resume) to go on"
            said += " from there"
        else:
            said = "before training (while starting or compiling), nothing new checkpointed; "
            said += f"resume (--resume) to go on from the newest checkpoint in {where}, or from "
            said += "the start if there is none"
        super().__init__(f"stopped by {self.signal.name} {said}")


@dataclasses.dataclass(frozen=True)
class Plan:
    """What to train: `keys`, a [run] array of keys, and `hps` alike (one run's for a "train"
    plan); `record` is the configuration that checkpoints and outputs record, and `runs` (a
    sweep's only) each run's setting and seed, which its logs name it by.
    `runs_per_call` fixes a sweep's group size (None: as many of its runs as fit in memory),
    and `data_parallel` the devices each run's environments are split over. `share`, a
    ``(K, N)`` part of a split sweep, trains the K-th of N shares of the whole sweep's groups
    (:func:`part_runs`): `keys`, `hps` and `runs` are then the whole sweep's. `after_group`, if
    given, is called on the process that writes with the :class:`Outcome` of the runs finished
    so far, after each group (a sweep writes its curves with it)."""

    kind: RunKind
    trainer: Trainer
    keys: jax.Array
    hps: Hyperparameters
    record: RunRecord
    description: str  # a few words, for the progress bar
    header: str  # a line, printed before compiling when progress is shown
    runs: tuple[dict[str, Any], ...] | None = None
    runs_per_call: int | None = None
    data_parallel: int | None = None
    after_group: Callable[[Outcome], None] | None = None
    share: tuple[int, int] | None = None

    def __post_init__(self) -> None:
        sweep = self.kind == "sweep"
        if (self.runs is not None) != sweep or (sweep and len(self.runs or ()) != self.num_runs):
            raise InvalidInput("a sweep's plan names each of its runs, and only a sweep's")
        if not sweep and self.num_runs != 1:
            raise InvalidInput(f"a train plan trains one run, not {self.num_runs}")
        if self.share is not None and not sweep:
            raise InvalidInput("only a sweep is split into parts")

    @property
    def num_runs(self) -> int:
        return int(self.keys.shape[0])

    @property
    def along_runs(self) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
        """How one run's functions take the run axis: a sweep's are vmapped (even over one
        run); a single run is its own program, so that its bits are those of one run
        compiled alone."""
        return jax.vmap if self.kind == "sweep" else one_run


@dataclasses.dataclass
class Outcome:
    """What the driver hands back: the last group's final state, every run's metrics
    ([run, update]), the update each run diverged at (from 1) or 0, and
    the times. `stopped_at` is the update where a callback stopped training, if it did."""

    state: TrainState
    metrics: dict[str, np.ndarray]
    diverged: np.ndarray
    compile_seconds: float
    train_seconds: float
    resumed_from: int
    runs_per_call: int
    stopped_at: int | None


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

    def open_on_main() -> dict[str, Any] | None:
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
        size = _group_size(plan, mesh, checkpointed, options.checkpoint_dir)
        if plan.runs_per_call is None and checkpointed is None:
            runs, data = (mesh.shape["runs"], mesh.shape["data"]) if mesh else (1, 1)
            key, hp = jax.eval_shape(first_run, (plan.keys, plan.hps))
            size = runs_per_call(plan.trainer, key, hp, size, runs, data)
        if plan.share is not None:
            plan = _share(plan, size, mesh.shape["runs"] if mesh else 1)
            _check_runs(plan, options)
        restored = None
        if checkpointed is not None:
            like = jax.eval_shape(_init(plan), *_group(plan, 0, size))
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
            _Training(
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
    return compile_program(trainer, *_group(plan, 0, size), plan.along_runs, per_call, mesh)


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


def _group_size(
    plan: Plan,
    mesh: Mesh | None,
    checkpointed: dict[str, Any] | None,
    checkpoint_dir: str | Path | None,
) -> int:
    """Runs per compiled call: the sweep's chunk, or its recorded one when resuming, rounded
    up to split evenly over the devices that share the runs."""
    chunk = plan.runs_per_call
    directory = None if checkpoint_dir is None else Path(checkpoint_dir).absolute()
    if checkpointed is not None:
        if chunk is not None and chunk != checkpointed["runs_per_call"]:
            raise ConfigMismatch(
                f"{directory} holds a sweep of {checkpointed['runs_per_call']} runs "
                f"per compiled call, not {chunk}; resume without chunk, or with that"
            )
        chunk = checkpointed["runs_per_call"]
    across = mesh.shape["runs"] if mesh else 1
    size = _multiple(min(chunk or plan.num_runs, plan.num_runs), across)
    if checkpointed is not None and size != checkpointed["runs_per_call"]:
        raise ConfigMismatch(
            f"{directory} holds a sweep of {checkpointed['runs_per_call']} runs per "
            f"call, which does not split evenly over {across} devices; resume with devices "
            "that divide it"
        )
    return size


def _share(plan: Plan, size: int, across: int) -> Plan:
    """The plan of `plan`'s part: its share of the whole sweep's groups of
    `size` runs (:func:`part_runs`), whose groups are then the sweep's own (each starts at a
    multiple of `size`, and only the sweep's last is padded, by the sweep's last run)."""
    assert plan.share is not None
    start, stop = part_runs(plan.share, plan.num_runs, size, across)
    index = slice(start, stop)
    return dataclasses.replace(
        plan,
        keys=plan.keys[index],
        hps=jax.tree.map(lambda x: x[index], plan.hps),
        runs=cast(tuple[dict[str, Any], ...], plan.runs)[index],
        share=None,
    )


def share_bounds(part: object, count: int) -> tuple[int, int]:
    """Where the K-th of N shares of `count` things starts and stops, for ``part=(K, N)``:
    shares as equal as they can be, the first ones one longer; with fewer things than shares,
    the shares past them are empty."""
    k, n = check_part(part)
    size, extra = divmod(count, n)
    start = (k - 1) * size + min(k - 1, extra)
    return start, start + size + (k <= extra)


def part_bounds(part: object, count: int) -> tuple[int, int]:
    """:func:`share_bounds` of a sweep's `count` runs, which has one for each of its parts."""
    k, n = check_part(part)
    if n > count:
        raise InvalidInput(f"part {k} of {n}: the sweep has only {count} runs to share")
    return share_bounds(part, count)


def part_runs(part: tuple[int, int], num_runs: int, size: int, across: int = 1) -> tuple[int, int]:
    """Where the runs of ``part=(K, N)`` start and stop among a sweep's `num_runs` runs trained
    in groups of `size` (the sweep's runs per call, rounded to the `across` devices that share
    a group's runs): the K-th of N shares of the groups (:func:`part_bounds`), so that a part
    trains whole groups of the sweep, each as the unsplit sweep trains it."""
    groups = -(-num_runs // size)
    if part[1] > groups:
        # The most runs per call that make N groups, a multiple of `across`.
        most = (-(-num_runs // (part[1] - 1)) - 1) // across * across
        fewer = f"split it into at most {groups} part{'s' * (groups > 1)}"
        fix = f"give runs per call (chunk, --chunk) of at most {most}, or {fewer}"
        fix = fix if 0 < most < size else fewer
        raise InvalidInput(
            f"part {part[0]} of {part[1]}: the sweep's {num_runs} runs train as {groups} "
            f"group{'s' * (groups > 1)} of {size} per compiled call, and a part trains whole "
            f"groups of the sweep (so that it merges into the sweep run unsplit, bit for bit): "
            f"{fix}"
        )
    first, stop = part_bounds(part, groups)
    return first * size, min(stop * size, num_runs)


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


def _group(plan: Plan, group: int, size: int) -> tuple[jax.Array, Hyperparameters]:
    """The keys and hyperparameters of group `group`: runs group·size … (group+1)·size − 1,
    the last run repeated past the end, so that every group has one shape."""
    if group == 0 and size == plan.num_runs:
        return plan.keys, plan.hps  # as they are: a gather would compile a program per leaf
    index = _padded(group * size, size, plan.num_runs)
    return plan.keys[index], jax.tree.map(lambda x: x[index], plan.hps)


class _Training:
    """The groups of a plan, run chunk by chunk, with the hooks' work between chunks."""

    def __init__(
        self,
        plan: Plan,
        options: Options,
        program: Program,
        size: int,
        checkpoints: Checkpoints | None,
        outputs: DirectoryLock | None,
        restored: Restored | None,
        report: Callable[[Progress], None] | None,
        main: bool,
    ):
        self.plan, self.options, self.program, self.size = plan, options, program, size
        self.checkpoints, self.restored, self.report = checkpoints, restored, report
        self.outputs = outputs  # the log directory, held and watched
        self.after_group = plan.after_group if main else None
        config = plan.trainer.config
        self.num_updates, self.samples = config.num_updates, config.samples_per_update
        self.groups = -(-plan.num_runs // size)
        self.finished = Finished()
        self.chunks_done = 0  # by this process, every group's
        self.checkpoint: Checkpoint | None = None  # the hook, when checkpointing
        self.evaluation = None
        if options.eval_every is not None:
            env, episodes, every = plan.trainer.env, options.eval_episodes, options.eval_every
            self.evaluation = Evaluation(env, episodes, every, self.num_updates, plan.along_runs)
        logs = (options.log_dir, options.wandb_project, plan.record, plan.runs)
        self.logs = open_logs(*logs, _logged_runs(restored, plan, size)) if main else None

    def __enter__(self) -> _Training:
        return self

    def __exit__(self, *exc: object) -> None:
        if self.logs:
            self.logs.close()

    def _hooks(self, counter: Counter, resumed_from: int | None) -> list[Hook]:
        """The work between chunks that the options ask for, in the order it is done."""
        hooks: list[Hook] = []
        if self.options.checkpoint_dir is not None:
            plan = self.plan
            record = {
                "kind": plan.kind,
                "config": plan.record,
                "runs_per_call": self.size,
                "num_updates": self.num_updates,
            }
            single_run = plan.trainer if plan.kind == "train" else None
            self.checkpoint = Checkpoint(
                self.checkpoints, self.finished, record, single_run, resumed_from
            )
            hooks.append(self.checkpoint)
        if self.outputs:  # after the checkpoint, so that a lost directory loses no state
            hooks.append(self.outputs)
        if self.logs:
            hooks.append(self.logs)
        if self.options.callback is not None:
            hooks.append(UserCallback(self.options.callback, self.plan.kind == "train"))
        if self.report:
            hooks.append(ProgressReport(self.report, counter))
        return hooks

    def train(self, signalled: list[int]) -> Outcome:
        """Every group from where it starts; `signalled` holds the stop signals caught, to which
        those still to come are added."""
        self.signalled = signalled
        first_group, start, resumed_from = 0, None, 0
        if self.restored is not None:
            point = self.restored.point()
            if point.finished:
                self.finished.add(point.finished, point.finished_diverged)
            first_group, resumed_from = point.group, point.update
            start = (_restart_envs(self.plan, self.restored.state, resumed_from), point.current)
        self.counter = Counter(
            self.plan.num_runs,
            self.size,
            self.num_updates,
            self.samples,
            self.program.compile_seconds,
            first_group,
            resumed_from,
            self.program.loaded,
        )
        self.hooks = self._hooks(self.counter, None if start is None else resumed_from)
        if self.report:
            self.report(self.counter.progress(first_group, resumed_from))
        state, stopped_at = None, None
        for group in range(first_group, self.groups):
            state, metrics, stopped_at = self._train_group(group, start)
            start = None
            self._end_group(group, state, metrics, resumed_from, stopped_at)
            if stopped_at is not None:
                break
        outcome = self._outcome(cast(TrainState, state), resumed_from, stopped_at)
        if self.checkpoints:
            self.checkpoints.wait()
        return outcome

    def _train_group(
        self, group: int, start: tuple[TrainState, dict[str, np.ndarray]] | None
    ) -> tuple[TrainState, dict[str, np.ndarray], int | None]:
        """Group `group`, chunk by chunk from `start` (a resumed group's state and metrics) or
        afresh: its final state, its metrics, and the update a hook stopped it at, if one did."""
        keys, hps = _group(self.plan, group, self.size)
        initial, metrics = start if start else (self.program.init(keys, hps), {})
        state = initial  # a resumed group may have no update left to run
        runs = range(group * self.size, min((group + 1) * self.size, self.plan.num_runs))
        for state, chunk in run_chunks(self.program, initial, hps):
            update = int(np.max(fetch(state.update)))
            if self.plan.kind == "train":
                self._check_finite(int(fetch(state.nonfinite_update)[0]))
            policy = make_policy(self.plan.trainer, state)
            if self.evaluation is not None:
                self.evaluation.add_column(policy, chunk, update)
            metrics = concatenate([metrics, chunk] if metrics else [chunk])
            done = Chunk(group, runs, update, state, policy, metrics)
            if any([hook.after_chunk(done) for hook in self.hooks]):  # every hook, then stop
                return state, metrics, update
            self._stop_if_signalled(group, update)
        return state, metrics, None

    def _stop_if_signalled(self, group: int, update: int) -> None:
        """Stops, checkpointed, on a signal caught (or at the chunk where joined processes stop
        for a preemption) while updates are left to train."""
        self.chunks_done += 1
        if self.options.checkpoint_dir is not None and _preempted(self.chunks_done):
            self.signalled.append(signal.SIGTERM)
        if self.signalled and (update < self.num_updates or group < self.groups - 1):
            assert self.options.checkpoint_dir is not None  # else nothing is caught
            if self.checkpoints is not None:  # the process that writes them
                self.checkpoints.wait()
            raise StoppedBySignal(self.signalled[0], update, self.options.checkpoint_dir)

    def _end_group(
        self,
        group: int,
        state: TrainState,
        metrics: dict[str, np.ndarray],
        resumed_from: int,
        stopped_at: int | None,
    ) -> None:
        """Keeps the group's runs (not the repeats that pad the last group) with the update
        each diverged at, and shows them to the plan's `after_group`."""
        kept = slice(0, min(self.size, self.plan.num_runs - group * self.size))
        self.finished.add(
            {k: v[kept] for k, v in metrics.items()}, fetch(state.nonfinite_update)[kept] + 1
        )
        if self.after_group:
            if self.outputs:
                self.outputs.check()
            self.after_group(self._outcome(state, resumed_from, stopped_at))

    def _outcome(self, state: TrainState, resumed_from: int, stopped_at: int | None) -> Outcome:
        """The runs finished so far, ending with the group whose final state is `state`."""
        finished = self.finished
        return Outcome(
            state=state,
            metrics=finished.joined(),
            diverged=finished.diverged,
            compile_seconds=self.program.compile_seconds,
            train_seconds=self.counter.elapsed(),
            resumed_from=resumed_from,
            runs_per_call=self.size,
            stopped_at=stopped_at,
        )

    def _check_finite(self, nonfinite: int) -> None:
        """A single run stops at its first non-finite update (a sweep's runs go on)."""
        if nonfinite < 0:
            return
        where = None
        if self.checkpoint is not None:
            if self.checkpoints:
                self.checkpoints.wait()
            saved = self.checkpoint.saved
            where = (
                f"The last good checkpoint, at update {saved[-1]}, is in "
                f"{Path(cast(str | Path, self.options.checkpoint_dir)).absolute()}"
                if saved
                else "No checkpoint was written before it"
            )
        variant = self.plan.record.setting.get("variant")
        own = (
            variant if isinstance(variant, str) and variant in self.plan.record.surrogates else None
        )
        raise TrainingDiverged(nonfinite + 1, (nonfinite + 1) * self.samples, where, own)


def _logged_runs(restored: Restored | None, plan: Plan, size: int) -> list[LoggedRuns]:
    """The runs and metrics a resumed run starts from, for the logs to rewrite."""
    if restored is None:
        return []
    point = restored.point()
    blocks = []
    if point.finished:
        blocks.append((range(len(point.finished["env_steps"])), point.finished))
    begin = point.group * size
    runs = range(begin, min(begin + size, plan.num_runs))
    return [*blocks, (runs, {k: v[: len(runs)] for k, v in point.current.items()})]


def _restart_envs(plan: Plan, state: TrainState, update: int) -> TrainState:
    """A restored state, with new environments if theirs lived outside JAX."""
    trainer = plan.trainer
    if not resets_itself(trainer.env):
        return state
    print(
        f"resuming at update {update} in fresh environments: the environments' state lives "
        "outside JAX (native MuJoCo, Gymnasium) and is not checkpointed, so each starts a "
        "new episode here (not bitwise the run that never stopped)",
        file=sys.stderr,
    )
    return cast(TrainState, jax.jit(plan.along_runs(trainer.restart_envs))(state))


def _preempted(chunk: int) -> bool:
    """Whether joined processes are at the chunk where all of them stop for a preemption: JAX's
    preemption service catches SIGTERM in any one of them, and names the next chunk that every
    process reaches (each calls this after every chunk, counting from 1 since it started)."""
    service = jax.config.jax_enable_preemption_service  # type: ignore[attr-defined]
    if not (jax.distributed.is_initialized() and service):
        return False
    from jax.experimental import multihost_utils

    return bool(multihost_utils.reached_preemption_sync_point(chunk))


def _multiple(size: int, of: int) -> int:
    """`size` rounded up to a multiple of `of`."""
    return -(-size // of) * of


def _padded(begin: int, size: int, num_runs: int) -> np.ndarray:
    return np.minimum(np.arange(begin, begin + size), num_runs - 1)
