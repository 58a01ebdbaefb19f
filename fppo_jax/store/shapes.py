"""The shape of a JSON file as a type: a ``TypedDict`` (its required and ``NotRequired`` keys,
no others), lists, mappings, unions and plain values, checked all the way down. A record read
back is held to the type its writer declares, so that a file cut short, edited or of another
layout is named where it differs, never read as a ``KeyError`` three calls later."""

from __future__ import annotations

import types
import typing
from collections.abc import Mapping, Sequence
from typing import Any


def mismatches(value: object, kind: Any, where: str = "") -> list[str]:
    """Where `value` (JSON as read) is not of `kind`, each as ``"where: why"`` (empty if none);
    `where` is the path of `value` in the file (``.budget.hopper.rungs[0]``)."""
    if kind is Any or kind is object:
        return []
    if typing.is_typeddict(kind):
        return _record_mismatches(value, kind, where)
    origin, args = typing.get_origin(kind), typing.get_args(kind)
    if origin in (typing.Union, types.UnionType):
        tried = [mismatches(value, arm, where) for arm in args]
        return [] if any(not found for found in tried) else min(tried, key=len)
    if origin in (list, Sequence):
        if not isinstance(value, list):
            return [f"{where}: {value!r} is not a list"]
        return [
            m for i, item in enumerate(value) for m in mismatches(item, args[0], f"{where}[{i}]")
        ]
    if origin in (dict, Mapping):
        if not isinstance(value, dict):
            return [f"{where}: {value!r} is not an object"]
        return [m for k, item in value.items() for m in mismatches(item, args[1], f"{where}.{k}")]
    if kind is type(None):
        return [] if value is None else [f"{where}: {value!r} is not null"]
    if kind is float:  # JSON writes 2.0 as 2
        ok = isinstance(value, int | float) and not isinstance(value, bool)
    elif kind is int:
        ok = isinstance(value, int) and not isinstance(value, bool)
    else:
        ok = isinstance(value, kind)
    return [] if ok else [f"{where}: {value!r} is not {kind.__name__}"]


def _record_mismatches(value: object, kind: Any, where: str) -> list[str]:
    if not isinstance(value, dict):
        return [f"{where}: {value!r} is not an object"]
    hints = typing.get_type_hints(kind)  # NotRequired[X] read as X; required keys apart
    found = [f"{where}.{key}: not in {kind.__name__}" for key in value if key not in hints]
    # In the order the type declares them (its set of required keys has none, from run to run).
    required = [key for key in hints if key in kind.__required_keys__]
    found += [f"{where}.{key}: missing" for key in required if key not in value]
    for key, item in value.items():
        if key in hints:
            found += mismatches(item, hints[key], f"{where}.{key}")
    return found
