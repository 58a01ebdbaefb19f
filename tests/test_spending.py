"""The boundaries of a group-sequential test (fppo_jax.stats.spending): Lan–DeMets'
O'Brien–Fleming-type spending against published boundaries, two-sided and one-sided."""

import numpy as np
import pytest
from scipy import stats

from fppo_jax.stats.spending import boundaries


def test_boundaries_are_the_published_obrien_fleming_type_ones():
    # Lan–DeMets O'Brien–Fleming-type spending, five equally spaced looks, two-sided 0.05
    # (Jennison and Turnbull 2000, Table 7.5; gsDesign's sfLDOF at 0.025 a side).
    five = boundaries(0.05, (0.2, 0.4, 0.6, 0.8, 1.0))
    np.testing.assert_allclose(five, [4.8769, 3.3570, 2.6803, 2.2898, 2.0310], atol=2e-4)
    np.testing.assert_allclose(boundaries(0.05, (0.5, 1.0)), [2.9626, 1.9686], atol=2e-4)
    assert boundaries(0.05, (1.0,)) == pytest.approx((stats.norm.isf(0.025),), abs=1e-6)
    with pytest.raises(ValueError, match="must increase from above 0"):
        boundaries(0.05, (0.5, 0.5))


def test_one_sided_boundaries_are_the_published_ones():
    # gsDesign's sfLDOF, one-sided 0.025, five looks: the two-sided 0.05 values to 4 decimals
    # (no path crosses both); one look is the fixed one-sided test.
    five = (0.2, 0.4, 0.6, 0.8, 1.0)
    np.testing.assert_allclose(
        boundaries(0.025, five, sides=1), [4.8769, 3.3570, 2.6803, 2.2898, 2.0310], atol=2e-4
    )
    assert boundaries(0.05, (1.0,), sides=1) == pytest.approx((stats.norm.isf(0.05),), abs=1e-6)
    # One-sided at a is one side of the two-sided at 2a, less the paths crossing both sides.
    np.testing.assert_allclose(boundaries(0.05, five, sides=1), boundaries(0.1, five), atol=1e-6)
    with pytest.raises(ValueError, match="a boundary has 1 or 2 sides, got 3"):
        boundaries(0.05, five, sides=3)
