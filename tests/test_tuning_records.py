"""Every recorded tune's files hold the shapes ``tuning_records`` gives them: each key a type
requires is there, no key is one the type lacks, and each value is of its key's type, all the
way down. A shape that drifted from what the tune writes fails here."""

import json
import types
import typing
from collections.abc import Mapping, Sequence
from pathlib import Path

import pytest

from fppo_jax.analysis.tuning_records import ArmResults, RungScores, ShareScores, TunePlan

TUNED = Path(__file__).resolve().parent.parent / "experiments" / "results" / "tuned"
TUNES = sorted(path.parent for path in TUNED.rglob("tune.json"))


def mismatches(value, kind, where="") -> list[str]:
    """Where `value` (JSON as read) is not of `kind`, each as ``"where: why"`` (empty if none)."""
    if kind is typing.Any or kind is object:
        return []
    if typing.is_typeddict(kind):
        if not isinstance(value, dict):
            return [f"{where}: {value!r} is not an object"]
        hints = typing.get_type_hints(kind)
        found = [f"{where}.{key}: not in {kind.__name__}" for key in value if key not in hints]
        found += [f"{where}.{key}: missing" for key in kind.__required_keys__ if key not in value]
        for key, item in value.items():
            if key in hints:
                found += mismatches(item, hints[key], f"{where}.{key}")
        return found
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
    if kind is float:
        ok = isinstance(value, int | float) and not isinstance(value, bool)
    elif kind is int:
        ok = isinstance(value, int) and not isinstance(value, bool)
    else:
        ok = isinstance(value, kind)
    return [] if ok else [f"{where}: {value!r} is not {kind.__name__}"]


def test_there_are_recorded_tunes_to_check():
    assert len(TUNES) >= 2, TUNES


@pytest.mark.parametrize("tune", TUNES, ids=lambda path: str(path.relative_to(TUNED)))
def test_a_recorded_tune_holds_its_files_shapes(tune):
    plan = json.loads((tune / "tune.json").read_text())
    assert mismatches(plan, TunePlan) == []
    results = json.loads((tune / "results.json").read_text())
    assert mismatches(results, dict[str, dict[str, ArmResults]]) == []
    rungs = sorted(tune.glob("*/rung-*/scores.json"))
    assert rungs
    for path in rungs:
        assert mismatches(json.loads(path.read_text()), RungScores) == [], path
    for path in tune.glob("*/rung-*/part-*/scores.json"):
        assert mismatches(json.loads(path.read_text()), ShareScores) == [], path


def test_a_key_missing_added_or_of_another_type_is_named():
    plan = json.loads((TUNES[0] / "tune.json").read_text())
    assert mismatches(plan, TunePlan) == []
    del plan["eta"]
    plan["extra"] = 1
    plan["budget"][plan["tasks"][0]]["rungs"][0]["trials"] = "nine"
    assert sorted(mismatches(plan, TunePlan)) == [
        f".budget.{plan['tasks'][0]}.rungs[0].trials: 'nine' is not int",
        ".eta: missing",
        ".extra: not in TunePlan",
    ]
