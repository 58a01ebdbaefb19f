"""fppo_jax.store.shapes: a JSON value held to its type all the way down, each place it differs
named by its path: a key missing, a key the type lacks, a value of another type, in lists,
mappings and unions; ``NotRequired`` keys may be absent."""

from typing import NotRequired, TypedDict

from fppo_jax.store.shapes import mismatches


class Inner(TypedDict):
    trials: int
    score: float | None


class Outer(TypedDict):
    name: str
    rungs: list[Inner]
    by_task: dict[str, Inner]
    note: NotRequired[str]


GOOD = {
    "name": "tune",
    "rungs": [{"trials": 9, "score": 1.5}, {"trials": 3, "score": None}],
    "by_task": {"cartpole": {"trials": 1, "score": 2}},  # JSON writes 2.0 as 2
}


def test_a_value_of_its_shape_has_no_mismatch():
    assert mismatches(GOOD, Outer) == []
    assert mismatches({**GOOD, "note": "a key NotRequired may be there"}, Outer) == []


def test_each_place_that_differs_is_named_by_its_path():
    bad = {
        "rungs": [{"trials": True, "score": 1.0}, "nine"],
        "by_task": {"cartpole": {"trials": 1, "score": "high"}},
        "extra": 1,
    }
    assert sorted(mismatches(bad, Outer)) == [
        ".by_task.cartpole.score: 'high' is not float",
        ".extra: not in Outer",
        ".name: missing",
        ".rungs[0].trials: True is not int",
        ".rungs[1]: 'nine' is not an object",
    ]
    assert mismatches([1, 2], Outer) == [": [1, 2] is not an object"]
    assert mismatches({"a": [1]}, dict[str, list[str]]) == [".a[0]: 1 is not str"]
