import collections
import itertools
import math

import jax
import numpy as np
import pytest

from fppo_jax.core.permutation import permutation, rounds


@pytest.mark.parametrize("n", [1, 2, 3, 7, 64, 511, 512, 513, 2048])
def test_draws_a_permutation_of_every_index(n: int) -> None:
    order = permutation(jax.random.key(n), n)
    assert order.dtype == np.int32
    assert sorted(np.asarray(order).tolist()) == list(range(n))


def test_each_key_draws_its_own_order_and_the_same_key_the_same() -> None:
    first, again, other = (permutation(jax.random.key(k), 512) for k in (0, 0, 1))
    np.testing.assert_array_equal(first, again)
    assert not np.array_equal(first, other)


def test_every_order_is_about_equally_likely() -> None:
    # 24,000 draws of the 24 orders of 4: 1,000 each expected, with a standard deviation of 31.
    keys = jax.random.split(jax.random.key(0), 24_000)
    orders = np.asarray(jax.vmap(permutation, (0, None))(keys, 4))
    counts = collections.Counter(map(tuple, orders))
    assert set(counts) == set(itertools.permutations(range(4)))
    assert 850 < min(counts.values()) and max(counts.values()) < 1150


def test_each_index_lands_anywhere_in_a_large_batch() -> None:
    # Index 0 and index 2047 over 4,096 shuffles of 2,048: their mean place is 1023.5 ± 9.2.
    keys = jax.random.split(jax.random.key(1), 4096)
    places = np.argsort(np.asarray(jax.vmap(permutation, (0, None))(keys, 2048)), axis=1)
    for index in (0, 2047):
        assert abs(places[:, index].mean() - 1023.5) < 50


@pytest.mark.parametrize("n", [2, 3, 256, 257, 4096, 4097, 2**16, 2**20, 2**24])
def test_rounds_give_each_element_at_least_three_log2_n_random_bits(n: int) -> None:
    index_bits = math.ceil(math.log2(n))
    random_bits = 32 - index_bits
    assert rounds(n) * random_bits >= 3 * index_bits
    assert (rounds(n) - 1) * random_bits < 3 * index_bits


def test_a_batch_past_two_to_the_24_takes_jax_permutation_itself() -> None:
    n, key = 2**24 + 1, jax.random.key(0)
    ours = jax.make_jaxpr(lambda k: permutation(k, n))(key)
    jax_own = jax.make_jaxpr(lambda k: jax.random.permutation(k, n))(key)
    assert str(ours) == str(jax_own)
