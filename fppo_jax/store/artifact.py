"""An artifact: what fppo-jax writes to be read back later, as a record (JSON, naming its layout,
``format``, and the digest of the data it goes with) and its data, written whole or not at all
and read back checked. Saved policies (``policy.json`` and ``policy.npz``), sweeps
(``sweep.json`` and ``curves.csv``) and checkpoints (their record beside orbax's items) are
artifacts.

Writing: each data file under a temporary name, flushed and renamed, then the record the same
way, last: a process stopped between the renames leaves data that the record's digest refuses,
never a wrong artifact read as right (:func:`write`; checkpoints leave the files to orbax, which
commits a step whole, and take their record from :func:`seal`).

Reading: a record that is not a JSON object, or data that does not match the digest written
with it, is :class:`DamagedArtifact`, naming the file and what is wrong; a record of a layout
this code does not read is :class:`~fppo_jax.store.files.IncompatibleFormat` (intact: refused,
never taken for damage). A reader that can go on without a damaged artifact (checkpoints: the
one before it) moves it aside with :func:`set_aside`, so nothing is lost; the others leave it
where it is and raise.
"""

from __future__ import annotations

import io
import json
import shutil
from collections.abc import Mapping
from pathlib import Path
from typing import Any, cast

import numpy as np

from fppo_jax.errors import InvalidInput, MissingFile
from fppo_jax.store.files import check_format, json_value, tree_digest, write_atomically
from fppo_jax.store.shapes import mismatches


class DamagedArtifact(InvalidInput):
    """An artifact that cannot be read back intact: its record is not a JSON object, or its data
    do not match the digest written with them."""


def seal(record: Mapping[str, object], format: int, **written: object) -> dict[str, object]:
    """`record` as written: its layout (``format``) first, then `written` (the digests of its
    data, by name, and what else the writer adds), as JSON reads it back (tuples as lists,
    numpy scalars as numbers)."""
    return cast(dict[str, object], json_value({"format": format, **record, **written}))


def write(
    directory: Path, name: str, record: Mapping[str, object], data: Mapping[str, bytes]
) -> None:
    """The files `data` (by name) in `directory`, then the `record` (:func:`seal`-ed) as `name`,
    each under a temporary name, flushed and renamed; the record last."""
    directory.mkdir(parents=True, exist_ok=True)
    for file, content in data.items():
        write_atomically(directory / file, content)
    write_atomically(directory / name, (json.dumps(record, indent=2) + "\n").encode())


def read_record(
    path: Path, what: str, reads: int | tuple[int, ...], kind: str = "an object"
) -> dict[str, Any]:
    """The record at `path` (of `what`, in words: "the saved policy in …"), a JSON object (`kind`,
    in words, for the message if it is not) in layout `reads` (or one of them; a record without
    a ``format`` is in the first layout);
    :class:`DamagedArtifact` naming the file if it is not,
    :class:`~fppo_jax.store.files.IncompatibleFormat` if it is in another layout."""
    try:
        record = json.loads(path.read_bytes())
    except ValueError as error:  # not JSON, or not text: a file cut short or written over
        raise DamagedArtifact(f"{path} is not valid JSON ({error})") from None
    if not isinstance(record, dict):
        raise DamagedArtifact(f"{path} holds a {type(record).__name__}, not {kind}")
    check_format(record, what, reads)
    return record


def read_typed(path: Path, kind: Any, what: str, reads: int | tuple[int, ...] = 1) -> Any:
    """The JSON object at `path` (`what` it is, in words: "the tune's plan"), held to `kind` (a
    ``TypedDict`` or a mapping of them, :func:`~fppo_jax.store.shapes.mismatches`) apart from
    its ``format``: :class:`~fppo_jax.errors.MissingFile` if it is not there,
    :class:`DamagedArtifact` naming the file and the first place it differs,
    :class:`~fppo_jax.store.files.IncompatibleFormat` if it is in another layout."""
    if not path.is_file():
        raise MissingFile(f"{what} is missing ({path})")
    record = read_record(path, what, reads)
    check_shape({k: v for k, v in record.items() if k != "format"}, kind, path, what)
    return record


def check_shape(record: object, kind: Any, path: Path, what: str) -> None:
    """:class:`DamagedArtifact` naming `path` and the first place where `record`, read from it,
    is not of `kind` (:func:`read_typed`)."""
    differs = mismatches(record, kind)
    if differs:
        more = f" (and {len(differs) - 1} more)" if len(differs) > 1 else ""
        raise DamagedArtifact(
            f"{path} is not {what} as fppo-jax writes it: {differs[0]}{more}; restore it or "
            "remove it to record it again"
        )


def arrays_file(arrays: Mapping[str, np.ndarray]) -> bytes:
    """Named arrays as a ``.npz`` file's bytes (readable with ``numpy.load``)."""
    buffer = io.BytesIO()
    np.savez(buffer, allow_pickle=True, **arrays)  # numpy's default, named: no array takes it
    return buffer.getvalue()


def read_arrays(path: Path, digest: str) -> dict[str, np.ndarray]:
    """The named arrays of the ``.npz`` file at `path`, checked against `digest`
    (:func:`verify`)."""
    with np.load(path, allow_pickle=False) as npz:
        arrays = dict(npz)
    verify(arrays, digest)
    return arrays


def verify(arrays: Any, digest: str, name: str = "") -> None:
    """:class:`DamagedArtifact` unless the tree of `arrays` (its `name`, in words, if any) has
    `digest` (:func:`~fppo_jax.store.files.tree_digest`)."""
    if tree_digest(arrays) != digest:
        which = f"{name} arrays" if name else "arrays"
        raise DamagedArtifact(f"its {which} do not match the digest written with them")


def set_aside(path: Path) -> Path:
    """Move the damaged artifact at `path` (a file or a directory) into ``damaged/`` beside it,
    replacing one of the same name set aside before; returns where it now is."""
    target = path.parent / "damaged" / path.name
    target.parent.mkdir(exist_ok=True)
    shutil.rmtree(target, ignore_errors=True)
    shutil.move(path, target)
    return target
