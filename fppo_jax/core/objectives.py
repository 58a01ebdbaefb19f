"""The objective, the surrogate a run maximises as one pytree: an :class:`Objective` holds the
surrogates of one compiled program (static, :func:`union`: the paper's six and any others) and,
as arrays, which of them it is and every one's hyperparameters, so a ``jax.vmap`` over a stack
of objectives (mixed surrogates, one's own included) compiles once. A checked one is built from
a variant's name by :func:`fppo_jax.core.resolution.objective`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Mapping, Sequence
from typing import cast

import jax
import jax.numpy as jnp
import numpy as np

from fppo_jax.core.surrogates import Surrogate, SurrogateIdentity
from fppo_jax.core.variants import BUILTINS, PAPERS, VARIANTS
from fppo_jax.errors import InvalidInput


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
    :func:`~fppo_jax.core.resolution.objective`, and :func:`stack` a mixed batch.
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


def identities(surrogates: Iterable[Surrogate]) -> dict[str, dict[str, SurrogateIdentity]]:
    """What a record keeps of `surrogates` beyond their names: ``{"surrogates": {name:
    identity}}`` for those of one's own (:meth:`Surrogate.identity`), nothing for built-ins
    (their names pin them), so records of built-ins alone are as before."""
    own = {s.name: s.identity() for s in surrogates if not s.builtin}
    return {"surrogates": own} if own else {}
