"""A sweep's files, an artifact (:mod:`fppo_jax.store.artifact`): ``curves.csv`` (one row per
run and update, a column per metric) and ``sweep.json`` (the settings, seeds, runs,
configuration, times and the machines they were measured on, with the SHA-256 digest of that
``curves.csv`` and one of each run's values, by which a re-sorted or filtered ``curves.csv`` is
still known for its sweep's), each
written whole or not at all, the record last, and read back checked, every flaw named with its
file. ``sweep.json`` names its layout (:data:`FORMAT`); one of another layout is refused as
:class:`~fppo_jax.store.files.IncompatibleFormat`, not as damage."""

from __future__ import annotations

import csv
import hashlib
import io
import json
import warnings
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, NotRequired, TypedDict, cast

import numpy as np

from fppo_jax.core.config import Setting
from fppo_jax.core.trainer import METRICS
from fppo_jax.errors import InvalidInput, MissingFile
from fppo_jax.store import artifact
from fppo_jax.store.numpy_policy import digest

# The layout of sweep.json and curves.csv (files.check_format; a record without one is in the
# first). Raise it when a change would make an earlier reader misread what this one writes.
FORMAT = 1


class SweepRun(TypedDict):
    """One run of a sweep: its setting (an index into the sweep's settings) and its seed."""

    setting: int
    seed: int


class SweepRecord(TypedDict):
    """What a sweep's ``sweep.json`` says of it: its settings, its seeds, each run's setting and
    seed, the update each run diverged at (from 1) or 0, the sweep's record as JSON
    (:meth:`~fppo_jax.store.record.RunRecord.to_json`) and its compile and train times."""

    settings: list[Setting]
    seeds: list[int]
    runs: list[SweepRun]
    diverged: list[int]
    config: dict[str, Any]
    compile_seconds: float
    train_seconds: float
    machines: NotRequired[list[str]]  # those it trained on, named as describe_machine does


class SealedSweepRecord(SweepRecord):
    """``sweep.json`` as written and read back: the :class:`SweepRecord`, its layout, the digest
    of its ``curves.csv`` and each run's (which files written before them lack) over the
    metrics of ``digest_columns``."""

    format: NotRequired[int]
    curves_sha256: str
    digest_columns: NotRequired[list[str]]
    run_digests: NotRequired[list[str]]


def write_sweep(
    directory: str | Path, record: SweepRecord, metrics: Mapping[str, np.ndarray]
) -> None:
    """`curves.csv` with a column per name of `metrics` ([run, update] each), then
    `sweep.json`: `record` (``settings``, ``seeds``, ``runs``, ``diverged``, ``config``,
    ``compile_seconds``, ``train_seconds``) with the digests."""
    directory = Path(directory)
    keys = list(dict.fromkeys(k for s in record["settings"] for k in s))
    text = io.StringIO(newline="")
    writer = csv.writer(text)
    writer.writerow(["run", "seed", *keys, "update", *metrics])
    for i, run in enumerate(record["runs"]):
        setting = record["settings"][run["setting"]]
        head = [i, run["seed"], *[setting.get(k, "") for k in keys]]
        for u in range(metrics["env_steps"].shape[1]):
            values = [metrics[name][i, u].item() for name in metrics]
            writer.writerow([*head, u + 1, *values])
    curves = text.getvalue().encode()
    # Each run's values as a reader parses them back from the text written.
    digests = [
        _run_digest(np.array([[float(repr(x)) for x in metrics[m][i].tolist()] for m in metrics]).T)
        for i in range(len(record["runs"]))
    ]
    sealed = artifact.seal(
        record,
        FORMAT,
        curves_sha256=hashlib.sha256(curves).hexdigest(),
        digest_columns=list(metrics),
        run_digests=digests,
    )
    # sweep.json last, naming the curves it goes with: a process stopped between the two
    # renames leaves a pair that reading refuses, never one that reads as a wrong sweep.
    artifact.write(directory, "sweep.json", sealed, {"curves.csv": curves})


def read_sweep(
    directory: str | Path,
) -> tuple[SealedSweepRecord, dict[str, np.ndarray], list[int]]:
    """What :func:`write_sweep` wrote: its record, the metrics its `curves.csv` holds
    ([run, update]) and the indices of the runs it holds among the record's.

    Each row is placed by its ``run`` and ``update`` columns and each value by its column's
    name, so rows and columns may come in any order, and a `curves.csv` filtered to some runs
    gives those runs (with a warning saying how many of the sweep's it holds). An ``InvalidInput``
    naming the file says what is wrong with a ``sweep.json`` that is not JSON or lacks a key or
    a value of the kind written (:data:`RECORD`); with a `curves.csv` whose rows for a run are
    not the ones ``sweep.json`` was written with (by each run's digest: another sweep's curves,
    or an edited or torn file); and with one that is not every update of each of its runs once
    (a column, an update missing or repeated, a value not a number).
    """
    directory = Path(directory)
    for name in ("sweep.json", "curves.csv"):
        if not (directory / name).is_file():
            raise MissingFile(f"{directory / name} not found: not a sweep's output")
    record = _read_record(directory / "sweep.json")
    path = directory / "curves.csv"
    curves = path.read_bytes()
    whole = hashlib.sha256(curves).hexdigest() == record["curves_sha256"]
    if not whole and "run_digests" not in record:  # written before runs had digests
        raise InvalidInput(
            f"{path} is not the curves.csv that {directory / 'sweep.json'} was written with "
            "(its SHA-256 digest differs from the one recorded there): the two are not one "
            "sweep's results, e.g. a sweep stopped between writing them, or a file changed "
            "since"
        )
    text = curves.decode(errors="replace")
    keys = {key for setting in record["settings"] for key in setting}
    metrics, present = _read_curves(path, text, record["runs"], keys, every_run=whole)
    if not whole:
        _check_run_digests(path, directory / "sweep.json", record, metrics, present)
    num_updates = metrics["env_steps"].shape[1]
    beyond = [i for i in present if record["diverged"][i] > num_updates]
    if beyond:
        raise InvalidInput(
            f"{directory / 'sweep.json'}: diverged says run {_few(beyond)} diverged after "
            f"the last of the {num_updates} updates {path} holds"
        )
    if len(present) < len(record["runs"]):
        warnings.warn(
            f"{path} holds rows for {len(present)} of the {len(record['runs'])} runs of "
            f"{directory / 'sweep.json'}: the result is those runs",
            stacklevel=3,  # SweepResult.read's caller
        )
    return record, metrics, present


def _integer(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _list_of(values: Any, valid: Callable[[Any], bool]) -> bool:
    return isinstance(values, list) and all(valid(value) for value in values)


def _setting(value: Any) -> bool:
    return (
        isinstance(value, dict)
        and isinstance(value.get("variant"), str)
        and all(_number(v) for k, v in value.items() if k != "variant")
    )


def _run(value: Any, settings: int) -> bool:
    return (
        isinstance(value, dict)
        and _integer(value.get("setting"))
        and 0 <= value["setting"] < settings
        and _integer(value.get("seed"))
    )


# What a sweep's reader needs of sweep.json: each key, what its value must be, and the check
# (which may look at the keys before it, already checked).
RECORD: dict[str, tuple[str, Callable[[Any, dict[str, Any]], bool]]] = {
    "settings": (
        "a list of settings, each a variant and numbers",
        lambda v, r: _list_of(v, _setting),
    ),
    "seeds": ("a list of integers", lambda v, r: _list_of(v, _integer)),
    "runs": (
        "a list of runs, each a setting (an index into settings) and a seed",
        lambda v, r: _list_of(v, lambda run: _run(run, len(r["settings"]))),
    ),
    "diverged": (
        "a list of one update (from 1, or 0) per run",
        lambda v, r: _list_of(v, lambda d: _integer(d) and d >= 0) and len(v) == len(r["runs"]),
    ),
    "config": ("an object naming the env", lambda v, r: isinstance(v, dict) and "env" in v),
    "compile_seconds": ("a number", lambda v, r: _number(v)),
    "train_seconds": ("a number", lambda v, r: _number(v)),
    "curves_sha256": ("a SHA-256 digest in hex", lambda v, r: _digest(v)),
}
# Keys of sweep.json that files written before them lack, checked when there.
OPTIONAL_RECORD: dict[str, tuple[str, Callable[[Any, dict[str, Any]], bool]]] = {
    "digest_columns": (
        "a list of metric names",
        lambda v, r: _list_of(v, lambda name: isinstance(name, str)) and "env_steps" in v,
    ),
    "machines": (
        "a list of machines, each named in words",
        lambda v, r: _list_of(v, lambda name: isinstance(name, str)),
    ),
    "run_digests": (
        "a list of one SHA-256 digest per run",
        lambda v, r: _list_of(v, _digest) and len(v) == len(r["runs"]) and "digest_columns" in r,
    ),
}


def _digest(value: Any) -> bool:
    return isinstance(value, str) and len(value) == 64 and set(value) <= set("0123456789abcdef")


def _read_record(path: Path) -> SealedSweepRecord:
    """``sweep.json`` at `path`, checked against :data:`RECORD`; an ``InvalidInput`` naming the
    file says what is wrong with it."""
    what = f"the sweep record {path}"
    record = artifact.read_record(path, what, FORMAT, "a sweep's record (an object)")
    missing = [key for key in RECORD if key not in record]
    if missing:
        raise InvalidInput(f"{path} has no {', '.join(missing)}")
    checks = {**RECORD, **{k: v for k, v in OPTIONAL_RECORD.items() if k in record}}
    for key, (expected, valid) in checks.items():
        if not valid(record[key], record):
            found = json.dumps(record[key])
            found = found if len(found) <= 60 else found[:57] + "..."
            raise InvalidInput(f"{path}: {key} is {found}, not {expected}")
    return cast(SealedSweepRecord, record)


# The columns every reader of a sweep needs; the other metrics are read when they are there.
CURVES_NEEDED = ("run", "update", "env_steps", "average_return")


def _read_curves(
    path: Path,
    text: str,
    runs: Sequence[SweepRun],
    keys: set[str],
    *,
    every_run: bool = True,
) -> tuple[dict[str, np.ndarray], list[int]]:
    """The metrics of a sweep's `curves.csv` at `path`, whose `text` was read, [run, update]:
    every column but the run's, its seed's, its setting's (`keys`) and the update's, for the
    runs of `runs` (its ``sweep.json``'s) that it holds (all of them if `every_run`), and
    those runs' indices; an ``InvalidInput`` naming the file says what is wrong."""
    with io.StringIO(text, newline="") as f:
        reader = csv.DictReader(f)
        columns = reader.fieldnames or []
        missing = [name for name in CURVES_NEEDED if name not in columns]
        if missing:
            raise InvalidInput(f"{path} has no {', '.join(missing)} column")
        names = [name for name in METRICS if name in columns]
        names += [c for c in columns if c not in {*METRICS, *keys, "run", "seed", "update"}]
        cells: dict[tuple[int, int], list[float]] = {}
        for row in reader:
            where = f"{path}, line {reader.line_num}"
            if None in row or None in row.values():
                raise InvalidInput(f"{where}: not one value per column of the header")
            run, update = _cell(row, "run", where, int), _cell(row, "update", where, int)
            if update < 1:
                raise InvalidInput(f"{where}: update {update}, but updates count from 1")
            if (run, update) in cells:
                raise InvalidInput(f"{where}: run {run}, update {update} a second time")
            if "seed" in row and 0 <= run < len(runs):
                seed = _cell(row, "seed", where, int)
                if seed != runs[run]["seed"]:
                    raise InvalidInput(
                        f"{where}: run {run} has seed {seed}, sweep.json {runs[run]['seed']}"
                    )
            cells[run, update] = [_cell(row, name, where, float) for name in names]
    present, num_updates = _check_cells(path, cells, len(runs), every_run)
    row_of = {run: i for i, run in enumerate(present)}
    at = tuple(np.array([(row_of[run], update - 1) for run, update in cells]).T)
    values = np.array(list(cells.values()))
    metrics = {name: np.empty((len(present), num_updates)) for name in names}
    for name, column in zip(names, values.T, strict=True):
        metrics[name][at] = column
    metrics["env_steps"] = metrics["env_steps"].astype(np.int64)
    return metrics, present


def _check_cells(
    path: Path, cells: dict[tuple[int, int], list[float]], num_runs: int, every_run: bool
) -> tuple[list[int], int]:
    """The runs that `cells` (by run and update) hold, and their updates, once checked: runs of
    the sweep only (every one if `every_run`), each with every update up to the last."""
    if not cells:
        raise InvalidInput(f"{path} has no rows")
    found, expected = {run for run, _ in cells}, set(range(num_runs))
    if found - expected:
        raise InvalidInput(
            f"{path} has rows for run {_few(found - expected)}; sweep.json has {num_runs} runs"
        )
    if every_run and expected - found:
        raise InvalidInput(
            f"{path} has no rows for run {_few(expected - found)} of sweep.json's {num_runs}"
        )
    num_updates = max(update for _, update in cells)
    for run in sorted(found):
        lacking = [u for u in range(1, num_updates + 1) if (run, u) not in cells]
        if lacking:
            raise InvalidInput(
                f"{path}: run {run} has no update {_few(lacking)} (the file goes to update "
                f"{num_updates})"
            )
    return sorted(found), num_updates


def _run_digest(values: np.ndarray) -> str:
    """The SHA-256 of one run's values, [update, column], as float64: their bytes alone
    (:func:`~fppo_jax.store.numpy_policy.digest`, unlabelled)."""
    return digest([(None, np.asarray(values, np.float64))])


def _check_run_digests(
    path: Path,
    record_path: Path,
    record: SealedSweepRecord,
    metrics: Mapping[str, np.ndarray],
    present: Sequence[int],
) -> None:
    """Each run that `path` holds has the values `record` (its ``sweep.json``) was written
    with, whatever the order of rows and columns."""
    columns = record["digest_columns"]
    lacking = [name for name in columns if name not in metrics]
    if lacking:
        raise InvalidInput(f"{path} has no {', '.join(lacking)} column, which {record_path} lists")
    wrong = [
        run
        for i, run in enumerate(present)
        if _run_digest(np.stack([metrics[name][i] for name in columns], axis=1))
        != record["run_digests"][run]
    ]
    if wrong:
        raise InvalidInput(
            f"{path}: the rows of run {_few(wrong)} are not those {record_path} was written with "
            "(their digests differ): another sweep's curves.csv beside it, or an edited or torn "
            "file"
        )


def _cell(row: Mapping[str, str], column: str, where: str, kind: type) -> Any:
    try:
        return kind(row[column])
    except ValueError:
        number = "an integer" if kind is int else "a number"
        raise InvalidInput(f"{where}: {column} is {row[column]!r}, not {number}") from None


def _few(numbers: set[int] | list[int]) -> str:
    """Sorted, the first five and how many more."""
    numbers = sorted(numbers)
    more = f" and {len(numbers) - 5} more" if len(numbers) > 5 else ""
    return ", ".join(map(str, numbers[:5])) + more
