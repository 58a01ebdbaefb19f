"""Action distributions of the policy: categorical and diagonal Gaussian.

Each is a pytree of its parameters, so the parameters of the rollout policy are stored with the
batch and the exact KL(π_old ‖ π_θ) can be recomputed at every minibatch step. Sampling is a
deterministic function of standard noise (``sample_from``), so a rollout can draw all its noise
at once, outside its sequential loop.
"""

from __future__ import annotations

import dataclasses
import math

import jax
import jax.numpy as jnp


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Categorical:
    """π(a) = softmax(logits)[a]."""

    logits: jax.Array

    @staticmethod
    def noise(key: jax.Array, shape: tuple[int, ...]) -> jax.Array:
        """Standard Gumbel noise, from which :meth:`sample_from` draws."""
        return jax.random.gumbel(key, shape)

    def sample_from(self, noise: jax.Array) -> jax.Array:
        """argmax(logits + g), g ~ Gumbel: an exact sample (the Gumbel-max trick)."""
        return jnp.argmax(self.logits + noise, axis=-1)

    def sample(self, key: jax.Array) -> jax.Array:
        return self.sample_from(self.noise(key, self.logits.shape))

    def mode(self) -> jax.Array:
        return jnp.argmax(self.logits, axis=-1)

    def log_prob(self, action: jax.Array) -> jax.Array:
        log_p = jax.nn.log_softmax(self.logits)
        # A one-hot contraction rather than a gather: element-wise, so it fuses (and its
        # gradient is no scatter).
        one_hot = jax.nn.one_hot(action, self.logits.shape[-1], dtype=log_p.dtype)
        return jnp.sum(log_p * one_hot, axis=-1)

    def entropy(self) -> jax.Array:
        log_p = jax.nn.log_softmax(self.logits)
        return -jnp.sum(jnp.exp(log_p) * log_p, axis=-1)

    def kl(self, other: Categorical) -> jax.Array:
        """KL(self ‖ other) = Σ_a p(a) (log p(a) − log q(a))."""
        log_p = jax.nn.log_softmax(self.logits)
        log_q = jax.nn.log_softmax(other.logits)
        return jnp.sum(jnp.exp(log_p) * (log_p - log_q), axis=-1)


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class DiagonalGaussian:
    """π(a) = Π_d N(a_d; μ_d, σ_d²), σ = exp(log_std); `log_std` has the shape of `mean`."""

    mean: jax.Array
    log_std: jax.Array

    @staticmethod
    def noise(key: jax.Array, shape: tuple[int, ...]) -> jax.Array:
        """Standard normal noise, from which :meth:`sample_from` draws."""
        return jax.random.normal(key, shape)

    def sample_from(self, noise: jax.Array) -> jax.Array:
        return self.mean + jnp.exp(self.log_std) * noise

    def sample(self, key: jax.Array) -> jax.Array:
        return self.sample_from(self.noise(key, self.mean.shape))

    def mode(self) -> jax.Array:
        return self.mean

    def log_prob(self, action: jax.Array) -> jax.Array:
        z = (action - self.mean) * jnp.exp(-self.log_std)
        return jnp.sum(-0.5 * z**2 - self.log_std - 0.5 * math.log(2 * math.pi), axis=-1)

    def entropy(self) -> jax.Array:
        return jnp.sum(self.log_std + 0.5 * math.log(2 * math.pi * math.e), axis=-1)

    def kl(self, other: DiagonalGaussian) -> jax.Array:
        """KL(self ‖ other) = Σ_d [log σ_o − log σ_s + (σ_s² + (μ_s − μ_o)²) / (2 σ_o²) − ½]."""
        var_self = jnp.exp(2 * self.log_std)
        var_other = jnp.exp(2 * other.log_std)
        terms = (
            other.log_std
            - self.log_std
            + (var_self + (self.mean - other.mean) ** 2) / (2 * var_other)
            - 0.5
        )
        return jnp.sum(terms, axis=-1)


Distribution = Categorical | DiagonalGaussian
