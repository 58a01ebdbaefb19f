import jax
import jax.numpy as jnp
import numpy as np

from fppo_jax.core.distributions import Categorical, DiagonalGaussian


def test_categorical_log_prob_entropy_and_kl():
    p_logits = jnp.array([[0.3, -1.0, 2.0]])
    q_logits = jnp.array([[1.0, 0.0, -0.5]])
    p, q = Categorical(p_logits), Categorical(q_logits)
    probs_p = np.exp(p_logits[0]) / np.exp(p_logits[0]).sum()
    probs_q = np.exp(q_logits[0]) / np.exp(q_logits[0]).sum()
    np.testing.assert_allclose(p.log_prob(jnp.array([2])), np.log(probs_p[2]), rtol=1e-6)
    np.testing.assert_allclose(p.entropy(), -(probs_p * np.log(probs_p)).sum(), rtol=1e-6)
    np.testing.assert_allclose(p.kl(q), (probs_p * np.log(probs_p / probs_q)).sum(), rtol=1e-5)
    assert int(p.mode()[0]) == 2


def test_gaussian_kl_matches_monte_carlo():
    old = DiagonalGaussian(jnp.array([0.3, -1.0, 0.0]), jnp.array([0.0, -0.5, 0.4]))
    new = DiagonalGaussian(jnp.array([0.1, -0.7, 0.5]), jnp.array([0.2, -0.3, 0.1]))
    samples = jax.vmap(old.sample)(jax.random.split(jax.random.key(0), 400_000))
    monte_carlo = jnp.mean(old.log_prob(samples) - new.log_prob(samples))
    np.testing.assert_allclose(old.kl(new), monte_carlo, rtol=0.02)
    np.testing.assert_allclose(old.kl(old), 0.0, atol=1e-7)


def test_gaussian_log_prob_and_entropy():
    dist = DiagonalGaussian(jnp.array([1.0, -2.0]), jnp.log(jnp.array([0.5, 2.0])))
    x = jnp.array([1.5, 0.0])
    sigma = np.array([0.5, 2.0])
    expected = np.sum(-0.5 * ((x - dist.mean) / sigma) ** 2 - np.log(sigma * np.sqrt(2 * np.pi)))
    np.testing.assert_allclose(dist.log_prob(x), expected, rtol=1e-6)
    np.testing.assert_allclose(
        dist.entropy(), np.sum(np.log(sigma * np.sqrt(2 * np.pi * np.e))), rtol=1e-6
    )
