"""Writing checkpoints: orbax's writes, each finished in a background thread, and the one error a
write that storage refuses becomes (:class:`CheckpointNotWritten`, naming the newest intact
checkpoint), whether orbax raises it at once or only logs it in that thread.

:mod:`fppo_jax.store.checkpoint` writes and reads a run's checkpoints through these.
"""

from __future__ import annotations

import os
import re
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from fppo_jax.errors import FppoError, first_line

if TYPE_CHECKING:
    import orbax.checkpoint as ocp


class CheckpointsUnavailable(FppoError, RuntimeError):
    """A checkpoint directory cannot be used: another process writes there, or none of its
    checkpoints is intact."""


class CheckpointNotWritten(CheckpointsUnavailable):
    """A checkpoint could not be written (a full disk, a file size limit, storage gone); the
    checkpoints before it are intact."""


class Writes:
    """Orbax's writes of `directory`'s checkpoints, each finished in a background thread: a
    write that storage refuses, at once or in that thread, is :class:`CheckpointNotWritten`,
    naming the newest intact checkpoint."""

    def __init__(self, manager: ocp.CheckpointManager, directory: Path):
        self.manager, self.directory = manager, directory
        self.pending: int | None = None  # the step being written, until it is on disk

    def start(self, step: int, args: ocp.args.Composite) -> None:
        """Start writing checkpoint `step`."""
        if not self._written(lambda: self.manager.save(step, args=args)):
            raise RuntimeError(f"orbax refused to write checkpoint step {step} in {self.directory}")
        self.pending = step

    def wait(self) -> None:
        """Block until the checkpoint being written is on disk."""
        self._written(self.manager.wait_until_finished)
        self._check_written()

    def _written(self, write: Callable[[], Any]) -> Any:
        """`write`'s result, or :class:`CheckpointNotWritten` where it, or the checkpoint written
        before it in the background, failed to write (orbax raises what storage said, as an
        ``OSError`` or tensorstore's ``ValueError``); then whether that earlier one is on disk."""
        try:
            result = write()
        except Exception as error:
            if not _storage_failure(error):
                raise
            raise self._not_written(_storage_reason(error)) from error
        self._check_written()
        return result

    def _check_written(self) -> None:
        """Raise :class:`CheckpointNotWritten` if the step last started is not on disk now that
        orbax says it has finished: a failure in one of its background threads is logged there,
        not raised, and would otherwise pass for a checkpoint."""
        if self.pending is not None and not self.manager.is_saving_in_progress():
            step, self.pending = self.pending, None
            if step not in committed_steps(self.manager):
                raise self._not_written(f"step {step} is not on disk after writing it")

    def _not_written(self, why: str) -> CheckpointNotWritten:
        kept = committed_steps(self.manager)
        before = f"the newest intact one is step {kept[-1]}" if kept else "none is intact"
        return CheckpointNotWritten(
            f"could not write a checkpoint in {self.directory} ({why}); {before}. Free space, "
            "or choose another checkpoint directory, and resume (--resume)"
        )


def committed_steps(manager: ocp.CheckpointManager) -> list[int]:
    """The steps of `manager`'s complete checkpoints on disk now, oldest first."""
    manager.reload()
    return sorted(manager.all_steps())


def _storage_failure(error: BaseException) -> bool:
    """Whether `error` is storage refusing a write, as orbax passes it on: an ``OSError``, or
    tensorstore's ``ValueError`` that carries the operating system's error code."""
    return isinstance(error, OSError) or "os_error_code" in str(error)


def _storage_reason(error: Exception) -> str:
    """What storage said, in the operating system's words where it gave its error code."""
    if isinstance(error, OSError) and error.strerror:
        return error.strerror
    code = re.search(r"os_error_code='(\d+)'", str(error))
    return os.strerror(int(code.group(1))) if code else first_line(error)
