"""A surrogate of one's own, declared (:func:`surrogate`): its declaration checked as a
built-in's is (:func:`~fppo_jax.core.surrogates.declare`), and against every other name a run
knows (the built-ins', the settings', the command line's), its function identified and tried,
and the intervals a tune searches its hyperparameters over read.

The command line's names are the parser's: this module asks it for them, lazily, the one import
that runs upward (``tests/test_layers.py``)."""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import Any

import jax

from fppo_jax.core.config import CONFIG_FIELDS
from fppo_jax.core.digest import function_digest
from fppo_jax.core.resolution import HYPERPARAMETER_DEFAULTS
from fppo_jax.core.search_space import interval
from fppo_jax.core.surrogates import Range, Surrogate, declare, probe
from fppo_jax.core.variants import BUILTINS
from fppo_jax.errors import InvalidInput


def surrogate(
    name: str,
    function: Callable[..., jax.Array],
    /,
    *,
    ranges: Mapping[str, str | Range] | None = None,
    needs_kl: bool = False,
    clip_range: tuple[str, str] | None = None,
    search: Mapping[str, Any] | None = None,
    **defaults: float,
) -> Surrogate:
    """A surrogate of one's own, accepted wherever a variant's name is (``train``, ``sweep``
    grids, :func:`~fppo_jax.objective`, :func:`~fppo_jax.hyperparameters`).

    `function` takes ``ratio``, ``advantage`` and any of ``kl`` and ``epsilon`` by name, and
    each hyperparameter named in `defaults` (their default values); `ranges` gives a
    hyperparameter's valid range as text (``"> 0"``, ``"[0, 1)"``); `needs_kl` says the
    surrogate gates on the KL divergence (so calling its objective without one is refused);
    `clip_range` names the two hyperparameters that are its distances below and above 1 (for
    the R± diagnostics; ε's otherwise); `search` gives the interval a tune searches each of
    them over, as ``(low, high)`` or ``(low, high, scale)`` with scale ``linear``, ``log`` or
    ``log1m`` (see :mod:`fppo_jax.core.search_space`). Everything is checked here, and the function
    is tried on a grid of ratios and advantages under ``jax.jit`` and ``jax.grad``, as training
    runs it: one that cannot be traced, or a value that is not finite, of the wrong shape or not
    a float, is refused, naming the surrogate.
    """
    if name in BUILTINS:
        raise InvalidInput(
            f"a surrogate cannot be named {name!r}: that is a built-in variant's name "
            f"(built-ins: {', '.join(BUILTINS)})"
        )
    declared = declare(name, function, ranges, needs_kl, clip_range, defaults)
    taken = [f"{key} is {what}" for key in defaults if (what := _taken_names().get(key))]
    if taken:
        raise InvalidInput(
            f"surrogate {name!r}: a hyperparameter of its own cannot take another setting's name "
            f"({'; '.join(taken)}), whose value it would take or shadow: rename it"
        )
    function_digest(function, f"surrogate {name!r}")  # what cannot be identified is refused
    probe(declared, declared.defaults)
    if search is None:
        return declared
    if not isinstance(search, Mapping):
        raise InvalidInput(
            f"surrogate {name!r}: search maps its hyperparameters to (low, high), got {search!r}"
        )
    stray = sorted(set(search) - set(defaults))
    if stray:
        raise InvalidInput(
            f"surrogate {name!r}: search names {', '.join(map(repr, stray))}, which it does not "
            f"take (it takes: {', '.join(defaults) or 'none'})"
        )
    where = f"surrogate {name!r}'s search"
    intervals = {key: interval(key, value, where) for key, value in search.items()}
    return dataclasses.replace(declared, search=MappingProxyType(intervals))


@functools.cache
def _taken_names() -> dict[str, str]:
    """What a surrogate's hyperparameter may not be named, each with what it is: an
    optimisation setting, a field of the run's shape or any name of the command line, where a
    hyperparameter becomes a flag and a setting of ``--config FILE``. The built-ins'
    hyperparameters are shared, as ``alpha`` is."""
    from fppo_jax.cli.parser import command_line_names  # the one import upward, done lazily

    shared = {key for s in BUILTINS.values() for key in s.defaults}
    return {
        **{key: "a name of the command line" for key in command_line_names() - shared},
        **{key: "a TrainConfig field" for key in CONFIG_FIELDS},
        **{key: "an optimisation setting" for key in HYPERPARAMETER_DEFAULTS},
    }
