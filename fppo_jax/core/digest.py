"""What tells a function apart in a record: a digest of its source and of the values it reads
beyond its arguments, so that two functions under one name (a surrogate of one's own changed
since a run was recorded) are not taken for each other."""

from __future__ import annotations

import contextlib
import dis
import functools
import hashlib
import inspect
import numbers
import types
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from fppo_jax.errors import InvalidInput


def function_digest(function: Callable[..., Any], where: str) -> str:
    """A short digest of what `function` computes with, so that a record tells two functions
    apart: its source (its compiled code where the source is not at hand) and the values it
    reads beyond its arguments (:func:`_identified`). `where` names the surrogate in the error
    that refuses a value that cannot be identified."""
    return hashlib.sha256(_identified(function, where, set())).hexdigest()[:16]


def _identified(function: Callable[..., Any], where: str, seen: set[int]) -> bytes:
    """The text that tells `function` apart: a function's source, then each global or closure
    variable it reads, as ``name=value``; a ``functools.partial``'s function, then its bound
    arguments; a callable instance's class, then its attributes. Modules, and functions and
    classes of other modules (named by the source), add nothing, so a function that reads
    nothing else is its source alone; `seen` holds the functions already identified."""
    function = inspect.unwrap(function)
    seen.add(id(function))
    if isinstance(function, functools.partial):
        bound = {**{f"args[{i}]": v for i, v in enumerate(function.args)}, **function.keywords}
        return _joined(
            _identified(function.func, where, seen),
            b"partial",
            _values(bound, getattr(function.func, "__module__", None), where, seen),
        )
    if isinstance(function, types.FunctionType):
        return _joined(
            _source(function), _values(_reads(function), function.__module__, where, seen)
        )
    cls = type(function)
    methods = [f for f in vars(cls).values() if isinstance(f, types.FunctionType)]
    try:
        text = inspect.getsource(cls).encode()
    except (OSError, TypeError):
        text = b"\n".join(_source(f) for f in methods)
    read = {name: value for f in methods for name, value in _reads(f).items()}
    return _joined(
        text,
        _values(read, cls.__module__, where, seen),
        _values(getattr(function, "__dict__", {}), cls.__module__, where, seen),
    )


def _joined(*parts: bytes) -> bytes:
    return b"\n".join(part for part in parts if part)


def _source(function: types.FunctionType) -> bytes:
    try:
        return inspect.getsource(function).encode()
    except (OSError, TypeError):
        code = function.__code__
        return code.co_code + repr(code.co_consts).encode()


def _reads(function: types.FunctionType) -> dict[str, object]:
    """The globals and closure variables `function` reads, by name, with their values."""
    read = {
        name: function.__globals__[name]
        for name in _global_names(function.__code__)
        if name in function.__globals__
    }
    for name, cell in zip(function.__code__.co_freevars, function.__closure__ or (), strict=True):
        with contextlib.suppress(ValueError):  # a cell not yet assigned holds nothing
            read[name] = cell.cell_contents
    return read


def _global_names(code: types.CodeType) -> list[str]:
    """The globals that `code` and the functions defined in it load, in order."""
    names = [i.argval for i in dis.get_instructions(code) if i.opname == "LOAD_GLOBAL"]
    for const in code.co_consts:
        if isinstance(const, types.CodeType):
            names += _global_names(const)
    return list(dict.fromkeys(names))


def _values(read: Mapping[Any, Any], module: str | None, where: str, seen: set[int]) -> bytes:
    """`read`'s values as ``name=value`` lines, those that identify something (see
    :func:`_identified`); one that cannot be identified is refused, naming it."""
    lines = []
    for name, value in read.items():
        if _plain(value):
            lines.append(f"{name}={value!r}".encode())
        elif isinstance(value, functools.partial) or (
            isinstance(value, types.FunctionType) and value.__module__ == module
        ):
            # A helper of the surrogate's own: what it computes with is the surrogate's too.
            if id(value) not in seen:
                lines.append(f"{name}=".encode() + _identified(value, where, seen))
        elif not (isinstance(value, types.ModuleType) or hasattr(value, "__name__")):
            raise InvalidInput(
                f"{where} reads {name}, of type {type(value).__name__}, which its record cannot "
                "identify (so a changed value would pass unseen): make it a hyperparameter, or "
                "a number, string, bool, None, or a tuple, list or dict of them"
            )
    return b"\n".join(lines)


def _plain(value: object) -> bool:
    """Whether `value` is plain data, whose ``repr`` identifies it: a number, a string, a
    bool, None, or a tuple, list or dict of them."""
    if value is None or isinstance(value, str | numbers.Number | np.bool_):
        return True
    if isinstance(value, tuple | list):
        return all(_plain(item) for item in value)
    if isinstance(value, dict):
        return all(_plain(key) and _plain(item) for key, item in value.items())
    return False
