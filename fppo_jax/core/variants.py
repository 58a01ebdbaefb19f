"""The built-in variants: their surrogates, each one declaration (a variant is added here
alone), the clip range ε they all take by default, and the regions where they differ.

With ``lo = 1 - ε`` and ``hi = 1 + ε`` the two *negatively optimised* regions of the paper
(Sect. 4.1) are

    R+ : A > 0 and r < lo      (a good action whose probability fell out of range)
    R- : A < 0 and r > hi      (a bad action whose probability rose out of range)

and the built-in surrogates are (slope = ∂L/∂r)::

    ppo          min(rA, clip(r, lo, hi) A)
    fppo-lp      min(rA, F A),  F = α r + (1 - α) lo  in R+,  α r + (1 - α) hi  in R-,
                 clip(r) elsewhere                                slope α A in R±
    fppo-qp      min(rA, F A),  F = r - k (lo - r)²  in R+,  r + k (r - hi)²  in R-,
                 clip(r) elsewhere                                slope (1 + 2 k d) A in R±
    ppo-rb       min(rA, F A),  F = -α r + (1 + α) lo  for r ≤ lo,  -α r + (1 + α) hi  for r ≥ hi,
                 r inside                                         slope -α A where PPO clips
    tr-ppo       A (no gradient) if KL ≥ δ and rA ≥ A, else rA
    tr-ppo-rb    value rA and slope -α A if KL ≥ δ and rA > A, else rA
    spo          rA - |A| (r - 1)² / (2ε)                         slope A - |A| (r - 1) / ε
    clip-higher  min(rA, clip(r, 1 - ε_low, 1 + ε_high) A)
    dpo          rA - drift,  drift = relu(x - α tanh(x / α)),  x = (r - 1) A  for A ≥ 0,
                              drift = relu(x - β tanh(x / β)),  x = log(r) A  for A < 0

where ``d`` is the distance past the bound and ``KL = KL(π_old(·|s) ‖ π_θ(·|s))`` per sample.
Sources: PPO (Schulman et al. 2017); FPPO-LP and FPPO-QP (the paper, Eqs. 20–22, Eq. 22's
sign corrected); PPO-RB, TR-PPO and TR-PPO-RB (Wang et al. 2019, "Truly Proximal Policy
Optimization"); SPO (Xie et al. 2024, "Simple Policy Optimization", its ε = 0.2); clip-higher
(Yu et al. 2025, "DAPO", ε_low = 0.2, ε_high = 0.28); DPO (Lu et al. 2022, "Discovered Policy
Optimisation", α = 2, β = 0.6).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from fppo_jax.core.surrogates import Range, Surrogate, declare

EPSILON = 0.2  # the clip range every variant takes, as the paper and baselines use it


def negative_regions(
    ratio: jax.Array, advantage: jax.Array, below: jax.Array, above: jax.Array | None = None
) -> tuple[jax.Array, jax.Array]:
    """Masks of R+ (A > 0, r < 1 - below) and R- (A < 0, r > 1 + above), the negatively
    optimised; `above` is `below` (ε) unless given."""
    above = below if above is None else above
    return (advantage > 0) & (ratio < 1 - below), (advantage < 0) & (ratio > 1 + above)


def outside_clip_range(
    ratio: jax.Array, below: jax.Array, above: jax.Array | None = None
) -> jax.Array:
    """Where `ratio` lies outside [1 - below, 1 + above]; `above` is `below` unless given."""
    if above is None:
        return jnp.abs(ratio - 1) > below
    return (1 - ratio > below) | (ratio - 1 > above)


def distance_past_bound(
    ratio: jax.Array, below: jax.Array, above: jax.Array | None = None
) -> jax.Array:
    """How far `ratio` lies outside [1 - below, 1 + above] (0 inside); `above` is `below`
    unless given."""
    above = below if above is None else above
    return jnp.maximum(1 - below - ratio, 0.0) + jnp.maximum(ratio - 1 - above, 0.0)


def ppo(ratio: jax.Array, advantage: jax.Array, epsilon: jax.Array) -> jax.Array:
    return jnp.minimum(ratio * advantage, jnp.clip(ratio, 1 - epsilon, 1 + epsilon) * advantage)


def fppo_lp(
    ratio: jax.Array, advantage: jax.Array, epsilon: jax.Array, alpha: jax.Array
) -> jax.Array:
    r, a = ratio, advantage
    lo, hi = 1 - epsilon, 1 + epsilon
    r_plus, r_minus = negative_regions(r, a, epsilon)
    pulled = jnp.where(r_plus, alpha * r + (1 - alpha) * lo, alpha * r + (1 - alpha) * hi)
    f = jnp.where(r_plus | r_minus, pulled, jnp.clip(r, lo, hi))
    return jnp.minimum(r * a, f * a)


def fppo_qp(ratio: jax.Array, advantage: jax.Array, epsilon: jax.Array, k: jax.Array) -> jax.Array:
    r, a = ratio, advantage
    lo, hi = 1 - epsilon, 1 + epsilon
    r_plus, r_minus = negative_regions(r, a, epsilon)
    # The paper's Eq. 22 prints `+ k(lo - r)²` for R+, which makes F ≥ r so that the
    # min keeps rA and nothing is pulled. Its Eq. 21 and proof (Eq. 23) give `r - k(lo - r)²`.
    # The distance is masked before it is squared: an unselected branch's infinite square
    # would turn the select's zero gradient into NaN.
    below = jnp.where(r_plus, lo - r, 0.0)
    above = jnp.where(r_minus, r - hi, 0.0)
    pulled = jnp.where(r_plus, r - k * below**2, r + k * above**2)
    f = jnp.where(r_plus | r_minus, pulled, jnp.clip(r, lo, hi))
    return jnp.minimum(r * a, f * a)


def tr_ppo(ratio: jax.Array, advantage: jax.Array, kl: jax.Array, delta: jax.Array) -> jax.Array:
    r, a = ratio, advantage
    gate = (jax.lax.stop_gradient(kl) >= delta) & (r * a >= a)
    return jnp.where(gate, a, r * a)


def ppo_rb(
    ratio: jax.Array, advantage: jax.Array, epsilon: jax.Array, alpha: jax.Array
) -> jax.Array:
    r, a = ratio, advantage
    lo, hi = 1 - epsilon, 1 + epsilon
    rollback_lo = -alpha * r + (1 + alpha) * lo
    rollback_hi = -alpha * r + (1 + alpha) * hi
    f = jnp.where(r <= lo, rollback_lo, jnp.where(r >= hi, rollback_hi, r))
    return jnp.minimum(r * a, f * a)


def tr_ppo_rb(
    ratio: jax.Array, advantage: jax.Array, kl: jax.Array, alpha: jax.Array, delta: jax.Array
) -> jax.Array:
    r, a = ratio, advantage
    gate = (jax.lax.stop_gradient(kl) >= delta) & (r * a > a)
    # Value rA, slope -αA: the stop-gradient term restores the value without adding slope.
    rolled_back = (-alpha * r + jax.lax.stop_gradient((1 + alpha) * r)) * a
    return jnp.where(gate, rolled_back, r * a)


def spo(ratio: jax.Array, advantage: jax.Array, epsilon: jax.Array) -> jax.Array:
    # Its optimum in r is 1 + ε sign(A): the penalty keeps the ratio at PPO's bound without
    # flattening the slope beyond it.
    return ratio * advantage - jnp.abs(advantage) / (2 * epsilon) * (ratio - 1) ** 2


def clip_higher(
    ratio: jax.Array, advantage: jax.Array, eps_low: jax.Array, eps_high: jax.Array
) -> jax.Array:
    clipped = jnp.clip(ratio, 1 - eps_low, 1 + eps_high)
    return jnp.minimum(ratio * advantage, clipped * advantage)


def dpo(ratio: jax.Array, advantage: jax.Array, alpha: jax.Array, beta: jax.Array) -> jax.Array:
    # As DPO's own code writes its discovered drift: each branch is relu(x - c tanh(x / c)),
    # zero with zero slope at x = 0, growing like x beyond c.
    def drift(x: jax.Array, c: jax.Array) -> jax.Array:
        return jax.nn.relu(x - c * jnp.tanh(x / c))

    positive = drift((ratio - 1) * advantage, alpha)
    negative = drift(jnp.log(ratio) * advantage, beta)
    return ratio * advantage - jnp.where(advantage >= 0, positive, negative)


_ROLLBACK = Range(">= 0", "the rollback coefficient")
_KL_BOUND = Range("> 0")
# Each built-in once: its function, its hyperparameters' defaults (the paper's values, Sect. 5;
# TR-PPO-RB's from the Truly PPO paper; SPO's, DAPO's and DPO's from theirs) and ranges.
# `alpha` is FPPO-LP's pulling factor, the RB variants' rollback coefficient and DPO's drift
# scale for A ≥ 0, as their papers name them.
BUILTINS: dict[str, Surrogate] = {
    s.name: s
    for s in (
        declare("ppo", ppo, None, False, None, {}, builtin=True),
        declare(
            "fppo-lp",
            fppo_lp,
            {
                "alpha": Range(
                    ">= 1",
                    "below 1 the min falls back to PPO's clipped objective, so it would "
                    "silently train PPO",
                )
            },
            False,
            None,
            {"alpha": 1.3},
            builtin=True,
        ),
        declare("fppo-qp", fppo_qp, {"k": Range(">= 0")}, False, None, {"k": 0.4}, builtin=True),
        declare("tr-ppo", tr_ppo, {"delta": _KL_BOUND}, True, None, {"delta": 0.035}, builtin=True),
        declare("ppo-rb", ppo_rb, {"alpha": _ROLLBACK}, False, None, {"alpha": 0.3}, builtin=True),
        declare(
            "tr-ppo-rb",
            tr_ppo_rb,
            {"alpha": _ROLLBACK, "delta": _KL_BOUND},
            True,
            None,
            {"alpha": 0.05, "delta": 0.03},
            builtin=True,
        ),
        declare("spo", spo, None, False, None, {}, builtin=True),
        declare(
            "clip-higher",
            clip_higher,
            {"eps_low": Range("(0, 1)"), "eps_high": Range("> 0")},
            False,
            ("eps_low", "eps_high"),
            {"eps_low": 0.2, "eps_high": 0.28},
            builtin=True,
        ),
        declare(
            "dpo",
            dpo,
            {"alpha": Range("> 0"), "beta": Range("> 0")},
            False,
            None,
            {"alpha": 2.0, "beta": 0.6},
            builtin=True,
        ),
    )
}
VARIANTS: tuple[str, ...] = tuple(BUILTINS)
# What trains when no variant is named: the paper's own.
DEFAULT_VARIANT = "fppo-lp"
# The paper's six, computed in every program: the loss's kernel is then the very one every
# recorded run was trained with (XLA's rounding of the loss follows the kernel's whole body),
# and computing the six costs one fused element-wise kernel.
PAPERS: tuple[str, ...] = VARIANTS[:6]
