"""fppo_jax.core.objectives: the Objective pytree, every surrogate of a program computed and the
chosen one selected: mixed variants under vmap, a branch not chosen that cannot reach the
gradient, and the KL a gated variant needs."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fppo_jax import VARIANTS, objective, stack
from fppo_jax.core.resolution import resolve
from fppo_jax.core.variants import PAPERS


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
