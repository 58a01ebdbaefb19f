"""Output directories checked writable before anything needs them, held by one writer and
watched for vanishing while it writes, and files written whole or not at all: under a temporary
name, then renamed into place, so that a reader, or a process killed mid-write, never leaves a
half-written file."""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import tempfile
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import jax
import numpy as np

from fppo_jax.errors import FppoError, InvalidInput
from fppo_jax.store.numpy_policy import digest


def writable_directory(path: str | Path) -> Path:
    """`path` as a directory that can be written, made if missing; an InvalidInput naming it and
    the reason otherwise, so that a run finds out before it trains rather than after."""
    path = Path(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=path):
            pass
    except FileExistsError:
        raise InvalidInput(
            f"cannot write to {path}: it is not a directory (a file, or a link that leads to none)"
        ) from None
    except OSError as error:
        raise InvalidInput(f"cannot write to {path}: {error.strerror or error}") from None
    return path


class DirectoryBusy(InvalidInput):
    """Another process is writing in a directory a run would write in."""


class DirectoryLost(InvalidInput):
    """A directory a run writes in vanished, or was replaced, while the run was writing."""


class IncompatibleFormat(InvalidInput):
    """A checkpoint or saved policy was written in another layout than this code reads."""


def check_format(record: Mapping[str, object], what: str, reads: int | tuple[int, ...]) -> None:
    """Raise :class:`IncompatibleFormat` unless `record` (of `what`, in words: "checkpoint at
    step 4 in …") is in layout `reads` (or one of them); a record without a ``format`` is in the
    first layout, written before layouts were recorded. Such a file is intact, so it is refused
    and left as it is, never taken for damage."""
    readable = reads if isinstance(reads, tuple) else (reads,)
    written = record.get("format", 1)
    if written not in readable:
        which = "a newer" if isinstance(written, int) and written > max(readable) else "another"
        formats = " or ".join(str(f) for f in readable)
        raise IncompatibleFormat(
            f"{what} was written by {which} version of fppo-jax (format {written!r}; this one "
            f"reads format {formats}). It is intact and was left as it is: read it with the "
            "fppo-jax that wrote it"
        )


class DirectoryLock:
    """The one writer of `directory` (holding ``.lock`` in it, ``flock``-ed), from before the
    first file is written until :meth:`release`; the operating system drops the lock when its
    holder exits, however it ends. :meth:`check` says, before each write, whether the
    directory is still the one locked."""

    def __init__(self, directory: str | Path, what: str, wait: float = 0.0) -> None:
        """`what` the directory holds, for messages ("checkpoints", "a run's outputs"); `wait`,
        the seconds to wait for another holder to let go (for holders that take turns)."""
        self.directory, self.what = Path(directory), what
        path = self.directory / ".lock"
        descriptor = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        deadline = time.monotonic() + wait
        while not _locked(descriptor):
            if time.monotonic() >= deadline:
                holder = os.pread(descriptor, 64, 0).decode(errors="replace").strip() or "unknown"
                os.close(descriptor)
                raise DirectoryBusy(
                    f"another process (pid {holder}) is writing {what} in {self.directory}; "
                    "wait for it to end, or choose another directory"
                )
            time.sleep(0.05)
        try:
            os.ftruncate(descriptor, 0)
            os.pwrite(descriptor, f"{os.getpid()}\n".encode(), 0)
        except OSError as error:  # a full disk: the lock is held, its holder's pid unwritten
            os.close(descriptor)
            raise NotWritten(f"cannot write {path}: {error.strerror or error}") from None
        self._descriptor: int | None = descriptor
        self._identity = _identity(self.directory)

    def check(self) -> None:
        """Raise :class:`DirectoryLost` if the directory is gone or another one stands there."""
        if _identity(self.directory) != self._identity:
            raise DirectoryLost(
                f"{self.directory}, where this run writes {self.what}, vanished or was replaced "
                "while it ran: what it had written there is lost, and the run stopped"
            )

    def after_chunk(self, chunk: object) -> bool:
        """As one of the driver's hooks: stops the run with :class:`DirectoryLost` once the
        directory is gone or replaced (:meth:`check`), else goes on."""
        self.check()
        return False

    def release(self) -> None:
        if self._descriptor is not None:
            os.close(self._descriptor)
            self._descriptor = None


def _locked(descriptor: int) -> bool:
    """Whether this process now holds the lock on `descriptor`'s file (never waiting)."""
    try:
        fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    return True


def _identity(directory: Path) -> tuple[int, int] | None:
    try:
        status = os.stat(directory)
    except OSError:
        return None
    return (status.st_dev, status.st_ino) if os.path.isdir(directory) else None


class NotWritten(FppoError, OSError):
    """A file that could not be written (a full disk, a quota, a read-only filesystem): what
    stood at its path before is kept, and no part of the new one is left."""


def write_atomically(path: Path, data: bytes) -> None:
    """`data` at `path`, written under a temporary name, flushed to disk and renamed;
    :class:`NotWritten` naming `path` if the system refuses it."""
    temporary = path.with_name(f".{path.name}.tmp")
    try:
        with open(temporary, "wb") as file:
            file.write(data)
            file.flush()
            os.fsync(file.fileno())
        os.replace(temporary, path)
    except OSError as error:
        # A full disk fails the write or the flush, whose error names no file: this names it.
        with contextlib.suppress(OSError):
            temporary.unlink(missing_ok=True)
        raise NotWritten(f"cannot write {path}: {error.strerror or error}") from None


def write_json(path: Path, value: Any) -> None:
    """`value` as indented JSON at `path`, atomically (numpy scalars as numbers)."""
    write_atomically(path, (json.dumps(value, indent=2, default=_plain) + "\n").encode())


def json_value(value: Any) -> Any:
    """`value` as :func:`write_json` writes it and ``json.load`` reads it back (tuples as
    lists, numpy scalars as numbers), to compare with a file's."""
    return json.loads(json.dumps(value, default=_plain))


def _plain(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"{type(value).__name__} is not JSON-serialisable")


def tree_digest(arrays: Any) -> str:
    """The SHA-256 of a tree of arrays: each leaf's path, dtype and shape, then its bytes, in
    the tree's order (what checkpoints and saved policies record of their arrays):
    :func:`fppo_jax.store.numpy_policy.digest`, each leaf labelled by its path."""
    leaves = jax.tree_util.tree_flatten_with_path(arrays)[0]
    return digest((jax.tree_util.keystr(path), leaf) for path, leaf in leaves)
