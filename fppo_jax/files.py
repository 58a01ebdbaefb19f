"""Output directories checked writable before anything needs them, and files written whole or
not at all: under a temporary name, then renamed into place, so that a reader, or a process
killed mid-write, never leaves a half-written file."""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np


def writable_directory(path: str | Path) -> Path:
    """`path` as a directory that can be written, made if missing; a ValueError naming it and
    the reason otherwise, so that a run finds out before it trains rather than after."""
    path = Path(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=path):
            pass
    except FileExistsError:
        raise ValueError(f"cannot write to {path}: it is a file, not a directory") from None
    except OSError as error:
        raise ValueError(f"cannot write to {path}: {error.strerror or error}") from None
    return path


def write_atomically(path: Path, data: bytes) -> None:
    """`data` at `path`, written under a temporary name, flushed to disk and renamed."""
    temporary = path.with_name(f".{path.name}.tmp")
    with open(temporary, "wb") as file:
        file.write(data)
        file.flush()
        os.fsync(file.fileno())
    os.replace(temporary, path)


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
