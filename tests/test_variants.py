"""Every variant's value and slope against the paper's definitions (Eq. 22 with its sign
corrected), region by region."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fppo_jax import VARIANTS, negative_regions, objective

EPS = 0.2
LO, HI = 1 - EPS, 1 + EPS


def value_and_slope(obj, r, a, kl=0.0):
    """L(r, A) and ∂L/∂r at one point."""
    f = lambda r_: obj(r_, jnp.float32(a), jnp.float32(kl))  # noqa: E731
    value, slope = jax.value_and_grad(f)(jnp.float32(r))
    return float(value), float(slope)


# (variant, hyperparameters, r, A, KL, expected value, expected slope), by the paper's definitions.
alpha, k, rb, delta = 1.3, 0.4, 0.3, 0.035
CASES = [
    # PPO: slope A inside, 0 where clipped, A in R± (the min keeps rA).
    ("ppo", {}, 1.1, 2.0, 0, 2.2, 2.0),
    ("ppo", {}, 1.5, 2.0, 0, HI * 2.0, 0.0),
    ("ppo", {}, 0.5, -2.0, 0, LO * -2.0, 0.0),
    ("ppo", {}, 0.5, 2.0, 0, 1.0, 2.0),  # R+
    ("ppo", {}, 1.5, -2.0, 0, -3.0, -2.0),  # R-
    # FPPO-LP: slope αA in R±, as PPO elsewhere.
    ("fppo-lp", {"alpha": alpha}, 0.5, 2.0, 0, (alpha * 0.5 + (1 - alpha) * LO) * 2.0, alpha * 2.0),
    (
        "fppo-lp",
        {"alpha": alpha},
        1.5,
        -2.0,
        0,
        (alpha * 1.5 + (1 - alpha) * HI) * -2.0,
        alpha * -2.0,
    ),
    ("fppo-lp", {"alpha": alpha}, 1.5, 2.0, 0, HI * 2.0, 0.0),
    ("fppo-lp", {"alpha": alpha}, 0.5, -2.0, 0, LO * -2.0, 0.0),
    ("fppo-lp", {"alpha": alpha}, 0.9, 2.0, 0, 1.8, 2.0),
    # FPPO-QP (corrected R+ branch): F = r - k d² in R+, r + k d² in R-, slope (1 + 2kd)A.
    (
        "fppo-qp",
        {"k": k},
        0.5,
        2.0,
        0,
        (0.5 - k * (LO - 0.5) ** 2) * 2.0,
        (1 + 2 * k * (LO - 0.5)) * 2.0,
    ),
    (
        "fppo-qp",
        {"k": k},
        1.5,
        -2.0,
        0,
        (1.5 + k * (1.5 - HI) ** 2) * -2.0,
        (1 + 2 * k * (1.5 - HI)) * -2.0,
    ),
    ("fppo-qp", {"k": k}, 1.5, 2.0, 0, HI * 2.0, 0.0),
    ("fppo-qp", {"k": k}, 1.0, -2.0, 0, -2.0, -2.0),
    # PPO-RB: slope -αA where PPO clips, A in R± (min keeps rA), A inside.
    ("ppo-rb", {"alpha": rb}, 1.5, 2.0, 0, (-rb * 1.5 + (1 + rb) * HI) * 2.0, -rb * 2.0),
    ("ppo-rb", {"alpha": rb}, 0.5, -2.0, 0, (-rb * 0.5 + (1 + rb) * LO) * -2.0, -rb * -2.0),
    ("ppo-rb", {"alpha": rb}, 0.5, 2.0, 0, 1.0, 2.0),
    ("ppo-rb", {"alpha": rb}, 1.5, -2.0, 0, -3.0, -2.0),
    ("ppo-rb", {"alpha": rb}, 1.1, 2.0, 0, 2.2, 2.0),
    # TR-PPO: constant A (slope 0) once KL ≥ δ and rA ≥ A, else rA; no ratio clipping.
    ("tr-ppo", {"delta": delta}, 1.5, 2.0, 0.1, 2.0, 0.0),
    ("tr-ppo", {"delta": delta}, 1.5, 2.0, 0.01, 3.0, 2.0),
    ("tr-ppo", {"delta": delta}, 0.5, 2.0, 0.1, 1.0, 2.0),
    ("tr-ppo", {"delta": delta}, 0.5, -2.0, 0.1, -2.0, 0.0),
    ("tr-ppo", {"delta": delta}, 1.5, -2.0, 0.1, -3.0, -2.0),
    # TR-PPO-RB: value rA and slope -αA once KL ≥ δ and rA > A, else rA.
    ("tr-ppo-rb", {"alpha": 0.05, "delta": 0.03}, 1.5, 2.0, 0.1, 3.0, -0.05 * 2.0),
    ("tr-ppo-rb", {"alpha": 0.05, "delta": 0.03}, 0.5, -2.0, 0.1, -1.0, -0.05 * -2.0),
    ("tr-ppo-rb", {"alpha": 0.05, "delta": 0.03}, 1.5, 2.0, 0.01, 3.0, 2.0),
    ("tr-ppo-rb", {"alpha": 0.05, "delta": 0.03}, 0.5, 2.0, 0.1, 1.0, 2.0),
    # SPO: rA - |A|(r - 1)²/(2ε), slope A - |A|(r - 1)/ε: zero at 1 + ε sign(A), never flat.
    ("spo", {}, 1.1, 2.0, 0, 2.2 - 2.0 * 0.1**2 / (2 * EPS), 2.0 - 2.0 * 0.1 / EPS),
    ("spo", {}, 1.5, 2.0, 0, 3.0 - 2.0 * 0.5**2 / (2 * EPS), 2.0 - 2.0 * 0.5 / EPS),
    ("spo", {}, 0.5, -2.0, 0, -1.0 - 2.0 * 0.5**2 / (2 * EPS), -2.0 + 2.0 * 0.5 / EPS),
    ("spo", {}, HI, 2.0, 0, HI * 2.0 - 2.0 * EPS / 2, 0.0),
    ("spo", {}, LO, -2.0, 0, LO * -2.0 - 2.0 * EPS / 2, 0.0),
    # Clip-higher (DAPO): PPO's min with the bounds 1 - ε_low and 1 + ε_high.
    ("clip-higher", {}, 1.25, 2.0, 0, 2.5, 2.0),
    ("clip-higher", {}, 1.5, 2.0, 0, 1.28 * 2.0, 0.0),
    ("clip-higher", {"eps_high": 0.4}, 1.3, 2.0, 0, 2.6, 2.0),
    ("clip-higher", {}, 0.5, -2.0, 0, LO * -2.0, 0.0),
    ("clip-higher", {}, 0.5, 2.0, 0, 1.0, 2.0),
    ("clip-higher", {}, 1.5, -2.0, 0, -3.0, -2.0),
    # DPO (α = 2, β = 0.6): rA - relu(x - c tanh(x / c)); x = (r - 1)A, c = α for A ≥ 0 and
    # x = log(r) A, c = β for A < 0; the drift is 0 where x ≤ 0.
    (
        "dpo",
        {},
        1.5,
        2.0,
        0,
        3.0 - (1.0 - 2.0 * math.tanh(0.5)),
        2.0 - 2.0 * math.tanh(0.5) ** 2,
    ),
    ("dpo", {}, 0.5, 2.0, 0, 1.0, 2.0),
    ("dpo", {}, 1.5, -2.0, 0, -3.0, -2.0),
    (
        "dpo",
        {},
        0.5,
        -2.0,
        0,
        -1.0 - (2.0 * math.log(2) - 0.6 * math.tanh(2.0 * math.log(2) / 0.6)),
        -2.0 + (1 - 1 / math.cosh(2.0 * math.log(2) / 0.6) ** 2) * 2.0 / 0.5,
    ),
    (
        "dpo",
        {"alpha": 1.0, "beta": 1.0},
        2.0,
        1.0,
        0,
        2.0 - (1.0 - math.tanh(1.0)),
        1.0 - math.tanh(1.0) ** 2,
    ),
]


@pytest.mark.parametrize("variant, params, r, a, kl, value, slope", CASES)
def test_value_and_slope_match_spec(variant, params, r, a, kl, value, slope):
    got_value, got_slope = value_and_slope(objective(variant, **params), r, a, kl)
    assert got_value == pytest.approx(value, rel=1e-5, abs=1e-6)
    assert got_slope == pytest.approx(slope, rel=1e-5, abs=1e-6)


def test_every_variant_is_covered():
    assert {case[0] for case in CASES} == set(VARIANTS)


def test_quadratic_pulling_corrects_the_papers_sign():
    """As printed, Eq. 22 gives F ≥ r in R+ so nothing is pulled; the corrected F pulls."""
    qp, ppo = objective("fppo-qp", k=0.4), objective("ppo")
    r, a = 0.5, 1.0
    printed_f = 0.4 * (LO - r) ** 2 + r
    assert min(r * a, printed_f * a) == pytest.approx(value_and_slope(ppo, r, a)[0])
    qp_value, qp_slope = value_and_slope(qp, r, a)
    assert qp_value < value_and_slope(ppo, r, a)[0]
    assert qp_slope > value_and_slope(ppo, r, a)[1]


@pytest.mark.parametrize("variant, params", [("fppo-lp", {"alpha": 1.5}), ("fppo-qp", {"k": 0.5})])
@pytest.mark.parametrize("a", [1.0, -1.0])
def test_pulling_is_continuous_at_the_bounds(variant, params, a):
    obj = objective(variant, **params)
    for bound in (LO, HI):
        below, _ = value_and_slope(obj, bound - 1e-4, a)
        above, _ = value_and_slope(obj, bound + 1e-4, a)
        assert below == pytest.approx(above, abs=5e-4)


def test_neutral_pulling_equals_ppo_everywhere():
    r = jnp.linspace(0.3, 1.7, 57)
    ppo = objective("ppo")
    for a in (-1.5, 0.7):
        adv = jnp.full_like(r, a)
        reference = jax.vmap(jax.value_and_grad(lambda r_, a_: ppo(r_, a_)))(r, adv)
        for neutral in (objective("fppo-lp", alpha=1.0), objective("fppo-qp", k=0.0)):
            got = jax.vmap(jax.value_and_grad(lambda r_, a_, o=neutral: o(r_, a_)))(r, adv)
            np.testing.assert_array_equal(got[0], reference[0])
            np.testing.assert_allclose(got[1], reference[1], rtol=0, atol=1e-7)


def test_neutral_pulling_parts_from_ppo_only_where_ppo_s_min_ties_in_float32():
    # One ulp past 1 + ε, rA and (1 + ε)A may round to the same number: PPO's min is then a
    # tie, whose gradient JAX splits (A/2), where α = 1 and k = 0 pull with r itself (A).
    r = np.nextafter(np.float32(1.2), np.float32(2))
    advantages = -np.random.default_rng(0).uniform(0.01, 3.0, 1000).astype(np.float32)
    ties = r * advantages == np.float32(1.2) * advantages
    assert 0 < ties.sum() < len(ties)
    for a, tie in ((advantages[ties][0], True), (advantages[~ties][0], False)):
        ppo = float(jax.grad(objective("ppo"))(jnp.float32(r), jnp.float32(a)))
        assert ppo == (a / 2 if tie else a)
        for neutral in (objective("fppo-lp", alpha=1.0), objective("fppo-qp", k=0.0)):
            assert float(jax.grad(neutral)(jnp.float32(r), jnp.float32(a))) == a


def test_kl_carries_no_gradient():
    obj = objective("tr-ppo", delta=0.01)
    grad_kl = jax.grad(lambda kl: jnp.sum(obj(jnp.array([1.5]), jnp.array([2.0]), kl)))(
        jnp.array([0.1])
    )
    assert float(grad_kl[0]) == 0.0


def test_negative_regions():
    r = jnp.array([0.5, 0.5, 1.5, 1.5, 1.0])
    a = jnp.array([1.0, -1.0, -1.0, 1.0, 1.0])
    r_plus, r_minus = negative_regions(r, a, EPS)
    assert r_plus.tolist() == [True, False, False, False, False]
    assert r_minus.tolist() == [False, False, True, False, False]
