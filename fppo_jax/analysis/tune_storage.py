"""A tune's Optuna storage: which one (``optuna.db`` in the output, a database URL, or a journal
file ending ``.log``), as the plan records it, and opened so that its failures are one line.

Many tunes may share one storage (a PostgreSQL database for a cluster's nodes): each tune's
studies are named after its identity, ``<studies>/<task>/<name>``, where ``studies`` is twelve
hex digits of the SHA-256 of the plan, the storage and the output folder, recorded in
``tune.json`` (``storage.studies``) when the tune starts. Tunes with another plan, or in
another folder, never load, train or delete each other's studies. A tune recorded before its
plan held the storage keeps its studies' plain names, ``<task>/<name>``.

The storage is recorded without its password and checked on every later call (a resume, an
array task, the join): one that is not the storage the tune started with is refused by name.
Opening it checks each pooled connection before use (``pool_pre_ping``), so a server restarted
between two uses is reconnected to; a storage that fails while in use (a server down, a full
disk) is :class:`StorageFailed`, one line naming it with its password masked and the cause
that the database gave."""

from __future__ import annotations

import functools
import hashlib
import json
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from fppo_jax.analysis.tune_files import STORAGE_FILE
from fppo_jax.analysis.tuning_records import StorageRecord
from fppo_jax.errors import FppoError, InvalidInput, MissingPackage, first_line, install_hint

# A storage ending so (a path, not a URL) is Optuna's journal: a file many processes append to,
# on a filesystem the nodes share, with no database server.
JOURNAL_SUFFIX = ".log"

# Tries at opening a database that other processes are making at the same moment: each makes
# the tables Optuna lacks and stamps the schema's version, and all but one of them find the
# other's work half done. Seconds waited after the k-th failed try: k times this.
OPEN_TRIES, OPEN_BACKOFF = 10, 0.05

_STORAGE_FORMS = (
    "a database URL (sqlite:///path/optuna.db, postgresql://user@host/db) or a journal file "
    f"ending {JOURNAL_SUFFIX} (path/optuna.log)"
)


class StorageFailed(FppoError, OSError):
    """Optuna's storage could not be opened or failed while in use: the line names it (its
    password masked) and the cause the database or the filesystem gave."""


def storage_record(
    plan: Mapping[str, object], storage: str | None, output: str | Path
) -> StorageRecord:
    """What ``tune.json`` records of `storage` (None: ``optuna.db`` in `output`): the URL or the
    journal file with its password masked, and the prefix of the tune's study names, drawn
    from the rest of `plan`, the storage and the output folder. Refuses, before anything is
    written, a storage that is not one (:func:`storage_shown`)."""
    url = storage_shown(storage)
    identity = json.dumps(
        [{k: v for k, v in plan.items() if k != "storage"}, url, str(Path(output).resolve())],
        sort_keys=True,
    )
    return {"url": url, "studies": hashlib.sha256(identity.encode()).hexdigest()[:12]}


def storage_shown(storage: str | None) -> str:
    """`storage` as the plan and every message show it: ``optuna.db`` for None, a URL with its
    password masked, a journal file as given. Refuses an empty one, one in memory (lost when
    the tune ends), a URL of no database SQLAlchemy knows and one whose driver is missing."""
    if storage is None:
        return STORAGE_FILE
    if not isinstance(storage, str) or not storage.strip():
        raise InvalidInput(
            f"storage must name Optuna's storage, {_STORAGE_FORMS}, got {storage!r} (leave it "
            f"out for {STORAGE_FILE} in the output)"
        )
    if _journal(storage):
        return storage
    url = _url(storage)
    # As given, unless it holds a password (SQLAlchemy's rendering escapes a path's colons).
    shown: str = storage if url.password is None else url.render_as_string(hide_password=True)
    if url.get_backend_name() == "sqlite" and (
        url.database in (None, "", ":memory:") or url.query.get("mode") == "memory"
    ):
        raise InvalidInput(
            f"storage {shown} is a database in memory, lost when the tune ends: give a file "
            f"(sqlite:///path/optuna.db), a server's URL or a journal file (path/optuna.log)"
        )
    _check_driver(url, shown)
    return shown


def tune_storage(optuna: Any, storage: str | None, output: Path, plan: Mapping[str, object]) -> Any:
    """The storage of the tune in `output`, whose `plan` is the one recorded: opened
    (:func:`open_storage`), its studies named as the plan says; a storage other than the one
    recorded is refused, naming both."""
    recorded = plan.get("storage")
    shown = storage_shown(storage)
    if isinstance(recorded, dict) and recorded.get("url") != shown:
        was = recorded.get("url")
        give = "no --storage (storage=None)" if was == STORAGE_FILE else f"--storage {was}"
        raise InvalidInput(
            f"{output} holds a tune whose trials are in Optuna's storage {was}, not {shown}: "
            f"give {give}, as the tune started with, to go on or join it"
        )
    url = storage if storage is not None else f"sqlite:///{(output / STORAGE_FILE).absolute()}"
    studies = recorded.get("studies") if isinstance(recorded, dict) else None
    return open_storage(optuna, url, studies)


def study_name(storage: Any, task: str, name: str) -> str:
    """The name of `task`'s study `name` (``draws``, or an arm's) in the tune's `storage`:
    ``<studies>/<task>/<name>``, or ``<task>/<name>`` where it has no identity (a tune
    recorded before it had one)."""
    studies = getattr(storage, "studies", None)
    return f"{task}/{name}" if studies is None else f"{studies}/{task}/{name}"


def open_storage(optuna: Any, url: str, studies: str | None = None) -> Any:
    """Optuna's storage at `url` (a database URL, or a journal file ending ``.log``), opened (a
    SQLite database or a journal file is made if need be), whose failures in use are
    :class:`StorageFailed`; `studies` is the prefix of the tune's study names (None: none)."""
    shown = storage_shown(url)
    if _journal(url):
        journal = optuna.storages.journal
        try:
            inner = journal.JournalStorage(journal.JournalFileBackend(url))
        except OSError as error:
            raise StorageFailed(f"cannot open Optuna's storage {shown}: {_reason(error)}") from None
    else:
        inner = optuna.storages.get_storage(_database(optuna, url, shown))
    wrapper: Any = _told_class(optuna.storages.BaseStorage)(inner, shown, _password(url), studies)
    return wrapper


def _database(optuna: Any, url: str, shown: str) -> Any:
    """The database at `url`, opened, its connections checked before each use: tried again
    while other processes are making the same new database's tables."""
    tried = 0
    while True:
        tried += 1
        try:
            return optuna.storages.RDBStorage(url, engine_kwargs={"pool_pre_ping": True})
        except Exception as error:  # SQLAlchemy's and the database driver's own errors
            if tried < OPEN_TRIES and _made_meanwhile(error):
                time.sleep(OPEN_BACKOFF * tried)
                continue
            raise StorageFailed(
                f"cannot open Optuna's storage {shown}: {_reason(error, _password(url))}"
            ) from None


def _made_meanwhile(error: Exception) -> bool:
    """Whether `error` is another process making the same tables or stamping their version
    at the same time (a table that already exists, a version row already there)."""
    from sqlalchemy import exc

    if isinstance(error, exc.IntegrityError):
        return True
    text = str(error).lower()
    return isinstance(error, exc.DBAPIError) and (
        "already exists" in text or "database is locked" in text
    )


@functools.cache
def _told_class(base: type) -> type:
    """A storage of Optuna's kind `base` that passes every call on to the storage it holds and
    tells that storage's failures as :class:`StorageFailed`; Optuna's own answers (a study not
    found, a trial already finished) pass through as they are."""

    def passed_on(name: str) -> Callable[..., Any]:
        def method(self: Any, *args: Any, **kwargs: Any) -> Any:
            try:
                return getattr(self.inner, name)(*args, **kwargs)
            except Exception as error:
                if not _failure(error):
                    raise
                raise StorageFailed(
                    f"Optuna's storage {self.shown} failed: {_reason(error, self.secret)}; what "
                    "the tune recorded is kept: the same command goes on from it once the "
                    "storage works again"
                ) from None

        method.__name__ = name
        return method

    def __init__(
        self: Any, inner: Any, shown: str, secret: str | None, studies: str | None
    ) -> None:
        self.inner, self.shown, self.secret, self.studies = inner, shown, secret, studies

    methods = {
        name: passed_on(name)
        for name, value in vars(base).items()
        if callable(value) and not name.startswith("_")
    }
    return type("TuneStorage", (base,), {**methods, "__init__": __init__})


def _failure(error: Exception) -> bool:
    """Whether `error` is the storage failing (the database, its connection, the file) rather
    than Optuna answering a question."""
    import optuna
    from sqlalchemy import exc

    return isinstance(error, optuna.exceptions.StorageInternalError | exc.SQLAlchemyError | OSError)


def _reason(error: BaseException, password: str | None = None) -> str:
    """What the database or the filesystem said, in one line: Optuna's own wrapper (which
    guesses "invalid data") and SQLAlchemy's set aside; `password`, if given, masked."""
    from sqlalchemy import exc

    cause: BaseException = error
    while isinstance(cause.__cause__, Exception) and not isinstance(cause, exc.DBAPIError):
        cause = cause.__cause__
    if isinstance(cause, exc.DBAPIError) and cause.orig is not None:
        cause = cause.orig
    if isinstance(cause, OSError) and cause.strerror:
        said = f"{cause.strerror} ({cause.filename})" if cause.filename else cause.strerror
    else:
        said = first_line(cause)  # type: ignore[arg-type]
    said = said.rstrip(".")  # the line goes on after it
    return said.replace(password, "***") if password else said


def _password(url: str) -> str | None:
    from sqlalchemy.engine import make_url
    from sqlalchemy.exc import ArgumentError

    try:
        return make_url(url).password
    except ArgumentError:  # not a URL: a journal file, no password
        return None


def _journal(storage: str) -> bool:
    return "://" not in storage and storage.endswith(JOURNAL_SUFFIX)


def _url(storage: str) -> Any:
    from sqlalchemy.engine import make_url
    from sqlalchemy.exc import ArgumentError

    try:
        return make_url(storage)
    except ArgumentError:
        raise InvalidInput(f"storage must be {_STORAGE_FORMS}, got {storage!r}") from None


def _check_driver(url: Any, shown: str) -> None:
    """SQLAlchemy knows `url`'s database, and its driver is installed (the ``postgres`` extra
    brings psycopg, which ``postgresql://`` uses)."""
    from sqlalchemy.exc import NoSuchModuleError

    try:
        dialect = url.get_dialect()
    except NoSuchModuleError:
        raise InvalidInput(
            f"cannot open Optuna's storage {shown}: SQLAlchemy knows no database "
            f"{url.drivername!r}; give {_STORAGE_FORMS}"
        ) from None
    try:
        dialect.import_dbapi()
    except ImportError as error:
        module = error.name or first_line(error)
        hint = (
            install_hint("postgres")
            if module.split(".")[0] == "psycopg"
            else f"install the package that provides {module}"
        )
        raise MissingPackage(
            f"Optuna's storage {shown} needs the database driver {module}, not installed: {hint}"
        ) from None
