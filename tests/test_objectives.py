"""Every variant's value and slope against the paper's definitions (Eq. 22 with its sign
corrected), region by region."""

import math
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fppo_jax import VARIANTS, negative_regions, objective, stack
from fppo_jax.core.objectives import PAPERS, resolve

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


def test_vmap_over_mixed_variants_matches_each_variant():
    objs = [
        objective("ppo"),
        objective("fppo-lp", alpha=1.4),
        objective("fppo-qp", k=0.3),
        objective("tr-ppo", delta=0.02),
        objective("ppo-rb", alpha=0.2),
        objective("tr-ppo-rb", alpha=0.1, delta=0.02),
        objective("fppo-lp", alpha=1.1, epsilon=0.1),
        objective("spo"),
        objective("clip-higher", eps_high=0.3),
        objective("dpo", beta=0.5),
    ]
    stacked = stack(objs)
    key_r, key_a, key_kl = jax.random.split(jax.random.key(0), 3)
    r = jax.random.uniform(key_r, (200,), minval=0.4, maxval=1.6)
    a = jax.random.normal(key_a, (200,))
    kl = jax.random.uniform(key_kl, (200,), maxval=0.05)

    def loss_and_grad(o):
        return jax.value_and_grad(lambda r_: jnp.sum(o(r_, a, kl)))(r)

    batched = jax.jit(jax.vmap(loss_and_grad))(stacked)
    for i, o in enumerate(objs):
        single = loss_and_grad(o)
        np.testing.assert_allclose(batched[0][i], single[0], rtol=1e-6)
        np.testing.assert_allclose(batched[1][i], single[1], rtol=1e-6, atol=1e-7)
    # Mixed variants really differ: the vmapped batch is not one objective repeated.
    assert len({round(float(v), 4) for v in batched[0]}) == len(objs)


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


@pytest.mark.parametrize(
    "variant, params, match",
    [
        ("sppo", {}, "unknown variant 'sppo'; valid variants: ppo, fppo-lp"),
        ("dpo", {"beta": 0.0}, "beta must be > 0 for dpo, got 0.0"),
        ("clip-higher", {"eps_low": 1.0}, "eps_low must be in \\(0, 1\\) for clip-higher"),
        ("clip-higher", {"eps_high": float("inf")}, "eps_high must be finite for clip-higher"),
        ("fppo-lp", {"alpha": 0.9}, "alpha must be >= 1 for fppo-lp"),
        ("fppo-lp", {"alpha": float("nan")}, "alpha must be >= 1"),
        ("fppo-qp", {"k": -0.1}, "k must be >= 0"),
        ("tr-ppo", {"delta": 0.0}, "delta must be > 0"),
        ("tr-ppo-rb", {"delta": -1.0}, "delta must be > 0"),
        ("ppo-rb", {"alpha": -0.1}, "alpha must be >= 0 for ppo-rb, got -0.1 \\(the rollback"),
        ("ppo", {"epsilon": 1.0}, "epsilon must be in \\(0, 1\\)"),
        ("ppo", {"epsilon": 0.0}, "epsilon must be in \\(0, 1\\)"),
        ("ppo", {"alpha": 1.3}, "ppo has no hyperparameter alpha"),
        (
            "fppo-qp",
            {"alpha": 1.3},
            "fppo-qp has no hyperparameter alpha \\(it takes: epsilon, k\\)",
        ),
    ],
)
def test_bad_hyperparameters_are_named(variant, params, match):
    with pytest.raises(ValueError, match=match):
        objective(variant, **params)


def test_trust_region_variants_require_kl():
    with pytest.raises(ValueError, match="tr-ppo gates on the KL"):
        objective("tr-ppo")(jnp.ones(3), jnp.ones(3))


def test_objective_name():
    assert [objective(v).name for v in VARIANTS] == list(VARIANTS)


@pytest.mark.parametrize("variant", PAPERS)
@pytest.mark.parametrize("among", [(), tuple(VARIANTS)])
def test_an_unselected_branch_cannot_make_the_gradient_nan(variant, among):
    # A > 0 and an overflowed ratio: each of the paper's variants is flat or linear there, but
    # FPPO-QP's square of the distance past the bound is infinite, and SPO's and DPO's values
    # are too; the select must not turn their zero weight into NaN.
    obj = objective(variant).among([resolve(v) for v in among])
    grad = jax.grad(lambda r: obj(r, jnp.float32(1.0), jnp.float32(0.0)))(jnp.float32(jnp.inf))
    assert np.isfinite(grad)


def test_a_variant_not_chosen_sees_its_own_defaults_not_a_shared_names_value():
    # PPO-RB's rollback α may be 0, which DPO (dividing by its α) must never see.
    stacked = stack([objective("ppo-rb", alpha=0.0), objective("dpo")])
    r = jnp.linspace(0.5, 1.5, 11)
    for i, single in enumerate([objective("ppo-rb", alpha=0.0), objective("dpo")]):
        o = jax.tree.map(lambda x, i=i: x[i], stacked)
        value, slope = jax.vmap(jax.value_and_grad(lambda r_, o=o: o(r_, jnp.float32(1.0))))(r)
        expected = jax.vmap(jax.value_and_grad(lambda r_, s=single: s(r_, jnp.float32(1.0))))(r)
        np.testing.assert_allclose(value, expected[0], rtol=1e-6)
        np.testing.assert_allclose(slope, expected[1], rtol=1e-6)
        assert np.isfinite(slope).all()


def test_a_traced_objective_without_kl_is_refused():
    # Under jit the variant is not known while tracing: a trust-region one would run ungated.
    with pytest.raises(ValueError, match="pass kl="):
        jax.jit(lambda o, r, a: o(r, a))(objective("tr-ppo"), jnp.ones(3), jnp.ones(3))
    with pytest.raises(ValueError, match="pass kl="):
        jax.vmap(lambda o, r, a: o(r, a))(
            stack([objective("ppo"), objective("tr-ppo")]),
            jnp.ones((2, 3)),
            jnp.ones((2, 3)),
        )
    kl = jnp.zeros(3)
    assert jax.jit(lambda o, r, a: o(r, a, kl))(
        objective("tr-ppo"), jnp.ones(3), jnp.ones(3)
    ).shape == (3,)


@pytest.mark.parametrize("value", ["1.3", True, np.ones(2), [1.3]])
def test_a_hyperparameter_that_is_not_a_number_is_refused(value):
    with pytest.raises(ValueError, match=r"alpha must be a (single )?number"):
        objective("fppo-lp", alpha=value)
    assert objective("fppo-lp", alpha=np.float32(1.25)).values["alpha"] == np.float32(1.25)


def test_an_optimisation_setting_that_is_not_a_number_is_refused():
    from fppo_jax import hyperparameters, sweep

    with pytest.raises(ValueError, match=r"learning_rate must be a number, got '0\.001'"):
        hyperparameters("ppo", learning_rate="0.001")
    with pytest.raises(ValueError, match=r"k must be a number, got '0\.4'"):
        sweep("cartpole", {"variant": "fppo-qp", "k": ["0.4"]}, seeds=1)


def test_resolve_takes_each_variant_and_lists_them_when_refusing():
    assert [resolve(v).name for v in VARIANTS] == list(VARIANTS)
    listed = "ppo, fppo-lp, fppo-qp, tr-ppo, ppo-rb, tr-ppo-rb, spo, clip-higher, dpo"
    for wrong in ("PPO", "fppo", None):
        with pytest.raises(
            ValueError, match=re.escape(f"unknown variant {wrong!r}; valid variants: {listed}")
        ):
            resolve(wrong)
    with pytest.raises(ValueError, match="unknown variant 'fppo'"):
        objective("fppo")
