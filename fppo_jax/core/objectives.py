"""The built-in surrogates, each one declaration, and the objective: which surrogate a run
maximises and its hyperparameters, as one pytree of traced arrays.

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

An :class:`Objective` holds the surrogates of one compiled program (static) and, as arrays,
which of them it is and every one's hyperparameters, so a ``jax.vmap`` over a stack of
objectives (mixed surrogates, one's own included) compiles once.
"""

from __future__ import annotations

import dataclasses
import importlib
import os
import sys
from collections.abc import Iterable, Mapping, Sequence
from typing import Any, cast

import jax
import jax.numpy as jnp
import numpy as np

from fppo_jax.core.checks import real_number
from fppo_jax.core.surrogates import (
    Range,
    Surrogate,
    as_trained,
    declare,
    float32_note,
    probe,
)
from fppo_jax.errors import FppoError, InvalidInput, first_line

EPSILON = 0.2  # the clip range every variant takes, as the paper and baselines use it
EPSILON_RANGE = Range("(0, 1)")


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


def resolve(variant: object) -> Surrogate:
    """The surrogate `variant` names: a built-in's name, a :class:`Surrogate`, or
    ``"module:attribute"`` (a surrogate of one's own, imported); else an error listing them."""
    if isinstance(variant, Surrogate):
        return variant
    if isinstance(variant, str) and variant in BUILTINS:
        return BUILTINS[variant]
    if isinstance(variant, str) and ":" in variant:
        return _imported(variant)
    raise InvalidInput(
        f"unknown variant {variant!r}; valid variants: {', '.join(VARIANTS)}, or a surrogate of "
        "one's own (fppo_jax.surrogate, or module:attribute on the command line)"
    )


def _imported(path: str) -> Surrogate:
    module_name, _, attribute = path.partition(":")
    if not module_name or module_name.startswith(".") or not attribute:
        raise InvalidInput(f"variant {path!r}: expected module:attribute, such as my_pkg.mod:ppo_x")
    found: Any = _import(path, module_name)
    for name in attribute.split("."):
        if not hasattr(found, name):
            raise InvalidInput(f"variant {path!r}: {module_name} has no {attribute!r}")
        found = getattr(found, name)
    if not isinstance(found, Surrogate):
        raise InvalidInput(
            f"variant {path!r} is a {type(found).__name__}, not a surrogate: declare it with "
            "fppo_jax.surrogate(name, function, **defaults)"
        )
    return found


def _import(path: str, module_name: str) -> Any:
    """The module `module_name`, imported as ``python -m`` would (the current directory first
    on the path), or one line saying why not: a module that raises, or exits, while it is
    imported is refused naming it. An error of the package's own passes as it is."""
    here = os.getcwd()
    looked = [here, *(p for p in sys.path if p not in ("", here))]
    sys.path.insert(0, here)
    try:
        return importlib.import_module(module_name)
    except FppoError:
        raise
    except ModuleNotFoundError as error:
        if error.name is None or not (module_name + ".").startswith(error.name + "."):
            raise InvalidInput(
                f"variant {path!r}: importing {module_name} failed: {error}"
            ) from None
        raise InvalidInput(
            f"variant {path!r}: no module {error.name!r} in the current directory or on "
            f"Python's path (looked in {', '.join(looked)})"
        ) from None
    except SyntaxError as error:
        raise InvalidInput(
            f"variant {path!r}: {module_name} does not parse: {error.filename}:{error.lineno}: "
            f"SyntaxError: {error.msg}"
        ) from None
    except SystemExit as error:
        raise InvalidInput(
            f"variant {path!r}: importing {module_name} called sys.exit({error.code!r}); "
            "a module that declares surrogates must not exit when imported"
        ) from None
    except Exception as error:
        raise InvalidInput(
            f"variant {path!r}: importing {module_name} raised {type(error).__name__}: "
            f"{first_line(error)}"
        ) from None
    finally:
        sys.path.remove(here)


def union(surrogates: Sequence[Surrogate]) -> tuple[Surrogate, ...]:
    """The surrogates of a program that runs `surrogates`: the paper's six (:data:`PAPERS`),
    then the others of `surrogates`, built-ins in their order before one's own as given. Two
    different surrogates under one name are refused."""
    distinct = list(dict.fromkeys([*(BUILTINS[name] for name in PAPERS), *surrogates]))
    names: dict[str, Surrogate] = {}
    for s in distinct:
        if names.setdefault(s.name, s) is not s:
            raise InvalidInput(
                f"two different surrogates are named {s.name!r}: give each of them its own name"
            )
    order = {name: i for i, name in enumerate(VARIANTS)}
    return tuple(sorted(distinct, key=lambda s: order.get(s.name, len(order))))


@dataclasses.dataclass(frozen=True)
class Objective:
    """A surrogate objective: which of `surrogates` it is (`variant`, an index), the clip
    range ε and the hyperparameters, by name, that any of them takes.

    `surrogates` is static (the program's functions); the rest are arrays, so objectives over
    the same surrogates stack, vmap and trace like any pytree. A hyperparameter is shared by
    the surrogates that take a name (``alpha``: FPPO-LP's, the RB variants', DPO's), as a grid
    axis is; one the chosen surrogate does not take holds 0 and has no effect. Build one with
    :func:`objective`, and :func:`stack` a mixed batch.
    """

    variant: jax.Array
    epsilon: jax.Array
    hyperparameters: dict[str, jax.Array]
    surrogates: tuple[Surrogate, ...]

    def __call__(
        self, ratio: jax.Array, advantage: jax.Array, kl: jax.Array | None = None
    ) -> jax.Array:
        """Per-sample objective values (to maximise); `kl` (no gradient) is required by the
        surrogates that gate on it (tr-ppo, tr-ppo-rb).

        Every surrogate of the program is computed and the chosen one selected, element-wise:
        the same program for any of them, and under ``vmap`` over objectives each gets its own.
        """
        if kl is None:
            self._check_kl_not_needed()
            kl = jnp.zeros_like(ratio)
        # A select rather than lax.switch: the surrogates are a few element-wise operations that
        # XLA fuses into one kernel, while a conditional (in the loss and again in its gradient)
        # costs more than all of them at minibatch sizes. Only the chosen one gets gradient: the
        # others contribute exact zeros as long as they are finite, which the paper's six are
        # for any ratio and any valid hyperparameter of a name they share.
        candidates = [
            s(self._ratio(i, s, ratio), advantage, kl, self.epsilon, self._own(i, s))
            for i, s in enumerate(self.surrogates)
        ]
        return jnp.choose(self.variant, candidates, mode="clip")

    def _guarded(self, s: Surrogate) -> bool:
        # The others see, when not chosen, a ratio of 1 and their own defaults, where they are
        # finite with a finite slope (as their declaration's trial showed), whatever the chosen
        # one's ratio and a shared name's value.
        return s.name not in PAPERS

    def _ratio(self, i: int, s: Surrogate, ratio: jax.Array) -> jax.Array:
        return jnp.where(self.variant == i, ratio, 1.0) if self._guarded(s) else ratio

    def _own(self, i: int, s: Surrogate) -> dict[str, jax.Array]:
        values = {key: self.hyperparameters[key] for key in s.defaults}
        if not self._guarded(s):
            return values
        chosen = self.variant == i
        return {key: jnp.where(chosen, v, s.defaults[key]) for key, v in values.items()}

    def _check_kl_not_needed(self) -> None:
        if not any(s.needs_kl for s in self.surrogates):
            return
        if isinstance(self.variant, jax.core.Tracer):
            # Which surrogate runs is known only when it runs: a KL-gated one would go ungated.
            raise InvalidInput(
                "the variant is traced (under jit or vmap), so it may gate on the KL "
                "divergence: pass kl= (per-sample KL(π_old ‖ π_θ))"
            )
        chosen = dict.fromkeys(self.surrogates[int(v)] for v in np.ravel(self.variant))
        gated = [s.name for s in chosen if s.needs_kl]
        if gated:
            raise InvalidInput(
                f"{', '.join(gated)} gates on the KL divergence: pass kl= (per-sample "
                "KL(π_old ‖ π_θ))"
            )

    def clip_range(self) -> tuple[jax.Array, jax.Array | None]:
        """The chosen surrogate's distances below and above 1 where it stops following r (the
        R± diagnostics' bounds): ε, and None for "the same", unless a surrogate of the program
        declares its own."""
        if all(s.clip_range is None for s in self.surrogates):
            return self.epsilon, None
        bounds = [
            (self.epsilon, self.epsilon)
            if s.clip_range is None
            else (self.hyperparameters[s.clip_range[0]], self.hyperparameters[s.clip_range[1]])
            for s in self.surrogates
        ]
        below, above = zip(*bounds, strict=True)
        return (
            jnp.choose(self.variant, below, mode="clip"),
            jnp.choose(self.variant, above, mode="clip"),
        )

    @property
    def surrogate(self) -> Surrogate:
        """The chosen surrogate (only for a concrete, unbatched objective)."""
        return self.surrogates[int(self.variant)]

    @property
    def name(self) -> str:
        """The chosen surrogate's name (only for a concrete, unbatched objective)."""
        return self.surrogate.name

    @property
    def values(self) -> dict[str, jax.Array]:
        """The chosen surrogate's hyperparameters (only for a concrete, unbatched objective)."""
        return {key: self.hyperparameters[key] for key in self.surrogate.defaults}

    def among(self, surrogates: Sequence[Surrogate]) -> Objective:
        """The same objective in the program of `surrogates` and its own (:func:`union`): the
        form in which it stacks with the objectives of any of them."""
        menu = union([*surrogates, *self.surrogates])
        index = jnp.asarray([menu.index(s) for s in self.surrogates], jnp.int32)[self.variant]
        unused = jnp.zeros_like(self.epsilon)
        return Objective(
            variant=index,
            epsilon=self.epsilon,
            hyperparameters={
                key: self.hyperparameters.get(key, unused) for key in hyperparameter_names(menu)
            },
            surrogates=menu,
        )


jax.tree_util.register_dataclass(
    Objective,
    data_fields=["variant", "epsilon", "hyperparameters"],
    meta_fields=["surrogates"],
)


def objective(
    variant: str | Surrogate, *, epsilon: float = EPSILON, **hyperparameters: float | None
) -> Objective:
    """The objective of `variant` (a built-in's name, or a surrogate of one's own), with its
    hyperparameters checked against their ranges before anything compiles.

    Built-ins and their hyperparameters: ``ppo``, ``spo`` (ε only), ``fppo-lp`` (α ≥ 1),
    ``fppo-qp`` (k ≥ 0), ``tr-ppo`` (δ > 0), ``ppo-rb`` (rollback α ≥ 0), ``tr-ppo-rb`` (α ≥ 0,
    δ > 0), ``clip-higher`` (0 < ε_low < 1, ε_high > 0), ``dpo`` (α > 0, β > 0); every one also
    takes ε (0 < ε < 1). Missing hyperparameters take their defaults (:data:`BUILTINS`); ``None``
    counts as missing. ε enters the built-ins through the bounds ``1 ± ε`` (SPO through its
    penalty's scale; tr-ppo, clip-higher and dpo use it only for value clipping and the R±
    diagnostics).
    """
    s = resolve(variant)
    given = {key: value for key, value in hyperparameters.items() if value is not None}
    extra = sorted(set(given) - set(s.defaults))
    if extra:
        takes = ", ".join(["epsilon", *s.defaults])
        raise InvalidInput(f"{s.name} has no hyperparameter {', '.join(extra)} (it takes: {takes})")
    eps = real_number("epsilon", epsilon)
    if eps not in EPSILON_RANGE:
        raise InvalidInput(f"epsilon must be {EPSILON_RANGE}, got {eps}")
    if as_trained(eps) not in EPSILON_RANGE:
        raise InvalidInput(f"epsilon must be {EPSILON_RANGE}, got {eps}, {float32_note(eps)}")
    values = {key: s.check(key, value) for key, value in {**s.defaults, **given}.items()}
    if not s.builtin:
        probe(s, values, eps)
    menu = union([s])
    # NumPy's scalars, put on the device as they are: JAX's own conversion of a Python number
    # is a small program, compiled for each dtype on every start.
    own = {key: np.float32(values.get(key, 0.0)) for key in hyperparameter_names(menu)}
    index, epsilon_value, own = jax.device_put((np.int32(menu.index(s)), np.float32(eps), own))
    return Objective(variant=index, epsilon=epsilon_value, hyperparameters=own, surrogates=menu)


def stack(objectives: Sequence[Objective]) -> Objective:
    """`objectives` as one batch (a leading axis), over all of their surrogates: what
    ``jax.vmap`` maps over to train or evaluate them side by side in one program."""
    menu = union([s for o in objectives for s in o.surrogates])
    return cast(
        Objective, jax.tree.map(lambda *xs: jnp.stack(xs), *[o.among(menu) for o in objectives])
    )


def hyperparameter_names(surrogates: Sequence[Surrogate]) -> tuple[str, ...]:
    """The hyperparameters any of `surrogates` takes, each once, in order."""
    return tuple(dict.fromkeys(key for s in surrogates for key in s.defaults))


def takers(name: str, surrogates: Mapping[str, Surrogate] = BUILTINS) -> list[str]:
    """The surrogates (by name) that take hyperparameter `name`."""
    return [key for key, s in surrogates.items() if name in s.defaults]


def identities(surrogates: Iterable[Surrogate]) -> dict[str, dict[str, dict[str, Any]]]:
    """What a record keeps of `surrogates` beyond their names: ``{"surrogates": {name:
    identity}}`` for those of one's own (:meth:`Surrogate.identity`), nothing for built-ins
    (their names pin them), so records of built-ins alone are as before."""
    own = {s.name: s.identity() for s in surrogates if not s.builtin}
    return {"surrogates": own} if own else {}
