"""fppo_jax.core.digest: what tells a surrogate's function apart in a record, the values it reads
included."""

import functools
import sys

import jax.numpy as jnp
import pytest

from fppo_jax import surrogate

SCALE = 1.0  # read by _scaled: part of its surrogate's identity


def _scaled(ratio, advantage):
    return SCALE * ratio * advantage


def _scaled_by(scale):
    def scaled(ratio, advantage):
        return scale * ratio * advantage

    return scaled


def _scaled_with(scale, ratio, advantage):
    return scale * ratio * advantage


class _Scaled:
    def __init__(self, scale):
        self.scale = scale

    def __call__(self, ratio, advantage):
        return self.scale * ratio * advantage


WEIGHTS = jnp.ones(3)


def _weighted(ratio, advantage):
    return WEIGHTS.sum() * ratio * advantage


def test_a_surrogates_identity_covers_the_values_its_function_reads(monkeypatch):
    def digest(function):
        return surrogate("scaled", function).identity()["digest"]

    # A module's constant: a rerun, a resumed run or a merge of another value is refused.
    first = digest(_scaled)
    assert digest(_scaled) == first
    monkeypatch.setattr(sys.modules[__name__], "SCALE", 2.0)
    assert digest(_scaled) != first
    # A closure's variable, a partial's bound arguments and a callable instance's attributes:
    # the same made twice is the same surrogate, and another value another.
    for make in (_scaled_by, functools.partial(functools.partial, _scaled_with), _Scaled):
        assert digest(make(1.0)) == digest(make(1.0)) != digest(make(2.0))
    with pytest.raises(
        ValueError,
        match=r"^surrogate 'weighted' reads WEIGHTS, of type ArrayImpl, which its record cannot "
        "identify .*: make it a hyperparameter, or a number, string, bool, None, or a tuple, "
        "list or dict of them$",
    ):
        surrogate("weighted", _weighted)
