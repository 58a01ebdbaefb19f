"""Running mean and variance, for observation normalisation and reward scaling (as baselines'
``VecNormalize``), carried as arrays in the jitted training state."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class RunningStats:
    """Mean and (population) variance of every sample seen so far, feature-wise."""

    mean: jax.Array
    var: jax.Array
    count: jax.Array

    @classmethod
    def create(cls, shape: tuple[int, ...] = ()) -> RunningStats:
        # count starts just above 0, as in baselines, so the first batch sets the statistics.
        return cls(jnp.zeros(shape), jnp.ones(shape), jnp.asarray(1e-4))

    def update(self, batch: jax.Array) -> RunningStats:
        """Merge a batch (leading axes are samples) by the parallel algorithm of Chan et al.

        δ = μ_b − μ,  n' = n + n_b,  μ' = μ + δ n_b / n',
        σ'² = (σ² n + σ_b² n_b + δ² n n_b / n') / n'.
        """
        batch = batch.reshape((-1, *self.mean.shape))
        batch_count = batch.shape[0]
        batch_mean = batch.mean(axis=0)
        batch_var = batch.var(axis=0)
        delta = batch_mean - self.mean
        count = self.count + batch_count
        mean = self.mean + delta * batch_count / count
        m2 = (
            self.var * self.count
            + batch_var * batch_count
            + delta**2 * self.count * batch_count / count
        )
        return RunningStats(mean, m2 / count, count)

    def normalize(self, x: jax.Array, clip: float = 10.0) -> jax.Array:
        """(x − μ) / sqrt(σ² + 1e-8), clipped to [−clip, clip]."""
        return jnp.clip((x - self.mean) / jnp.sqrt(self.var + 1e-8), -clip, clip)

    def scale(self, x: jax.Array, clip: float = 10.0) -> jax.Array:
        """x / sqrt(σ² + 1e-8), clipped to [−clip, clip] (no centring: for rewards)."""
        return jnp.clip(x / jnp.sqrt(self.var + 1e-8), -clip, clip)
