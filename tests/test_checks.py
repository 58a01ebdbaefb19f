"""fppo_jax.core.checks: the checks of plain values made alike in every layer, and their
messages."""

import re

import numpy as np
import pytest
from helpers import BAD_SEEDS

from fppo_jax.core.checks import (
    check_fraction,
    check_part,
    check_seed,
    check_seeds,
    parse_seeds,
    positive_int,
    real_number,
)


def test_positive_int_takes_python_and_numpy_integers_and_returns_a_python_int():
    for value in (1, 7, np.int64(7), np.int32(7), np.uint8(7)):
        checked = positive_int("n", value)
        assert checked == int(value) and type(checked) is int


@pytest.mark.parametrize(
    "value", [0, -1, True, np.bool_(True), 2.0, np.float32(2.0), "3", None, [3]]
)
def test_positive_int_refuses_anything_else_naming_the_setting_and_the_value(value):
    with pytest.raises(
        ValueError, match=re.escape(f"width must be a positive integer, got {value!r}")
    ):
        positive_int("width", value)


def test_check_seed_takes_every_64_bit_integer_signed_or_not():
    for seed in (0, -5, -(2**63), 2**63, 2**64 - 1, np.uint64(2**64 - 1), np.int8(-3)):
        checked = check_seed(seed)
        assert checked == int(seed) and type(checked) is int


@pytest.mark.parametrize(
    "seed, message",
    [
        (True, "a seed must be an integer, got True"),
        (1.0, "a seed must be an integer, got 1.0"),
        ("1", "a seed must be an integer, got '1'"),
        (None, "a seed must be an integer, got None"),
        (2**64, f"a seed must fit in 64 bits, got {2**64}"),
        (-(2**63) - 1, f"a seed must fit in 64 bits, got {-(2**63) - 1}"),
    ],
)
def test_check_seed_refuses_non_integers_and_seeds_beyond_64_bits(seed, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        check_seed(seed)


@pytest.mark.parametrize(
    "text, seeds",
    [
        ("3", [0, 1, 2]),  # a count
        ("1", [0]),
        ("10:13", [10, 11, 12]),  # a range, as range(10, 13)
        ("-2:1", [-2, -1, 0]),
        ("0,3,7", [0, 3, 7]),  # a list, in its order
        ("7,0", [7, 0]),
    ],
)
def test_parse_seeds_reads_a_count_a_range_or_a_list(text, seeds):
    assert parse_seeds(text) == seeds


@pytest.mark.parametrize(
    "text, message",
    [
        ("abc", "seeds 'abc' are not a count (20), a range (10:20) or a list (0,3,7)"),
        ("1.5", "seeds '1.5' are not a count"),
        ("1:2:3", "seeds '1:2:3' are not a count"),
        ("3,", "seeds '3,' are not a count"),
        ("", "seeds '' are not a count"),
        ("0", "seeds must be a positive integer, got 0"),
        ("-1", "seeds must be a positive integer, got -1"),
        ("5:5", "seeds must name at least one seed, got '5:5'"),
        ("6:2", "seeds must name at least one seed, got '6:2'"),
        ("1,2,1", "seeds must be distinct, got '1,2,1'"),
        (f"0,{2**64}", f"a seed must fit in 64 bits, got {2**64}"),
        (f"0,{2**32}", f"seeds 0 and {2**32} give the same key"),
        # Refused by their count, before a list of them is built.
        ("0:10000000000", "at most 100,000 seeds may be given, got 10,000,000,000"),
        ("100001", "at most 100,000 seeds may be given, got 100,001"),
    ],
)
def test_parse_seeds_refuses_what_names_no_distinct_valid_seeds(text, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        parse_seeds(text)


@pytest.mark.parametrize(
    "seeds, message",
    BAD_SEEDS,
)
def test_check_seeds_refuses_what_names_no_distinct_valid_seeds(seeds, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        check_seeds(seeds)


def test_check_seeds_takes_a_count_a_sequence_or_an_array():
    assert check_seeds(3) == [0, 1, 2]
    assert check_seeds(2, first=1_000_000) == [1_000_000, 1_000_001]
    assert check_seeds(np.int64(2)) == [0, 1]
    assert check_seeds([7, 0]) == [7, 0]
    assert check_seeds(range(10, 12)) == [10, 11]
    assert check_seeds(np.array([4, 5])) == [4, 5]


def test_real_number_takes_numbers_and_refuses_strings_booleans_and_arrays():
    assert real_number("x", np.float32(0.5)) == 0.5 and real_number("x", 3) == 3.0
    for value, message in (
        ("1", "x must be a number, got '1'"),
        (True, "x must be a number, got True"),
        (np.ones(2), "x must be a single number, got an array of shape (2,)"),
    ):
        with pytest.raises(ValueError, match=re.escape(message)):
            real_number("x", value)


def test_check_fraction_takes_numbers_strictly_inside_and_refuses_the_rest_in_one_message():
    assert check_fraction("the level", 0.05) == 0.05
    assert check_fraction("the level", np.float32(0.5)) == 0.5
    assert check_fraction("the margin", 0.2, 0.5) == 0.2
    for value in (0, 1, 1.5, -0.1, float("nan"), "0.9", None, True):
        with pytest.raises(
            ValueError, match=re.escape(f"the level must be in (0, 1), got {value!r}")
        ):
            check_fraction("the level", value)
    with pytest.raises(ValueError, match=re.escape("the margin must be in (0, 0.5), got 0.5")):
        check_fraction("the margin", 0.5, 0.5)


def test_check_part_takes_k_of_n_and_refuses_anything_else():
    assert check_part((2, 3)) == (2, 3)
    assert check_part([np.int64(1), np.int64(1)]) == (1, 1)
    for bad in ((0, 2), (3, 2), (1.0, 2), "1/2", (1, 2, 3), (True, 2)):
        with pytest.raises(
            ValueError,
            match=re.escape(f"part must be the K-th of N parts, 1 <= K <= N, got {bad!r}"),
        ):
            check_part(bad)
