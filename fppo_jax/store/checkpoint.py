"""Checkpoints of a run: everything it carries, its metrics so far and its record, written by
orbax's ``CheckpointManager`` atomically and in the background, and verified when read back.

``<directory>/<step>/`` holds four items: ``state`` (every array of the training state, PRNG keys as
their raw data), ``curves`` (the metrics of every update so far), ``policy`` (what
:func:`~fppo_jax.store.saved_policy.load_policy` needs) and ``record`` (JSON: the run's
configuration, the policy's description and a SHA-256 digest of each array item). A run's step
counts its updates; a sweep's, group × updates per run + update, and its record and ``curves`` also
say where it is (:class:`ResumePoint`: the group, the update, the finished groups). A checkpoint is
an artifact (:mod:`fppo_jax.store.artifact`) whose files orbax writes: orbax commits a step whole
(a temporary directory, renamed once complete) and keeps the newest `keep` (deleting older ones
only after a newer one is committed); the record, sealed with its format and digests, catches one
damaged afterwards (a truncated or altered file). A damaged checkpoint is reported, set aside in
``<directory>/damaged/`` and the one before it used. Every record names the layout it was written
in (:data:`FORMAT`): a checkpoint of another layout is refused as
:class:`~fppo_jax.store.files.IncompatibleFormat`, and left where it is, never taken for damage.

Nothing here changes the process: orbax logs through absl at its own levels, and reports its own
failures (a damaged checkpoint read, a write storage refused) as it does; what this module says of
them is one warning per damaged checkpoint and one error (a
:class:`~fppo_jax.store.checkpoint_writes.CheckpointsUnavailable`; for a write refused, the
:class:`~fppo_jax.store.checkpoint_writes.CheckpointNotWritten` that
:mod:`~fppo_jax.store.checkpoint_writes` raises).

Saved policies, a trained policy on its own, are :mod:`fppo_jax.store.saved_policy`'s.
"""

from __future__ import annotations

import dataclasses
import os
import warnings
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, NamedTuple, NotRequired, TypedDict, cast

import jax
import numpy as np

from fppo_jax.core.policy import Policy, PolicyDescription
from fppo_jax.errors import InvalidInput, MissingFile, first_line
from fppo_jax.store import artifact
from fppo_jax.store.checkpoint_writes import CheckpointsUnavailable, Writes, committed_steps
from fppo_jax.store.files import (
    DirectoryBusy,
    DirectoryLock,
    check_format,
    tree_digest,
    writable_directory,
)
from fppo_jax.store.record import RunRecord

if TYPE_CHECKING:
    import orbax.checkpoint as ocp

# What a checkpoint holds: one run (``train``) or a sweep's runs in groups (``sweep``).
RunKind = Literal["train", "sweep"]

# The layout of a checkpoint's items and record (files.check_format). Raise it when a change
# makes checkpoints that the previous code cannot read, or that this code cannot read from it.
# 2: a single run's state and metrics carry the run axis (of one), as a sweep's always did.
FORMAT = 2
# The formats whose policy item load_policy reads: the policy's layout is the first's still.
POLICY_FORMATS = (1, 2)


class DamagedCheckpoint(UserWarning):
    """A checkpoint could not be read back intact and was set aside."""


class ConfigMismatch(InvalidInput):
    """A checkpoint belongs to a run with a different configuration."""


class CheckpointedRun(TypedDict):
    """What a run's checkpoints record of it beside each point (:meth:`Checkpoints.save_point`'s
    keywords): its kind, its record, its runs per compiled call and its updates per run."""

    kind: RunKind
    config: RunRecord
    runs_per_call: int
    num_updates: int


class PointRecord(TypedDict):
    """What a checkpoint records of its run and point (JSON): the kind of run, the run's record
    (:meth:`~fppo_jax.store.record.RunRecord.to_json`), the group and the update it holds, and
    the runs per compiled call."""

    kind: RunKind
    config: dict[str, Any]
    group: int
    update: int
    runs_per_call: int


class CheckpointRecord(PointRecord):
    """A checkpoint's ``record`` item as written: its :class:`PointRecord`, its layout (which
    records of the first format lack), the policy's description (a single run's; None for a
    sweep) and the digest of each array item, by name."""

    format: NotRequired[int]
    policy: PolicyDescription | None
    digests: dict[str, str]


class Curves(TypedDict):
    """A checkpoint's ``curves`` item: the metrics of the group in training so far ([run,
    update], by name) and, once one of a sweep's groups is done, the finished groups' metrics and
    the update each of their runs diverged at (from 1) or 0."""

    current: dict[str, np.ndarray]
    finished: NotRequired[dict[str, np.ndarray]]
    finished_diverged: NotRequired[np.ndarray]


@dataclasses.dataclass
class Restored:
    """A checkpoint read back: its step, the state (in the structure asked for), the metrics
    so far and the record."""

    step: int
    state: Any
    curves: Curves
    record: CheckpointRecord

    def point(self) -> ResumePoint:
        """Where the checkpoint says training stopped."""
        return ResumePoint(
            group=self.record["group"],
            update=self.record["update"],
            current={name: np.asarray(values) for name, values in self.curves["current"].items()},
            finished={k: np.asarray(v) for k, v in self.curves.get("finished", {}).items()},
            finished_diverged=np.asarray(self.curves.get("finished_diverged", []), np.int32),
        )


class ResumePoint(NamedTuple):
    """Where training is when it is checkpointed, and where a resumed run goes on: update
    `update` of group `group` (a sweep's runs train in groups; a single run is group 0), the
    group's metrics so far, and the finished groups' metrics and first diverged updates (empty
    when none is finished)."""

    group: int
    update: int
    current: dict[str, np.ndarray]
    finished: dict[str, np.ndarray]
    finished_diverged: np.ndarray


def open_checkpoints(
    directory: str | Path | None,
    resume: bool,
    keep: int,
    kind: RunKind,
    run_config: RunRecord,
) -> tuple[Checkpoints | None, CheckpointRecord | None]:
    """The checkpoints of a `kind` of run ("train" or "sweep") in `directory`, and the newest
    one's record, checked against this run before anything is compiled (None, None without a
    directory)."""
    if directory is None:
        return None, None
    writable_directory(directory)  # else orbax's own error, a traceback, when it first writes
    checkpoints = Checkpoints(directory, keep)
    try:
        checkpoints.lock()
        record = checkpoints.latest_record()
        if record is None and checkpoints.steps():  # never a silent fresh start
            if not resume:
                raise InvalidInput(
                    f"{checkpoints.directory} already holds checkpoints (none of whose records "
                    "can be read); choose another directory"
                )
            for step in reversed(checkpoints.steps()):
                checkpoints._set_aside(step, ValueError("its record cannot be read"))
            raise CheckpointsUnavailable(
                f"no checkpoint in {checkpoints.directory} is intact (each was moved to "
                f"{checkpoints.directory / 'damaged'}); nothing was restored. To start "
                "afresh, remove the directory or choose another"
            )
        if record is not None and not resume:
            raise InvalidInput(
                f"{checkpoints.directory} already holds checkpoints; pass resume=True (--resume) "
                "to continue that run, or choose another directory"
            )
        newest = None
        if record is not None:
            newest = _checked(record, f"the newest checkpoint in {checkpoints.directory}")
            check_same_run(newest, kind, run_config, checkpoints.directory)
    except Exception:
        checkpoints.close()
        raise
    return checkpoints, newest


def check_same_run(
    record: CheckpointRecord, kind: RunKind, current: RunRecord, directory: Path
) -> None:
    """Raise :class:`ConfigMismatch` unless checkpoint `record` belongs to a `kind` of run
    recorded as `current`, naming every field whose value differs.

    A run trained to its end may go on for more steps (a larger ``total_steps``) when nothing
    it did depends on the budget: not when its learning rate anneals over the run, and not
    for a sweep, whose finished groups would stay short.
    """
    if record.get("kind") != kind:
        raise ConfigMismatch(
            f"{directory} holds the checkpoints of a {record.get('kind')}, not of a {kind}"
        )
    saved = RunRecord.from_json(record["config"], f"the checkpoint's record in {directory}")
    steps, now = saved.config.total_steps, current.config.total_steps
    annealed = [r.config.anneal_learning_rate for r in (saved, current)]
    if now > steps and kind == "train" and not any(annealed):
        saved = dataclasses.replace(
            saved, config=dataclasses.replace(saved.config, total_steps=now)
        )
    elif now > steps and (
        kind != "train" or all(annealed)
    ):  # else the schedules differ: named below
        why = "its learning rate anneals over the run" if kind == "train" else "it is a sweep"
        raise ConfigMismatch(
            f"{directory} holds a run of {steps:,} steps, which cannot go on to {now:,}: "
            f"{why}. Use another checkpoint directory."
        )
    differing = saved.differences(current, "in the checkpoint", "now")
    if differing:
        raise ConfigMismatch(
            f"{directory} holds a run with a different configuration; differing: "
            + "; ".join(differing)
            + ". Resume with the checkpoint's settings, or use another checkpoint directory."
        )


class Checkpoints:
    """The checkpoints of one run (or one sweep) in `directory`, keeping the newest `keep` (a
    positive integer, as :class:`~fppo_jax.run.options.Options` checks it)."""

    def __init__(self, directory: str | Path, keep: int = 3):
        self.directory = Path(directory).absolute()
        self._lock: DirectoryLock | None = None
        if os.path.lexists(self.directory) and not self.directory.is_dir():
            raise InvalidInput(
                f"checkpoint directory {self.directory} is not a directory (a file, or a link "
                "that leads to none)"
            )
        self._manager = _manager(self.directory, keep)
        self._writes = Writes(self._manager, self.directory)

    def steps(self) -> list[int]:
        """Steps of the complete checkpoints, oldest first."""
        return committed_steps(self._manager)

    def latest_record(self) -> dict[str, Any] | None:
        """The record of the newest checkpoint whose record can be read, as JSON reads it, in
        whatever layout (no arrays are read: for checks before compiling); None if there is
        none."""
        import orbax.checkpoint as ocp

        for step in reversed(self.steps()):
            try:
                return cast(dict[str, Any], self._read(step, record=ocp.args.JsonRestore()).record)
            except Exception:  # a damaged record; restore() reports it
                continue
        return None

    def restore(
        self, like: Any, check: Callable[[CheckpointRecord], None] | None = None
    ) -> Restored | None:
        """The newest intact checkpoint, its state in the structure of `like` (arrays or
        ``jax.ShapeDtypeStruct``\\ s); damaged ones are reported and set aside. `check` sees
        the record of the one chosen, fallbacks included, and may raise. None if no
        checkpoint is intact."""
        import orbax.checkpoint as ocp

        leaves, treedef = jax.tree.flatten(like)
        abstract = {_name(i): _storable_shape(leaf) for i, leaf in enumerate(leaves)}
        for step in reversed(self.steps()):
            try:
                read = self._read(step, record=ocp.args.JsonRestore()).record
            except Exception as error:  # an unreadable record is damage
                self._set_aside(step, error)
                continue
            record = _checked(read, f"checkpoint at step {step} in {self.directory}")
            try:
                names = ["state", "curves"] + (["policy"] if record["policy"] else [])
                restore = {name: ocp.args.StandardRestore() for name in names}
                restore["state"] = ocp.args.StandardRestore(abstract)
                items = self._read(step, **restore)
                for name in names:
                    _verify(name, items[name], record)
            except Exception as error:  # any failure to read back is damage
                self._set_aside(step, error)
                continue
            if check is not None:
                check(record)
            state = [_from_storable(items.state[_name(i)], leaf) for i, leaf in enumerate(leaves)]
            return Restored(step, jax.tree.unflatten(treedef, state), items.curves, record)
        return None

    def save_point(
        self,
        point: ResumePoint,
        state: Any,
        *,
        kind: RunKind,
        config: RunRecord,
        runs_per_call: int,
        num_updates: int,
        policy: Policy | None = None,
    ) -> None:
        """Checkpoint a `kind` of run ("train" or "sweep") configured as `config` at `point`,
        with its `state` (and, for one run, its `policy`, which ``load_policy`` reads); the
        record names the point, which :meth:`Restored.point` reads back."""
        record: PointRecord = {
            "kind": kind,
            "config": config.to_json(),
            "group": point.group,
            "update": point.update,
            "runs_per_call": runs_per_call,
        }
        curves = Curves(current=point.current)
        if point.finished:
            curves["finished"] = point.finished
            curves["finished_diverged"] = point.finished_diverged
        self.save(point.group * num_updates + point.update, state, curves, record, policy)

    def save(
        self,
        step: int,
        state: Any,
        curves: Curves,
        record: PointRecord,
        policy: Policy | None = None,
    ) -> None:
        """Start writing checkpoint `step`; it completes in the background, and then the
        checkpoints beyond the newest `keep` are deleted. A checkpoint directory that vanished
        or was replaced since the run began is :class:`~fppo_jax.store.files.DirectoryLost`, at
        once."""
        import orbax.checkpoint as ocp

        if self._lock is not None:
            self._lock.check()
        host = jax.device_get(
            {_name(i): _storable(leaf) for i, leaf in enumerate(jax.tree.leaves(state))}
        )
        arrays = {"state": host, "curves": jax.device_get(curves)}
        if policy is not None:
            arrays["policy"] = jax.device_get(policy.arrays())
        sealed = artifact.seal(
            record,
            FORMAT,
            policy=policy.describe() if policy is not None else None,
            digests={name: tree_digest(value) for name, value in arrays.items()},
        )
        # Orbax waits for the previous save to finish before it starts this one.
        items = {name: ocp.args.StandardSave(value) for name, value in arrays.items()}
        args = _args(**items, record=ocp.args.JsonSave(sealed))
        self.wait()  # the one before, on disk: orbax would wait for it here anyway
        self._writes.start(step, args)

    def policy(self) -> tuple[Policy, CheckpointRecord]:
        """The policy of the newest readable checkpoint, and its record."""
        import orbax.checkpoint as ocp

        for step in reversed(self.steps()):
            try:
                read = self._read(step, record=ocp.args.JsonRestore()).record
            except Exception as error:  # try the previous one
                _warn(self.directory, step, error, "could not be read")
                continue
            where = f"checkpoint at step {step} in {self.directory}"
            record = _checked(read, where, POLICY_FORMATS)
            described = record.get("policy")
            try:
                if described is not None:
                    arrays = self._read(step, policy=ocp.args.StandardRestore()).policy
                    _verify("policy", arrays, record)
            except Exception as error:  # try the previous one
                _warn(self.directory, step, error, "could not be read")
                continue
            if described is None:
                raise InvalidInput(
                    f"{self.directory} holds the checkpoints of a {record.get('kind')}, not of "
                    "one policy: load_policy reads the checkpoints of train()"
                )
            return Policy.from_parts(described, arrays), record
        raise MissingFile(f"no readable checkpoint in {self.directory}")

    def _read(self, step: int, **items: Any) -> Any:
        return self._manager.restore(step, args=_args(**items))

    def wait(self) -> None:
        """Block until the checkpoint being written is complete;
        :class:`~fppo_jax.store.checkpoint_writes.CheckpointNotWritten` if it could not be."""
        self._writes.wait()

    def lock(self) -> None:
        """Make this the directory's one writer, or raise
        :class:`~fppo_jax.store.checkpoint_writes.CheckpointsUnavailable`
        naming the process that is (:class:`~fppo_jax.store.files.DirectoryLock`)."""
        try:
            self._lock = DirectoryLock(self.directory, "checkpoints")
        except DirectoryBusy as error:
            raise CheckpointsUnavailable(str(error)) from None

    def close(self, *, quiet: bool = False) -> None:
        """Finish writing, and let another process write here. `quiet`, when the run is already
        failing: a checkpoint still being written that fails too (into a directory that
        vanished, say) is let go rather than raised over the run's own error."""
        try:
            if not quiet:
                self.wait()
            self._manager.close()
        except Exception:
            if not quiet:
                raise
        finally:
            if self._lock is not None:
                self._lock.release()
                self._lock = None

    def _set_aside(self, step: int, error: Exception) -> None:
        target = artifact.set_aside(self.directory / str(step))
        self._manager.reload()
        _warn(self.directory, step, error, "is damaged", f"moved to {target}, ")


def _manager(directory: Path, keep: int) -> ocp.CheckpointManager:
    """Orbax's manager of `directory`'s checkpoints, writing in the background and keeping the
    newest `keep` (it deletes older ones only after a new one is committed); in a multi-process
    run this process alone writes there (the driver's process 0)."""
    # Orbax on first use, here and in each method: a run without checkpoints never waits for it.
    import orbax.checkpoint as ocp

    options = ocp.CheckpointManagerOptions(
        max_to_keep=keep, create=True, enable_async_checkpointing=True
    )
    if jax.process_count() > 1:
        alone = {jax.process_index()}
        options.multiprocessing_options = ocp.options.MultiprocessingOptions(
            primary_host=jax.process_index(), active_processes=alone
        )
        options.create = False  # orbax creates it with every process only
        directory.mkdir(parents=True, exist_ok=True)
    return ocp.CheckpointManager(directory, options=options)


def _warn(directory: Path, step: int, error: Exception, what: str, done: str = "") -> None:
    warnings.warn(
        f"checkpoint at step {step} in {directory} {what} "
        f"({type(error).__name__}: {first_line(error)}); {done}trying the previous one",
        DamagedCheckpoint,
        stacklevel=4,
    )


def _args(**items: Any) -> ocp.args.Composite:
    import orbax.checkpoint as ocp

    return ocp.args.Composite(**items)


def _name(index: int) -> str:
    return f"leaf_{index:05d}"


def _is_key(x: Any) -> bool:
    return jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key)  # type: ignore[attr-defined]  # jax.dtypes does not re-export it


def _storable(x: Any) -> Any:
    return jax.random.key_data(x) if _is_key(x) else x


def _storable_shape(x: Any) -> jax.ShapeDtypeStruct:
    if _is_key(x):
        return cast(jax.ShapeDtypeStruct, jax.eval_shape(jax.random.key_data, x))
    return jax.ShapeDtypeStruct(np.shape(x), x.dtype)


def _from_storable(x: np.ndarray, like: Any) -> Any:
    return jax.random.wrap_key_data(x) if _is_key(like) else x  # type: ignore[arg-type]  # host key data is a valid argument


def _checked(
    record: Mapping[str, object], what: str, formats: int | tuple[int, ...] = FORMAT
) -> CheckpointRecord:
    """`record`, a checkpoint's record item as JSON reads it (of `what`, in words), once shown
    to be in a layout of `formats` (:func:`~fppo_jax.store.files.check_format`)."""
    check_format(record, what, formats)
    return cast(CheckpointRecord, record)


def _verify(name: str, arrays: Any, record: CheckpointRecord) -> None:
    artifact.verify(arrays, record["digests"][name], name)
