"""The loop of a batch of runs: each group of the plan, chunk by chunk, with the hooks' work
between chunks (:mod:`fppo_jax.run.hooks`: checkpoint, output directory, logs, callback,
progress), a single run stopped where it diverged, and every run stopped on a signal.
"""

from __future__ import annotations

import signal
import sys
from collections.abc import Callable
from pathlib import Path
from typing import cast

import jax
import numpy as np

from fppo_jax.core.policy import make_policy
from fppo_jax.core.trainer import TrainState
from fppo_jax.envs import resets_itself
from fppo_jax.run.distributed import fetch
from fppo_jax.run.divergence import TrainingDiverged
from fppo_jax.run.execution import Program, concatenate, run_chunks
from fppo_jax.run.hooks import (
    Checkpoint,
    Chunk,
    Evaluation,
    Finished,
    Hook,
    ProgressReport,
    UserCallback,
)
from fppo_jax.run.options import Options
from fppo_jax.run.plan import Outcome, Plan, group_inputs
from fppo_jax.run.progress import Counter, Progress
from fppo_jax.run.stop_signals import StoppedBySignal
from fppo_jax.store.checkpoint import CheckpointedRun, Checkpoints, Restored
from fppo_jax.store.files import DirectoryLock
from fppo_jax.store.metric_log import LoggedRuns, open_logs


class Training:
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

    def __enter__(self) -> Training:
        return self

    def __exit__(self, *exc: object) -> None:
        if self.logs:
            self.logs.close()

    def _hooks(self, counter: Counter, resumed_from: int | None) -> list[Hook]:
        """The work between chunks that the options ask for, in the order it is done."""
        hooks: list[Hook] = []
        if self.options.checkpoint_dir is not None:
            plan = self.plan
            run = CheckpointedRun(
                kind=plan.kind,
                config=plan.record,
                runs_per_call=self.size,
                num_updates=self.num_updates,
            )
            single_run = plan.trainer if plan.kind == "train" else None
            self.checkpoint = Checkpoint(
                self.checkpoints, self.finished, run, single_run, resumed_from
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
        keys, hps = group_inputs(self.plan, group, self.size)
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
