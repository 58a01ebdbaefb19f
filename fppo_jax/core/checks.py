"""The checks of plain values that every layer makes alike, each written once: a positive
integer, a real number, a fraction such as a confidence level, a seed and a list of seeds, and
a part K/N of a sweep. Each returns the value checked (as a Python number) or raises
:class:`~fppo_jax.errors.InvalidInput` naming it."""

from __future__ import annotations

import numbers
from collections.abc import Sequence
from typing import Any, cast

import jax
import numpy as np

from fppo_jax.errors import InvalidInput

# The most seeds one setting may name: far more than a sweep trains, so more is a mistyped
# range, refused before a list of them is built.
MAX_SEEDS = 100_000


def positive_int(name: str, value: object) -> int:
    """`value` if it is a positive integer (numpy integers included, booleans not)."""
    if isinstance(value, bool | np.bool_) or not isinstance(value, int | np.integer) or value < 1:
        raise InvalidInput(f"{name} must be a positive integer, got {value!r}")
    return int(value)


def real_number(name: str, value: object) -> float:
    """`value` as a float if it is a real number (numpy's included); strings and booleans,
    which ``float`` would take, are refused."""
    if isinstance(value, str | bool | np.bool_) or not isinstance(
        value, numbers.Real | np.ndarray | jax.Array
    ):
        raise InvalidInput(f"{name} must be a number, got {value!r}")
    if np.ndim(cast(Any, value)) != 0:
        raise InvalidInput(
            f"{name} must be a single number, got an array of shape {np.shape(cast(Any, value))}"
        )
    return float(value)


def check_fraction(name: str, value: object, high: float = 1.0) -> float:
    """`value` as a float if it is a number strictly between 0 and `high`: a confidence or an
    error level (in (0, 1)), an equivalence margin (in (0, 0.5)). Anything else, a string or a
    boolean included, is refused in one message."""
    number = isinstance(value, numbers.Real) and not isinstance(value, bool | np.bool_)
    if not (number and 0 < cast(float, value) < high):
        raise InvalidInput(f"{name} must be in (0, {high:g}), got {value!r}")
    return float(cast(float, value))


def check_seed(seed: object) -> int:
    """`seed` if it is an integer that ``jax.random.key`` takes (numpy integers included)."""
    if isinstance(seed, bool | np.bool_) or not isinstance(seed, int | np.integer):
        raise InvalidInput(f"a seed must be an integer, got {seed!r}")
    if not -(2**63) <= seed < 2**64:
        raise InvalidInput(f"a seed must fit in 64 bits, got {seed}")
    return int(seed)


def check_seeds(seeds: object, shown: str | None = None, first: int = 0) -> list[int]:
    """Seeds `first` … `first` + n − 1 for a count n, else the given ones (a sequence, a range),
    checked: at least one, at most :data:`MAX_SEEDS` (counted before a list of them is built),
    each a seed (:func:`check_seed`), distinct, and distinct in the low 32 bits that JAX's keys
    keep. `shown` is how the seeds were written (a command line's text), for the messages."""
    if isinstance(seeds, int | np.integer) and not isinstance(seeds, bool | np.bool_):
        seeds = range(first, first + positive_int("seeds", seeds))
    elif (
        isinstance(seeds, str)
        or not isinstance(seeds, Sequence | np.ndarray)
        or (not isinstance(seeds, range) and np.ndim(cast(Any, seeds)) != 1)
    ):
        raise InvalidInput(f"seeds must be a count or a sequence of integers, got {seeds!r}")
    given = cast(Sequence[Any], seeds)
    count = max(0, given.stop - given.start) if isinstance(given, range) else len(given)
    if count > MAX_SEEDS:
        raise InvalidInput(f"at most {MAX_SEEDS:,} seeds may be given, got {count:,}")
    checked = [check_seed(seed) for seed in given]
    described = repr(checked) if shown is None else repr(shown)
    if not checked:
        raise InvalidInput(f"seeds must name at least one seed, got {described}")
    if len(set(checked)) < len(checked):
        raise InvalidInput(f"seeds must be distinct, got {described}")
    # JAX's keys (without 64-bit mode) keep a seed's low 32 bits: seeds equal there would train
    # the same run twice, and count it as two.
    by_low_bits: dict[int, int] = {}
    for seed in checked:
        other = by_low_bits.setdefault(seed % 2**32, seed)
        if other != seed:
            raise InvalidInput(
                f"seeds {other} and {seed} give the same key (JAX keeps a seed's low 32 bits), "
                "so the same run: choose seeds that differ below 2**32"
            )
    return checked


def parse_seeds(text: str) -> list[int]:
    """Seeds written on a command line: ``20`` (seeds 0 … 19), ``10:20`` (seeds 10 … 19, as
    Python's ``range(10, 20)``) or a comma list such as ``0,3,7``, checked (:func:`check_seeds`)."""
    seeds: int | range | list[int]
    try:
        if ":" in text:
            start, stop = (int(part) for part in text.split(":"))
            seeds = range(start, stop)
        elif "," in text:
            seeds = [int(part) for part in text.split(",")]
        else:
            seeds = int(text)
    except ValueError:
        raise InvalidInput(
            f"seeds {text!r} are not a count (20), a range (10:20) or a list (0,3,7)"
        ) from None
    return check_seeds(seeds, shown=text)


def check_part(part: object, shown: str | None = None) -> tuple[int, int]:
    """`part` as (K, N) if it is the K-th of N shares (of a sweep, a study's look, a tune's
    rung): two integers (numpy's included), 1 <= K <= N. `shown` is how it was written (a
    command line's ``K/N``), for the message."""
    if (
        not isinstance(part, tuple | list)
        or len(part) != 2
        or not all(isinstance(x, int | np.integer) and not isinstance(x, bool) for x in part)
        or not 1 <= part[0] <= part[1]
    ):
        described = repr(part) if shown is None else repr(shown)
        raise InvalidInput(f"part must be the K-th of N parts, 1 <= K <= N, got {described}")
    return int(part[0]), int(part[1])
