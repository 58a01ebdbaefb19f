"""Per-sample surrogate objectives of PPO and its variants, as one pure function.

Every variant maximises a per-sample objective ``L(r, A)`` of the likelihood ratio
``r = π_θ(a|s) / π_old(a|s)`` and the advantage ``A``. With ``lo = 1 - ε`` and ``hi = 1 + ε``
the two *negatively optimised* regions of the paper (Sect. 4.1) are

    R+ : A > 0 and r < lo      (a good action whose probability fell out of range)
    R- : A < 0 and r > hi      (a bad action whose probability rose out of range)

and the variants are (slope = ∂L/∂r)::

    ppo        min(rA, clip(r, lo, hi) A)
    fppo-lp    min(rA, F A),  F = α r + (1 - α) lo  in R+,  α r + (1 - α) hi  in R-,
               clip(r) elsewhere                                slope α A in R±
    fppo-qp    min(rA, F A),  F = r - k (lo - r)²  in R+,  r + k (r - hi)²  in R-,
               clip(r) elsewhere                                slope (1 + 2 k d) A in R±
    ppo-rb     min(rA, F A),  F = -α r + (1 + α) lo  for r ≤ lo,  -α r + (1 + α) hi  for r ≥ hi,
               r inside                                         slope -α A where PPO clips
    tr-ppo     A (no gradient) if KL ≥ δ and rA ≥ A, else rA
    tr-ppo-rb  value rA and slope -α A if KL ≥ δ and rA > A, else rA

where ``d`` is the distance past the bound and ``KL = KL(π_old(·|s) ‖ π_θ(·|s))`` per sample.

The variant and its hyperparameters are the leaves of an :class:`Objective` pytree, so a
``jax.vmap`` over a stacked batch of objectives (mixed variants included) compiles once.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np

VARIANTS: tuple[str, ...] = ("ppo", "fppo-lp", "fppo-qp", "tr-ppo", "ppo-rb", "tr-ppo-rb")

# The hyperparameters each variant takes, with the paper's values as defaults (Sect. 5;
# TR-PPO-RB's from the Truly PPO paper). `alpha` is the pulling factor of FPPO-LP and the
# rollback coefficient of the RB variants, as in the papers.
DEFAULTS: dict[str, dict[str, float]] = {
    "ppo": {},
    "fppo-lp": {"alpha": 1.3},
    "fppo-qp": {"k": 0.4},
    "tr-ppo": {"delta": 0.035},
    "ppo-rb": {"alpha": 0.3},
    "tr-ppo-rb": {"alpha": 0.05, "delta": 0.03},
}

EPSILON = 0.2  # the clip range every variant takes, as the paper and baselines use it

_TRUST_REGION = ("tr-ppo", "tr-ppo-rb")


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Objective:
    """A surrogate objective: the variant (an index into :data:`VARIANTS`) and its hyperparameters.

    All fields are arrays, so objectives stack, vmap and trace like any pytree. A field the
    variant does not use holds 0 and has no effect. Build one with :func:`objective`.
    """

    variant: jax.Array
    epsilon: jax.Array
    alpha: jax.Array
    k: jax.Array
    delta: jax.Array

    def __call__(
        self, ratio: jax.Array, advantage: jax.Array, kl: jax.Array | None = None
    ) -> jax.Array:
        """Per-sample objective values (to maximise). `kl` is required by tr-ppo and tr-ppo-rb."""
        if kl is None:
            if isinstance(self.variant, jax.core.Tracer):
                # Which variant runs is known only when it runs: a trust-region one would go
                # ungated.
                raise ValueError(
                    "the variant is traced (under jit or vmap), so it may gate on the KL "
                    "divergence: pass kl= (per-sample KL(π_old ‖ π_θ))"
                )
            if _needs_kl(self.variant):
                raise ValueError(
                    f"{self.name} gates on the KL divergence: pass kl= (per-sample KL(π_old ‖ π_θ))"
                )
            kl = jnp.zeros_like(ratio)
        return surrogate(self, ratio, advantage, kl)

    @property
    def name(self) -> str:
        """The variant's name (only for a concrete, unbatched objective)."""
        return VARIANTS[int(self.variant)]


def check_variant(variant: object) -> str:
    """`variant` if it names one of :data:`VARIANTS`; else an error that lists them."""
    if variant not in VARIANTS:
        raise ValueError(f"unknown variant {variant!r}; valid variants: {', '.join(VARIANTS)}")
    return str(variant)


def objective(name: str, *, epsilon: float = EPSILON, **hyperparameters: float) -> Objective:
    """The objective of variant `name`, with its hyperparameters checked against their ranges.

    Variants and their hyperparameters: ``ppo`` (ε), ``fppo-lp`` (ε, α ≥ 1), ``fppo-qp``
    (ε, k ≥ 0), ``tr-ppo`` (ε, δ > 0), ``ppo-rb`` (ε, rollback α ≥ 0), ``tr-ppo-rb`` (ε, α ≥ 0,
    δ > 0). Missing hyperparameters take the paper's values (:data:`DEFAULTS`); ``None`` counts as
    missing. ε only enters through the bounds ``1 ± ε`` (0 < ε < 1); tr-ppo uses it solely for
    the negative-region diagnostic and value clipping.
    """
    check_variant(name)
    given = {key: value for key, value in hyperparameters.items() if value is not None}
    allowed = DEFAULTS[name]
    extra = sorted(set(given) - set(allowed))
    if extra:
        takes = ", ".join(["epsilon", *allowed])
        raise ValueError(f"{name} has no hyperparameter {', '.join(extra)} (it takes: {takes})")
    values = {"epsilon": epsilon, **allowed, **given}
    for key, value in values.items():
        _check_range(name, key, real(key, value))
    return Objective(
        variant=jnp.asarray(VARIANTS.index(name), jnp.int32),
        epsilon=jnp.asarray(values["epsilon"], jnp.float32),
        alpha=jnp.asarray(values.get("alpha", 0.0), jnp.float32),
        k=jnp.asarray(values.get("k", 0.0), jnp.float32),
        delta=jnp.asarray(values.get("delta", 0.0), jnp.float32),
    )


def real(name: str, value: object) -> float:
    """`value` as a float if it is a real number (numpy's included); strings and booleans,
    which ``float`` would take, are refused."""
    if isinstance(value, str | bool | np.bool_) or not isinstance(
        value, numbers.Real | np.ndarray | jax.Array
    ):
        raise ValueError(f"{name} must be a number, got {value!r}")
    if np.ndim(value) != 0:
        raise ValueError(f"{name} must be a single number, got an array of shape {np.shape(value)}")
    return float(value)


def _check_range(variant: str, key: str, value: float) -> None:
    # Written as `not (in range)` so that NaN is out of every range.
    if key == "epsilon" and not 0.0 < value < 1.0:
        raise ValueError(f"epsilon must be in (0, 1), got {value}")
    if key == "alpha" and variant == "fppo-lp" and not value >= 1.0:
        raise ValueError(
            f"alpha must be >= 1 for fppo-lp, got {value} (below 1 the min falls back to "
            "PPO's clipped objective, so it would silently train PPO)"
        )
    if key == "alpha" and variant != "fppo-lp" and not value >= 0.0:
        raise ValueError(
            f"alpha (the rollback coefficient) must be >= 0 for {variant}, got {value}"
        )
    if key == "k" and not value >= 0.0:
        raise ValueError(f"k must be >= 0 for fppo-qp, got {value}")
    if key == "delta" and not (value > 0.0 and math.isfinite(value)):
        raise ValueError(f"delta must be > 0 for {variant}, got {value}")
    if not math.isfinite(value):
        raise ValueError(f"{key} must be finite, got {value}")


def _needs_kl(variant: jax.Array) -> bool:
    return bool(np.isin(np.asarray(variant), [VARIANTS.index(v) for v in _TRUST_REGION]).any())


def negative_regions(
    ratio: jax.Array, advantage: jax.Array, epsilon: jax.Array
) -> tuple[jax.Array, jax.Array]:
    """Masks of R+ (A > 0, r < 1 - ε) and R- (A < 0, r > 1 + ε), the negatively optimised."""
    return (advantage > 0) & (ratio < 1 - epsilon), (advantage < 0) & (ratio > 1 + epsilon)


def distance_past_bound(ratio: jax.Array, epsilon: jax.Array) -> jax.Array:
    """How far `ratio` lies outside [1 - ε, 1 + ε] (0 inside)."""
    return jnp.maximum(1 - epsilon - ratio, 0.0) + jnp.maximum(ratio - 1 - epsilon, 0.0)


Surrogate = Callable[[Objective, jax.Array, jax.Array, jax.Array], jax.Array]


def _ppo(o: Objective, r: jax.Array, a: jax.Array, kl: jax.Array) -> jax.Array:
    return jnp.minimum(r * a, jnp.clip(r, 1 - o.epsilon, 1 + o.epsilon) * a)


def _fppo_lp(o: Objective, r: jax.Array, a: jax.Array, kl: jax.Array) -> jax.Array:
    lo, hi = 1 - o.epsilon, 1 + o.epsilon
    r_plus, r_minus = negative_regions(r, a, o.epsilon)
    pulled = jnp.where(r_plus, o.alpha * r + (1 - o.alpha) * lo, o.alpha * r + (1 - o.alpha) * hi)
    f = jnp.where(r_plus | r_minus, pulled, jnp.clip(r, lo, hi))
    return jnp.minimum(r * a, f * a)


def _fppo_qp(o: Objective, r: jax.Array, a: jax.Array, kl: jax.Array) -> jax.Array:
    lo, hi = 1 - o.epsilon, 1 + o.epsilon
    r_plus, r_minus = negative_regions(r, a, o.epsilon)
    # The paper's Eq. 22 prints `+ k(lo - r)²` for R+, which makes F ≥ r so that the
    # min keeps rA and nothing is pulled. Its Eq. 21 and proof (Eq. 23) give `r - k(lo - r)²`.
    # The distance is masked before it is squared: an unselected branch's infinite square
    # would turn the select's zero gradient into NaN.
    below = jnp.where(r_plus, lo - r, 0.0)
    above = jnp.where(r_minus, r - hi, 0.0)
    pulled = jnp.where(r_plus, r - o.k * below**2, r + o.k * above**2)
    f = jnp.where(r_plus | r_minus, pulled, jnp.clip(r, lo, hi))
    return jnp.minimum(r * a, f * a)


def _tr_ppo(o: Objective, r: jax.Array, a: jax.Array, kl: jax.Array) -> jax.Array:
    gate = (jax.lax.stop_gradient(kl) >= o.delta) & (r * a >= a)
    return jnp.where(gate, a, r * a)


def _ppo_rb(o: Objective, r: jax.Array, a: jax.Array, kl: jax.Array) -> jax.Array:
    lo, hi = 1 - o.epsilon, 1 + o.epsilon
    rollback_lo = -o.alpha * r + (1 + o.alpha) * lo
    rollback_hi = -o.alpha * r + (1 + o.alpha) * hi
    f = jnp.where(r <= lo, rollback_lo, jnp.where(r >= hi, rollback_hi, r))
    return jnp.minimum(r * a, f * a)


def _tr_ppo_rb(o: Objective, r: jax.Array, a: jax.Array, kl: jax.Array) -> jax.Array:
    gate = (jax.lax.stop_gradient(kl) >= o.delta) & (r * a > a)
    # Value rA, slope -αA: the stop-gradient term restores the value without adding slope.
    rolled_back = (-o.alpha * r + jax.lax.stop_gradient((1 + o.alpha) * r)) * a
    return jnp.where(gate, rolled_back, r * a)


_SURROGATES: tuple[Surrogate, ...] = (_ppo, _fppo_lp, _fppo_qp, _tr_ppo, _ppo_rb, _tr_ppo_rb)


def surrogate(o: Objective, ratio: jax.Array, advantage: jax.Array, kl: jax.Array) -> jax.Array:
    """Per-sample objective of `o` (to maximise); `kl` only gates and carries no gradient.

    Every variant's surrogate is computed and the one of `o.variant` selected, element-wise:
    the same program for any variant, and under ``vmap`` over objectives each gets its own.
    """
    # A select rather than lax.switch: the surrogates are a few element-wise operations that
    # XLA fuses into one kernel, while a conditional (in the loss and again in its gradient)
    # costs more than all of them at minibatch sizes. Only the selected branch gets gradient,
    # and every branch is finite, so the others contribute exact zeros.
    candidates = [f(o, ratio, advantage, kl) for f in _SURROGATES]
    return jnp.choose(o.variant, candidates, mode="clip")
