"""The errors a user can act on.

Every expected failure (bad input, a missing optional package, a refused or damaged record, a
run that cannot go on) is a :class:`FppoError`; the command line prints it in one line. Any
other exception is a bug and keeps its traceback. Each kind also derives from the built-in
exception a caller would catch for it (``ValueError`` for bad input, ``ImportError`` for a
missing package, ``FileNotFoundError`` for a missing file), so ``except ValueError`` keeps
working.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable


class FppoError(Exception):
    """An expected failure, told in one line that names the problem and what to do."""


class InvalidInput(FppoError, ValueError):
    """An argument, option, setting or file whose value is not accepted."""


class MissingPackage(FppoError, ImportError):
    """An optional package (or a piece of one) that this use needs is not installed."""


class MissingFile(FppoError, FileNotFoundError):
    """A file or directory that was named, or that a record needs, is not there."""


class NotEnoughMemory(FppoError, MemoryError):
    """What was asked for would not fit in this machine's memory."""


def install_hint(extra: str) -> str:
    """The command that installs the package's optional `extra` (``pyproject.toml``), for an
    install from the package index and from a clone of the repository alike: what a
    :class:`MissingPackage` tells the user to run."""
    return f"pip install 'fppo-jax[{extra}]' (from a clone: pip install -e '.[{extra}]')"


def first_line(error: Exception) -> str:
    """An error's message, its first line, for a report of what could not be read."""
    text = str(error).strip()
    return text.splitlines()[0][:200] if text else "no message"


def did_you_mean(name: str, known: Iterable[str]) -> str:
    """The end of a message refusing `name`: the nearest of `known` (up to three, by
    :func:`difflib.get_close_matches`) as "; did you mean a or b?", or nothing."""
    return suggested(difflib.get_close_matches(name, list(known), n=3))


def suggested(names: list[str]) -> str:
    """`names` offered as "; did you mean a or b?" at a message's end, or nothing."""
    return f"; did you mean {' or '.join(names)}?" if names else ""
