"""Resolution, in one place: a variant's name → its surrogate → its hyperparameters, each with
its default (the paper's Table 2 for FPPO's α and k on a registered task), range and check →
the checked :class:`~fppo_jax.core.config.Hyperparameters` that a run trains with.

A variant's name travels down from here and never comes back: :func:`resolve` finds the
surrogate among the built-ins (:mod:`fppo_jax.core.variants`) or imports it
(``module:attribute``); :func:`objective` checks ε and its own hyperparameters against their
ranges (:class:`~fppo_jax.core.surrogates.Surrogate`) and builds the
:class:`~fppo_jax.core.objectives.Objective`; :func:`hyperparameters` adds the optimisation
settings, checked here; :func:`resolve_hyperparameters` does it all for one setting of a task.
"""

from __future__ import annotations

import importlib
import os
import sys
from collections.abc import Iterable
from typing import Any

import jax
import numpy as np

from fppo_jax.core.config import Hyperparameters, Setting
from fppo_jax.core.objectives import Objective, hyperparameter_names, union
from fppo_jax.core.surrogates import Range, Surrogate, check_in_range, probe
from fppo_jax.core.variants import BUILTINS, DEFAULT_VARIANT, EPSILON, VARIANTS
from fppo_jax.errors import FppoError, InvalidInput, first_line

EPSILON_RANGE = Range("(0, 1)")

# The paper's Table 2: FPPO-LP's α and FPPO-QP's k per task.
TABLE2: dict[str, dict[str, float]] = {
    **{task: {"alpha": 1.3, "k": 0.4} for task in ("cartpole", "acrobot", "mountaincar")},
    "hopper": {"alpha": 1.3, "k": 0.2},
    "walker2d": {"alpha": 1.3, "k": 0.1},
    "halfcheetah": {"alpha": 1.3, "k": 0.4},
    "ant": {"alpha": 1.3, "k": 0.4},
    "reacher": {"alpha": 1.1, "k": 0.4},
    "swimmer": {"alpha": 1.1, "k": 0.1},
}
_TABLE2_VARIANTS = {"fppo-lp": "alpha", "fppo-qp": "k"}

# The hyperparameters some built-in variants take and others do not (α, k, δ, …).
VARIANT_SPECIFIC: tuple[str, ...] = hyperparameter_names(list(BUILTINS.values()))
SYMBOLS = {
    "alpha": "α",
    "k": "k",
    "delta": "δ",
    "epsilon": "ε",
    "beta": "β",
    "eps_low": "ε_low",
    "eps_high": "ε_high",
}

HYPERPARAMETER_DEFAULTS: dict[str, float] = {
    "learning_rate": 3e-4,
    "gamma": 0.99,
    "gae_lambda": 0.95,
    "entropy_coef": 0.0,
    "value_coef": 0.5,
    "max_grad_norm": 0.5,
}

_RANGES: dict[str, Range] = {
    "learning_rate": Range("> 0"),
    "gamma": Range("(0, 1]"),
    "gae_lambda": Range("[0, 1]"),
    "entropy_coef": Range(">= 0"),
    "value_coef": Range(">= 0"),
    "max_grad_norm": Range("> 0"),
}


def resolve_hyperparameters(
    variant: str | Surrogate, task: str | None = None, **values: Any
) -> tuple[Hyperparameters, Setting]:
    """Checked hyperparameters of one setting, with Table 2's α or k for a registered `task`,
    and the setting as plain values (the variant's name, ε, its own hyperparameters, the
    optimisation settings), as records and tables show it."""
    surrogate = resolve(variant)
    given = {name: value for name, value in values.items() if value is not None}
    hp = hyperparameters(surrogate, **{**table2(task, surrogate.name), **given})
    o = hp.objective
    settings: Setting = {"variant": surrogate.name, "epsilon": as_float(o.epsilon)}
    settings.update({name: as_float(value) for name, value in o.values.items()})
    settings.update({name: as_float(getattr(hp, name)) for name in HYPERPARAMETER_DEFAULTS})
    return hp, settings


def table2(task: str | None, variant: str) -> dict[str, float]:
    """The paper's Table 2 value of `variant`'s own hyperparameter on `task` ({} if none)."""
    name = _TABLE2_VARIANTS.get(variant)
    if task not in TABLE2 or name is None:
        return {}
    return {name: TABLE2[task][name]}


def hyperparameters(
    variant: str | Surrogate = DEFAULT_VARIANT, *, epsilon: float = EPSILON, **values: float | None
) -> Hyperparameters:
    """Checked hyperparameters: the objective of `variant` (a built-in's name or a surrogate of
    one's own; ε and its own hyperparameters, see :func:`objective`) and
    the optimisation settings.

    Unset settings take :data:`HYPERPARAMETER_DEFAULTS`; unknown names and out-of-range values
    raise ``InvalidInput`` naming the parameter.
    """
    surrogate = resolve(variant)
    taken_by_some = hyperparameter_names([*BUILTINS.values(), surrogate])
    own = {name: values.pop(name) for name in taken_by_some if name in values}
    unknown = sorted(set(values) - set(HYPERPARAMETER_DEFAULTS))
    if unknown:
        raise InvalidInput(
            f"unknown hyperparameter {', '.join(unknown)}; valid: "
            + ", ".join(["epsilon", *taken_by_some, *HYPERPARAMETER_DEFAULTS])
        )
    settings = {**HYPERPARAMETER_DEFAULTS, **{k: v for k, v in values.items() if v is not None}}
    for name, value in settings.items():
        check_in_range(name, value, _RANGES[name])
    # NumPy's scalars, put on the device as they are (as the objective's own: no conversion
    # program to compile).
    scalars = jax.device_put({name: np.float32(value) for name, value in settings.items()})
    return Hyperparameters(objective=objective(surrogate, epsilon=epsilon, **own), **scalars)


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
    eps = check_in_range("epsilon", epsilon, EPSILON_RANGE)
    values = {key: s.check(key, value) for key, value in {**s.defaults, **given}.items()}
    if not s.builtin:
        try:
            probe(s, values, eps)
        except InvalidInput as error:
            raise InvalidInput(f"{error}{_where_finite(s)}") from None
    menu = union([s])
    # NumPy's scalars, put on the device as they are: JAX's own conversion of a Python number
    # is a small program, compiled for each dtype on every start.
    own = {key: np.float32(values.get(key, 0.0)) for key in hyperparameter_names(menu)}
    index, epsilon_value, own = jax.device_put((np.int32(menu.index(s)), np.float32(eps), own))
    return Objective(variant=index, epsilon=epsilon_value, hyperparameters=own, surrogates=menu)


def _where_finite(surrogate: Surrogate) -> str:
    """What to do about a surrogate of one's own that fails at hyperparameters other than
    those its declaration tried (its defaults, which passed): a tune draws them from its search
    space, and one such point stops the tune, so the space is what to narrow."""
    names = " or ".join([*surrogate.defaults, "epsilon"])
    return (
        f": give it {names} where it is finite (a tune draws them from its search space and "
        f"stops at such a point: narrow the interval of {names} to where it is finite, in a "
        "space file, --space, and tune into a new output)"
    )


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


def sweepable(surrogates: Iterable[Surrogate] = ()) -> tuple[str, ...]:
    """What a sweep's grid may vary: the variant, ε, the hyperparameters of the built-ins and of
    `surrogates`, and the optimisation settings."""
    own = hyperparameter_names([*BUILTINS.values(), *surrogates])
    return ("variant", "epsilon", *own, *HYPERPARAMETER_DEFAULTS)


SWEEPABLE: tuple[str, ...] = sweepable()


def as_float(x: jax.Array) -> float:
    """The shortest decimal that round-trips the float32, so that 1.3 is reported as 1.3."""
    return float(str(np.asarray(x)[()]))
