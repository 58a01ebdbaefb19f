"""An experiment under its plan: the plan is written in the experiment's folder before any run,
with the commit of the code, and every later call goes on only under the same plan, the fields
recorded only (the commit, where a copy of the folder now lies) aside. The folder is locked
while its plan is read and written, and while it trains; the tasks of a SLURM job array take
turns with the lock to check the plan, then train their shares side by side.

A study (``plan.json``) and a tune (``tune.json``) are both experiments of this kind; another
experiment (a race, say) takes the same steps through :class:`Preregistered`."""

from __future__ import annotations

import hashlib
import json
import subprocess
from collections.abc import Callable, Mapping
from pathlib import Path
from types import TracebackType
from typing import TypeVar, cast

from fppo_jax.errors import InvalidInput, MissingFile
from fppo_jax.store.files import DirectoryLock, writable_directory, write_json

# Any plan check_plan holds to: a study's, a tune's, as JSON.
Plan = TypeVar("Plan", bound=Mapping[str, object])


# Seconds an array task waits for the others that started with it to check the plan: each
# holds the folder's lock for that alone, well under a second, before it trains its share.
PART_LOCK_WAIT = 60.0


def commit() -> str:
    """The commit of the code that runs (``git rev-parse HEAD`` in the package's directory), or
    ``unknown`` outside a git checkout."""
    try:
        done = subprocess.run(
            ["git", "rev-parse", "HEAD"],
            cwd=Path(__file__).resolve().parent,
            capture_output=True,
            text=True,
            check=True,
            timeout=30,
        )
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return done.stdout.strip() or "unknown"


def plan_digest(path: Path, what: str) -> str:
    """The SHA-256 of the plan file at `path`, by which another experiment records that it
    stands on this one (`what` it is, in words, for the message if it is missing)."""
    if not path.is_file():
        raise MissingFile(f"{path.parent} holds no {what} ({path.name} is missing)")
    return hashlib.sha256(path.read_bytes()).hexdigest()


def check_plan(
    output: Path,
    plan: Plan,
    what: str,
    name: str,
    recorded_only: frozenset[str] = frozenset({"commit"}),
    upgrade: Callable[[dict[str, object]], dict[str, object]] | None = None,
) -> Plan:
    """Write `plan` as `name` in `output`, or check it against the one there: `what` (a study,
    a tune) goes on only under the plan it started with, the fields in `recorded_only` aside
    (the commit: a group records its own; ``field.key`` for one key of an object). A plan
    recorded by an earlier version is read through `upgrade` (to this code's form of the same
    plan) first. Returns the plan as recorded, with the commit it was made at (of `plan`'s
    shape: the file's fields are compared with it, one by one)."""
    path = output / name
    if not path.exists():
        write_json(path, plan)
        return plan
    try:
        recorded = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as error:
        raise InvalidInput(f"cannot read the plan {path}: {error}") from None
    if not isinstance(recorded, dict):
        raise InvalidInput(f"cannot read the plan {path}: it holds no JSON object")
    if upgrade is not None:
        recorded = upgrade(recorded)
    for field in dict.fromkeys([*recorded, *plan]):
        was, now = recorded.get(field), plan.get(field)
        if field in recorded_only or was == now:
            continue
        if isinstance(was, dict) and isinstance(now, dict):
            keys = [
                k
                for k in dict.fromkeys([*was, *now])
                if was.get(k) != now.get(k) and f"{field}.{k}" not in recorded_only
            ]
            if not keys:
                continue
            field, was, now = f"{field}.{keys[0]}", was.get(keys[0]), now.get(keys[0])
        raise InvalidInput(
            f"{output} holds {what} planned with {field} = {_shown(was)}, not {_shown(now)}: "
            f"{what} goes on only under its plan (start another in a new directory)"
        )
    return cast(Plan, recorded)


def _shown(value: object) -> str:
    return "none" if value is None else json.dumps(value)


class Preregistered:
    """An experiment's folder, `output`, from its plan's check to the call's end: locked
    throughout, except that an array task's (`shared`) lets go once it has read what the tasks
    must read in turn (:meth:`share_out`), to train its share beside the others."""

    def __init__(
        self,
        output: str | Path,
        what: str,
        *,
        shared: bool = False,
        apart_from: Mapping[str, str] | None = None,
    ) -> None:
        """`apart_from`: the plan files of other kinds of experiment (by file, what it is),
        whose folder this one refuses: its files would be written over theirs."""
        for name, other in (apart_from or {}).items():
            if (Path(output) / name).is_file():
                raise InvalidInput(
                    f"{output} holds {other} ({name}): {what} is written in a folder of its own "
                    "(give another --output)"
                )
        self.output = writable_directory(output)
        self.what, self.shared = what, shared
        self._lock = DirectoryLock(self.output, what, wait=PART_LOCK_WAIT if shared else 0.0)

    def check(
        self,
        plan: Plan,
        name: str,
        recorded_only: frozenset[str],
        upgrade: Callable[[dict[str, object]], dict[str, object]] | None = None,
    ) -> Plan:
        """`plan` written, or held to the one recorded (:func:`check_plan`)."""
        return check_plan(self.output, plan, self.what, name, recorded_only, upgrade)

    def share_out(self) -> None:
        """An array task lets go of the lock here: what each share writes is its own."""
        if self.shared:
            self._lock.release()

    def __enter__(self) -> Preregistered:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        error: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self._lock.release()
