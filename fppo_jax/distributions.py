"""Action distributions of the policy: categorical and diagonal Gaussian.

Each is a pytree of its parameters, so the parameters of the rollout policy are stored with the
batch and the exact KL(π_old ‖ π_θ) can be recomputed at every minibatch step.
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

    def sample(self, key: jax.Array) -> jax.Array:
        return jax.random.categorical(key, self.logits)

    def mode(self) -> jax.Array:
        return jnp.argmax(self.logits, axis=-1)

    def log_prob(self, action: jax.Array) -> jax.Array:
        log_p = jax.nn.log_softmax(self.logits)
        return jnp.take_along_axis(log_p, action[..., None].astype(jnp.int32), axis=-1)[..., 0]

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

    def sample(self, key: jax.Array) -> jax.Array:
        return self.mean + jnp.exp(self.log_std) * jax.random.normal(key, self.mean.shape)

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
