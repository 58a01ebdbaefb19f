"""What a tune searches: each hyperparameter's interval and the scale it is drawn on.

Every arm of a tune searches the same intervals for the hyperparameters every surrogate shares
(:data:`SHARED`): the optimisation settings and the clip range ε. A surrogate's own
hyperparameters (FPPO-LP's α, DPO's α and β, …) are searched over the intervals of
:data:`OWN` for the built-ins, or those a surrogate of one's own declares
(``fppo_jax.surrogate(..., search={...})``); one with neither is refused by name.

Scales: ``linear`` draws the value uniformly; ``log`` draws its logarithm uniformly; ``log1m``
draws the logarithm of 1 − value uniformly, so that a discount such as γ reaches 0.999 and
0.9999 as often as 0.9 and 0.99.

The default intervals span the tuned settings that RL Baselines3 Zoo and CleanRL publish for
PPO (``rl_zoo3/hyperparams/ppo.yml`` and the sampler of ``rl_zoo3/hyperparams_opt.py``;
CleanRL's ``ppo_continuous_action.py`` and ``ppo.py``): learning rates 2e-5 … 2.5e-3
(RL Zoo's HalfCheetah 2.06e-5, CleanRL's 3e-4 and 2.5e-4), γ from 0.9 to 0.9999 (RL Zoo's
sampler's choices; 0.9999 its Swimmer), λ 0.8 … 1 (its choices 0.8 … 1.0), ε 0.1 … 0.4 (its
choices), an entropy weight 0 … 0.01 (RL Zoo's tuned values are 4e-4 … 2.3e-3, CleanRL's 0 and
0.01), a gradient clip 0.3 … 5 (its choices) and a value weight 0.25 … 1
(CleanRL's 0.5; RL Zoo's tuned 0.5 … 0.92).
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypedDict

from fppo_jax.core.resolution import HYPERPARAMETER_DEFAULTS, hyperparameters, table2
from fppo_jax.core.shape_space import SHAPE_AXES, Choice, ChoiceValue
from fppo_jax.core.surrogates import Surrogate
from fppo_jax.core.variants import EPSILON
from fppo_jax.errors import InvalidInput

SCALES = ("linear", "log", "log1m")


class Axis(TypedDict):
    """An interval as records hold it (a tune's ``tune.json``)."""

    low: float
    high: float
    scale: str


@dataclasses.dataclass(frozen=True)
class Interval:
    """Where a hyperparameter is searched: from `low` to `high`, both included, on `scale`."""

    low: float
    high: float
    scale: str = "linear"

    def to_json(self) -> Axis:
        return {"low": self.low, "high": self.high, "scale": self.scale}

    def contains(self, value: float) -> bool:
        return self.low <= value <= self.high

    def __str__(self) -> str:
        return f"[{self.low:g}, {self.high:g}] ({self.scale})"


SHARED: dict[str, Interval] = {
    "learning_rate": Interval(1e-5, 3e-3, "log"),
    "gamma": Interval(0.9, 0.9999, "log1m"),
    "gae_lambda": Interval(0.8, 1.0),
    "epsilon": Interval(0.1, 0.4),
    "entropy_coef": Interval(0.0, 0.01),
    "max_grad_norm": Interval(0.3, 5.0, "log"),
    "value_coef": Interval(0.25, 1.0),
}

# The built-ins' own hyperparameters, searched around their papers' values: FPPO-LP's α over
# the paper's ablation (Fig. 6: 1.1 … 1.5) widened to 2; FPPO-QP's k over its ablation
# (0.1 … 0.5) from 0 (PPO) to 1; the RB variants' rollback α and the KL bounds δ around the
# Truly PPO paper's (Wang et al. 2019: α 0.05 … 0.3, δ 0.02 … 0.035); clip-higher's ε_low and
# ε_high around DAPO's (Yu et al. 2025: 0.2 and 0.28); DPO's α and β around its paper's
# (Goldie et al. 2024: 2 and 0.6).
OWN: dict[str, dict[str, Interval]] = {
    "ppo": {},
    "spo": {},
    "fppo-lp": {"alpha": Interval(1.0, 2.0)},
    "fppo-qp": {"k": Interval(0.0, 1.0)},
    "tr-ppo": {"delta": Interval(0.005, 0.1, "log")},
    "ppo-rb": {"alpha": Interval(0.0, 1.0)},
    "tr-ppo-rb": {"alpha": Interval(0.0, 0.5), "delta": Interval(0.005, 0.1, "log")},
    "clip-higher": {"eps_low": Interval(0.1, 0.4), "eps_high": Interval(0.1, 0.6)},
    "dpo": {"alpha": Interval(0.5, 4.0, "log"), "beta": Interval(0.2, 1.5, "log")},
}


def interval(name: str, value: Any, where: str) -> Interval:
    """`value` (``{"low": …, "high": …, "scale": …}`` or ``(low, high[, scale])``) as an
    :class:`Interval` of hyperparameter `name`, its shape checked (`where` names its source)."""
    if isinstance(value, Interval):
        found = value
    elif isinstance(value, Mapping):
        stray = sorted(set(value) - {"low", "high", "scale"})
        if stray or not {"low", "high"} <= set(value):
            raise InvalidInput(
                f"{where}: {name} must be {{'low': …, 'high': …, 'scale': …}}, got {value!r}"
            )
        found = Interval(value["low"], value["high"], value.get("scale", "linear"))
    elif isinstance(value, list | tuple) and len(value) in (2, 3):
        found = Interval(*value)
    else:
        raise InvalidInput(f"{where}: {name} must be (low, high[, scale]), got {value!r}")
    low, high, scale = found.low, found.high, found.scale
    numbers = all(
        isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)
        for x in (low, high)
    )
    if not numbers or low > high:
        raise InvalidInput(f"{where}: {name}'s interval must be finite, low <= high, got {value!r}")
    if scale not in SCALES:
        raise InvalidInput(
            f"{where}: {name}'s scale must be one of {', '.join(SCALES)}, got {scale!r}"
        )
    if scale == "log" and low <= 0:
        raise InvalidInput(f"{where}: {name} on a log scale needs low > 0, got {low}")
    if scale == "log1m" and high >= 1:
        raise InvalidInput(f"{where}: {name} on a log1m scale needs high < 1, got {high}")
    return Interval(float(low), float(high), scale)


@dataclasses.dataclass(frozen=True)
class SearchSpace:
    """The intervals of one arm: the shared ones, then its surrogate's own; on a task, the
    run-shape axes every arm shares (`shape`, :mod:`fppo_jax.core.shape_space`) with each
    one's value at trial 0 (`shape_default`)."""

    shared: Mapping[str, Interval]
    own: Mapping[str, Interval]
    shape: Mapping[str, Choice] = dataclasses.field(default_factory=dict)
    shape_default: Mapping[str, ChoiceValue] = dataclasses.field(default_factory=dict)

    @property
    def axes(self) -> dict[str, Interval | Choice]:
        return {**self.shared, **self.shape, **self.own}

    def to_json(self) -> dict[str, Axis]:
        """The intervals (a task's run-shape axes are recorded apart, per task)."""
        return {name: axis.to_json() for name, axis in {**self.shared, **self.own}.items()}


def read_space_file(path: str | Path) -> dict[str, Any]:
    """A space file (JSON, or YAML: .yaml/.yml): ``{name: interval}`` for shared axes and
    ``{variant: {name: interval}}`` for a variant's own."""
    path = Path(path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as error:
        raise InvalidInput(f"cannot read the space file {path}: {error}") from None
    try:
        if path.suffix in (".yaml", ".yml"):
            data = _yaml_with_numbers(text)
        else:
            data = json.loads(text)
    except Exception as error:  # JSON's and YAML's own errors, whose text names the place
        raise InvalidInput(f"cannot read the space file {path}: {error}") from None
    if not isinstance(data, dict):
        raise InvalidInput(f"the space file {path} must map names to intervals, got {data!r}")
    return data


# A number in exponent form without a dot (1e-4, 2E+3): YAML 1.2 and JSON read it as a number,
# but PyYAML follows YAML 1.1, whose floats need the dot, and reads it as text.
_EXPONENT = re.compile(r"^[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+$")


def _yaml_with_numbers(text: str) -> Any:
    """`text` as PyYAML's safe loader reads it, but for :data:`_EXPONENT`, read as a number:
    an interval written ``{low: 1e-4, high: 1e-2}`` means numbers, as in a JSON file."""
    import yaml

    # On a class of its own: PyYAML's resolvers are class-wide, and SafeLoader is everyone's.
    loader: Any = type("Loader", (yaml.SafeLoader,), {})
    loader.add_implicit_resolver("tag:yaml.org,2002:float", _EXPONENT, list("-+0123456789"))
    return yaml.load(text, Loader=loader)  # a SafeLoader, with one more resolver


def search_spaces(
    surrogates: list[Surrogate], given: Mapping[str, Any] | None = None
) -> dict[str, SearchSpace]:
    """Each arm's search space: :data:`SHARED` and the arm's own intervals, replaced where
    `given` (a space file's content) names them (its run-shape axes are
    :func:`~fppo_jax.core.shape_space.shape_space`'s). Every interval is checked against the
    hyperparameter's valid range at both ends, so that every point of it can train."""
    given = dict(given or {})
    arms = {s.name for s in surrogates}
    shared = dict(SHARED)
    for name in [n for n in given if n not in arms and n not in SHAPE_AXES]:
        if name not in SHARED:
            valid = ", ".join([*SHARED, *SHAPE_AXES, *sorted(arms)])
            raise InvalidInput(f"the search space has no axis {name!r}; it takes: {valid}")
        shared[name] = interval(name, given.pop(name), "the search space")
    for name, axis in shared.items():
        _check_ends(name, axis, lambda value, name=name: _check_shared(name, value))
    spaces = {}
    for s in surrogates:
        own = dict(OWN.get(s.name, {})) if s.builtin else dict(s.search)
        replaced = given.get(s.name, {})
        if not isinstance(replaced, Mapping):
            raise InvalidInput(f"the search space of {s.name} must map names to intervals")
        for name, value in replaced.items():
            if name not in s.defaults:
                raise InvalidInput(
                    f"the search space gives {s.name} {name!r}, which it does not take "
                    f"(it takes: {', '.join(s.defaults) or 'none'})"
                )
            own[name] = interval(name, value, f"the search space of {s.name}")
        missing = [name for name in s.defaults if name not in own]
        if missing:
            raise InvalidInput(
                f"{s.name} has no search interval for {', '.join(missing)}: declare one "
                f"(fppo_jax.surrogate(..., search={{{missing[0]!r}: (low, high)}})) or give "
                "it in the space file"
            )
        for name, axis in own.items():
            _check_ends(name, axis, lambda value, name=name, s=s: s.check(name, value))
        spaces[s.name] = SearchSpace(shared, own)
    return spaces


def _check_ends(name: str, axis: Interval, check: Any) -> None:
    """Both ends of `axis` valid for `name` (an interval reaches both)."""
    for end in (axis.low, axis.high):
        try:
            check(end)
        except InvalidInput as error:
            raise InvalidInput(
                f"the search interval {axis} of {name} leaves its range: {error}"
            ) from None


def _check_shared(name: str, value: float) -> None:
    hyperparameters("ppo", **{name: value})


def default_setting(surrogate: Surrogate, task: str | None) -> dict[str, float]:
    """The arm's own default setting on `task` (trial 0): the optimisation settings' defaults,
    ε, and its own defaults (the paper's Table 2 for FPPO on a registered task)."""
    return {
        **HYPERPARAMETER_DEFAULTS,
        "epsilon": EPSILON,
        **dict(surrogate.defaults),
        **table2(task, surrogate.name),
    }
