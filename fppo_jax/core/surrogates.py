"""A surrogate objective, declared once: its name, its per-sample function and its own
hyperparameters with their defaults and valid ranges (:class:`Surrogate`, :func:`declare`,
through which the built-ins and one's own are declared), and its function tried as training
runs it (:func:`probe`).

A surrogate maximises a per-sample objective ``L(r, A)`` of the likelihood ratio
``r = π_θ(a|s) / π_old(a|s)`` and the advantage ``A``. Its function takes, by name, any of

    ratio, advantage     the per-sample r and A (arrays of one shape)
    kl                   the per-sample KL(π_old(·|s) ‖ π_θ(·|s)), without gradient
    epsilon              the run's clip range ε (which also clips the value loss)

and each of its own hyperparameters (float32 scalars, traced: they vmap like any pytree leaf),
and returns L, an array of the ratio's shape and float dtype::

    def clip_higher(ratio, advantage, eps_low, eps_high):
        clipped = jnp.clip(ratio, 1 - eps_low, 1 + eps_high)
        return jnp.minimum(ratio * advantage, clipped * advantage)

    mine = surrogate("my-clip-higher", clip_higher, eps_low=0.2, eps_high=0.28,
                     ranges={"eps_low": "(0, 1)", "eps_high": "> 0"},
                     clip_range=("eps_low", "eps_high"))

``clip_range`` names the hyperparameters giving the distances below and above 1 where the
surrogate stops following ``r``; the diagnostics of the negatively optimised regions R± use
them (``1 - ε`` and ``1 + ε`` when it names none).
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
import math
import re
import sys
from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import Any, TypedDict

import jax
import jax.numpy as jnp
import numpy as np

from fppo_jax.core.checks import real_number
from fppo_jax.core.digest import function_digest
from fppo_jax.errors import InvalidInput, first_line

# The arguments every surrogate function may take by name, besides its own hyperparameters.
INPUTS = ("ratio", "advantage", "kl", "epsilon")
_NAME = re.compile(r"[a-z0-9][a-z0-9_.-]*\Z")
_BOUND = re.compile(r"\s*(>=|<=|>|<)\s*(\S+)\s*\Z")
_INTERVAL = re.compile(r"\s*([\[(])\s*([^,\s]+)\s*,\s*([^,\s]+)\s*([\])])\s*\Z")


@dataclasses.dataclass(frozen=True)
class Range:
    """Where a hyperparameter is valid, written as its error message shows it: ``"> 0"``,
    ``">= 1"``, ``"< 1"``, ``"(0, 1)"``, ``"[0, 1)"`` …; `why` says what lies outside."""

    text: str
    why: str = ""

    def __post_init__(self) -> None:
        self.bounds()  # a range that cannot be read is refused when declared

    def bounds(self) -> tuple[float, float, bool, bool]:
        """(low, high, low included, high included)."""
        try:
            if match := _BOUND.match(self.text):
                op, value = match.group(1), float(match.group(2))
                if op.startswith(">"):
                    return value, math.inf, op == ">=", False
                return -math.inf, value, False, op == "<="
            if match := _INTERVAL.match(self.text):
                low, high = float(match.group(2)), float(match.group(3))
                if low <= high:
                    return low, high, match.group(1) == "[", match.group(4) == "]"
        except ValueError:
            pass
        raise InvalidInput(
            f"a range must read like '> 0', '>= 1', '< 1' or '(0, 1]', got {self.text!r}"
        )

    def __contains__(self, value: float) -> bool:
        # Written as comparisons that NaN fails: NaN lies outside every range.
        low, high, with_low, with_high = self.bounds()
        above = value >= low if with_low else value > low
        below = value <= high if with_high else value < high
        return bool(above and below)

    def __str__(self) -> str:
        low, high, _, _ = self.bounds()
        interval = not (math.isinf(low) or math.isinf(high))
        return f"in {self.text.strip()}" if interval else self.text.strip()


def check_in_range(name: str, value: object, valid: Range | None, of: str = "") -> float:
    """`value` of hyperparameter `name` as a float, if it is a finite number in `valid` (any, if
    None) both as given and as training holds it (:func:`as_trained`): the one check of every
    hyperparameter, a surrogate's own (`of` names it in the message: "for fppo-lp"), ε and the
    optimisation settings."""
    value = real_number(name, value)
    of = f" for {of}" if of else ""
    if math.isinf(value):
        raise InvalidInput(f"{name} must be finite{of}, got {value}")
    # NaN lies outside every range, and is finite nowhere.
    if valid is not None and value not in valid:
        why = f" ({valid.why})" if valid.why else ""
        raise InvalidInput(f"{name} must be {valid}{of}, got {value}{why}")
    if math.isnan(value):
        raise InvalidInput(f"{name} must be a number{of}, got {value}")
    trained = as_trained(value)
    if math.isinf(trained) or (valid is not None and trained not in valid):
        bound = "finite" if valid is None else str(valid)
        raise InvalidInput(f"{name} must be {bound}{of}, got {value}, {float32_note(value)}")
    return value


def as_trained(value: float) -> float:
    """`value` as training holds it, a float32: past float32's range it is infinite, and
    below its smallest it is 0, so a range is checked on both."""
    with np.errstate(over="ignore"):
        return float(np.float32(value))


def float32_note(value: float) -> str:
    """Why `value`, in range itself, is refused: what training's float32 makes of it."""
    return f"which training's float32 holds as {as_trained(value):g}"


# What records keep of a surrogate of one's own (:meth:`Surrogate.identity`, JSON): its name,
# its hyperparameters' defaults, the digest of its function and where an import finds it (None
# for one made in a script or a notebook). "import" is a keyword: hence the functional form.
SurrogateIdentity = TypedDict(
    "SurrogateIdentity",
    {"name": str, "hyperparameters": dict[str, float], "digest": str, "import": str | None},
)


@dataclasses.dataclass(frozen=True, eq=False)
class Surrogate:
    """A declared surrogate (see the module's docstring); build one with
    :func:`~fppo_jax.core.own_surrogates.surrogate`.

    Equal only to itself, so that a compiled program's surrogates are those very functions.
    """

    name: str
    function: Callable[..., jax.Array]
    defaults: Mapping[str, float]
    ranges: Mapping[str, Range]
    needs_kl: bool = False
    clip_range: tuple[str, str] | None = None
    builtin: bool = False
    # Where a tune searches each of its own hyperparameters (fppo_jax.core.search_space).
    search: Mapping[str, Any] = dataclasses.field(default_factory=lambda: MappingProxyType({}))

    @property
    def hyperparameters(self) -> tuple[str, ...]:
        """Its own hyperparameters' names (ε, which every surrogate has, is not one)."""
        return tuple(self.defaults)

    def __call__(
        self,
        ratio: jax.Array,
        advantage: jax.Array,
        kl: jax.Array,
        epsilon: jax.Array,
        values: Mapping[str, jax.Array],
    ) -> jax.Array:
        """L(r, A) at its hyperparameters' `values`; the function gets the inputs it takes."""
        given = {"ratio": ratio, "advantage": advantage, "kl": kl, "epsilon": epsilon, **values}
        return self.function(**{name: given[name] for name in _parameters(self.function)})

    def check(self, name: str, value: object) -> float:
        """`value` of hyperparameter `name` as a float, if it is a finite number in its range."""
        return check_in_range(name, value, self.ranges.get(name), self.name)

    def identity(self) -> SurrogateIdentity:
        """What records keep of a surrogate of one's own, so that two functions under one name
        are told apart: its name, its defaults and a digest of its function's source and of the
        values it reads (:func:`function_digest`)."""
        return {
            "name": self.name,
            "hyperparameters": dict(self.defaults),
            "digest": function_digest(self.function, f"surrogate {self.name!r}"),
            "import": self.location(),
        }

    def location(self) -> str | None:
        """Where an import finds this surrogate (``"module:attribute"``, as the command line's
        ``--variant`` takes it): an attribute of its function's module that is this very
        surrogate; None for one made in a script or a notebook (``__main__``)."""
        module = sys.modules.get(getattr(self.function, "__module__", None) or "")
        if module is None or module.__name__ == "__main__":
            return None
        found = [name for name, value in vars(module).items() if value is self]
        return f"{module.__name__}:{found[0]}" if found else None

    def __repr__(self) -> str:
        values = ", ".join(f"{k}={v:g}" for k, v in self.defaults.items())
        return f"surrogate({self.name!r}{', ' if values else ''}{values})"


def declare(
    name: str,
    function: Callable[..., jax.Array],
    ranges: Mapping[str, str | Range] | None,
    needs_kl: bool,
    clip_range: tuple[str, str] | None,
    defaults: Mapping[str, float],
    builtin: bool = False,
) -> Surrogate:
    """A :class:`Surrogate`, its declaration checked (the built-ins are declared through here
    too; :func:`~fppo_jax.core.own_surrogates.surrogate` also refuses their names and tries the
    function)."""
    if not isinstance(name, str) or not _NAME.match(name):
        raise InvalidInput(
            f"a surrogate's name must be lower-case letters, digits, '-', '_' or '.', got {name!r}"
        )
    if not callable(function):
        raise InvalidInput(f"surrogate {name!r}: its function must be callable, got {function!r}")
    clash = sorted(set(defaults) & set(INPUTS))
    if clash:
        raise InvalidInput(
            f"surrogate {name!r}: {', '.join(clash)} is an input every surrogate gets, not a "
            "hyperparameter of its own"
        )
    _check_signature(name, function, defaults)
    checked_ranges = _checked_ranges(name, ranges, clip_range, defaults)
    if not isinstance(needs_kl, bool):
        raise InvalidInput(f"surrogate {name!r}: needs_kl must be True or False, got {needs_kl!r}")
    declared = Surrogate(
        name,
        function,
        MappingProxyType(dict(defaults)),
        MappingProxyType(checked_ranges),
        needs_kl,
        None if clip_range is None else (clip_range[0], clip_range[1]),
        builtin,
    )
    for key, value in defaults.items():
        declared.check(key, value)
    return declared


def _checked_ranges(
    name: str,
    ranges: Mapping[str, str | Range] | None,
    clip_range: tuple[str, str] | None,
    defaults: Mapping[str, float],
) -> dict[str, Range]:
    """`ranges`, each a :class:`Range`, once it and `clip_range` are found to name only
    hyperparameters that the surrogate takes."""
    given = {} if ranges is None else ranges
    if not isinstance(given, Mapping) or not all(
        isinstance(r, str | Range) for r in given.values()
    ):
        raise InvalidInput(
            f"surrogate {name!r}: ranges must map hyperparameters to a range's text, such as "
            f"{{'eps_high': '> 0'}}, got {ranges!r}"
        )
    checked = {key: r if isinstance(r, Range) else Range(r) for key, r in given.items()}
    stray = sorted(set(checked) - set(defaults))
    if clip_range is not None:
        if not (isinstance(clip_range, tuple | list) and len(clip_range) == 2):
            raise InvalidInput(
                f"surrogate {name!r}: clip_range must name two hyperparameters, got {clip_range!r}"
            )
        stray += [key for key in clip_range if key not in defaults]
    if stray:
        raise InvalidInput(
            f"surrogate {name!r} has no hyperparameter {', '.join(map(repr, stray))} "
            f"(it takes: {', '.join(defaults) or 'none'})"
        )
    return checked


def _parameters(function: Callable[..., Any]) -> tuple[str, ...]:
    return tuple(inspect.signature(function).parameters)


def _check_signature(
    name: str, function: Callable[..., Any], defaults: Mapping[str, float]
) -> None:
    try:
        parameters = inspect.signature(function).parameters
    except (TypeError, ValueError):
        raise InvalidInput(
            f"surrogate {name!r}: the signature of {function!r} cannot be read"
        ) from None
    takes = (*INPUTS, *defaults)
    unknown = [
        p
        for p, spec in parameters.items()
        if p not in takes
        or spec.kind in (spec.VAR_POSITIONAL, spec.VAR_KEYWORD, spec.POSITIONAL_ONLY)
    ]
    if unknown:
        raise InvalidInput(
            f"surrogate {name!r}: its function takes {', '.join(unknown)}, which it would not "
            f"be given; it may take {', '.join(INPUTS)} and its hyperparameters "
            f"({', '.join(defaults) or 'none declared'}), each by name"
        )
    missing = [p for p in ("ratio", "advantage", *defaults) if p not in parameters]
    if missing:
        raise InvalidInput(
            f"surrogate {name!r}: its function does not take {', '.join(missing)} (a surrogate "
            "takes ratio and advantage, and each hyperparameter it declares, by name)"
        )


# What a function that runs on arrays does wrong under tracing, as training traces it, and how
# to write it instead; the most specific first (a bool conversion is a concretization).
_TRACING_ERRORS: tuple[tuple[type[Exception], str], ...] = (
    (
        jax.errors.TracerBoolConversionError,
        "uses Python control flow (if, while, and, or) on traced values; use jnp.where",
    ),
    (
        jax.errors.TracerArrayConversionError,
        "turns a traced value into a NumPy array (NumPy where jax.numpy is needed); use jax.numpy",
    ),
    (
        jax.errors.TracerIntegerConversionError,
        "needs a traced value as a Python integer; keep it an array and use jax.numpy",
    ),
    (
        jax.errors.ConcretizationTypeError,
        "needs a traced value as a Python number (float(), int(), a shape from values); keep it "
        "an array and use jax.numpy",
    ),
)


def probe(declared: Surrogate, values: Mapping[str, float], epsilon: float = 0.2) -> None:
    """Try `declared` with `values` on ratios 0.25 … 4 and advantages of both signs (a KL of
    0 and 0.1), under ``jax.jit`` and ``jax.grad`` as training runs it: its value must be a
    finite float array of the ratio's shape, and its slope in the ratio finite."""
    ratio: np.ndarray | jax.Array
    advantage: np.ndarray | jax.Array
    ratio, advantage = np.meshgrid(np.geomspace(0.25, 4.0, 17), [-2.0, -0.5, 0.0, 0.5, 2.0])
    ratio, advantage = (
        jnp.asarray(ratio.ravel(), jnp.float32),
        jnp.asarray(advantage.ravel(), jnp.float32),
    )
    kl = jnp.tile(jnp.asarray([0.0, 0.1], jnp.float32), ratio.size // 2 + 1)[: ratio.size]
    arrays = {key: jnp.asarray(value, jnp.float32) for key, value in values.items()}
    eps = jnp.asarray(epsilon, jnp.float32)
    inputs = (ratio, advantage, kl, eps, arrays)

    where = f"surrogate {declared.name!r}"
    try:
        shape = jax.eval_shape(declared, *inputs)
    except Exception as error:
        raise _failed(where, error) from None
    if not hasattr(shape, "shape") or shape.shape != ratio.shape:
        raise InvalidInput(
            f"{where} must return one value per sample (an array of the ratio's shape "
            f"{ratio.shape}), got {_described(shape)}"
        )
    if not jnp.issubdtype(shape.dtype, jnp.floating):
        raise InvalidInput(f"{where} must return floats, got {shape.dtype}")
    try:
        out, slope = _value_and_slope(declared, *inputs)
    except Exception as error:
        raise _failed(where, error) from None
    for what, array in (("value", out), ("slope in the ratio", slope)):
        bad = ~np.isfinite(np.asarray(array))
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise InvalidInput(
                f"{where} has a {what} that is not finite ({float(np.asarray(array)[i])}) at "
                f"ratio {float(ratio[i]):.3g}, advantage {float(advantage[i]):g} with "
                + ", ".join(f"{k} = {v:g}" for k, v in {"epsilon": epsilon, **values}.items())
            )


def _failed(where: str, error: Exception) -> InvalidInput:
    """Why the surrogate `where` names failed when tried, in one line."""
    cause = next((why for kind, why in _TRACING_ERRORS if isinstance(error, kind)), None)
    if cause is not None:
        return InvalidInput(f"{where} {cause}")
    return InvalidInput(f"{where} failed when tried: {type(error).__name__}: {first_line(error)}")


@functools.partial(jax.jit, static_argnums=0)
def _value_and_slope(
    declared: Surrogate,
    ratio: jax.Array,
    advantage: jax.Array,
    kl: jax.Array,
    epsilon: jax.Array,
    values: Mapping[str, jax.Array],
) -> tuple[jax.Array, jax.Array]:
    """`declared`'s value per sample and its slope in the ratio, compiled as training compiles
    it (once per surrogate). Per sample: the surrogate is element-wise, so the slope of the sum
    is each one's slope."""

    def summed(r: jax.Array) -> tuple[jax.Array, jax.Array]:
        out = declared(r, advantage, kl, epsilon, values)
        return jnp.sum(out), out

    (_, out), slope = jax.value_and_grad(summed, has_aux=True)(ratio)
    return out, slope


def _described(out: object) -> str:
    shape = getattr(out, "shape", None)
    return f"shape {shape}" if shape is not None else type(out).__name__
