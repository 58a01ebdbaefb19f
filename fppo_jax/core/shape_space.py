"""What a tune searches of the run's shape: categorical axes of :class:`~fppo_jax.core.config.
TrainConfig` fields, each combination of values its own compiled program.

Andrychowicz et al. (2021, "What matters in on-policy reinforcement learning?") rank the
rollout's length, the epochs and minibatches, observation normalisation, the networks' size and
the policy's initial action std among the choices that matter most. RL Baselines3 Zoo's tuned
MuJoCo PPO settings (``rl_zoo3/hyperparams/ppo.yml``) span 512 to 2,048 samples per update,
minibatches of 32 to 64 samples, 5 to 20 epochs, layers of 64 or 256 units and an initial
log-std from 0 down to −2 (its HalfCheetah's). The default axes, around the task's configured
shape (n steps per rollout, m minibatches):

- ``num_steps``: n, n/2 and n/4 (2,048 samples per update down to 512 at the paper's 8 × 256);
  the number of environments stays as configured: it is the machine's choice, not the method's;
- ``num_minibatches``: m, m/2 and m/4 (minibatches of 16 to 256 samples at the paper's);
- ``num_epochs``: 5, 10 and 20;
- ``hidden_sizes``: ``"64,64"`` and ``"256,256"``;
- ``normalize_observations``: on and off;
- ``initial_log_std``: 0, −0.5, −1 and −2, on tasks with continuous actions alone.

An axis the run's settings fix (``--num-steps …``) is not searched. A space file gives an axis
its own values (``{"num_epochs": [10, 20]}``), the configured one among them (trial 0's).
Every combination of the values is checked on the task before any compile, and one that makes
no valid run is refused by name. A searched shape
changes the number of updates in a run, so only schedulers whose runs are whole (racing, the
validation race) search it: :func:`~fppo_jax.analysis.tune_design.design` says so.
"""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Collection, Mapping
from typing import Any, TypedDict

from fppo_jax.core.config import TrainConfig
from fppo_jax.errors import InvalidInput

# A value of a categorical axis, as Optuna draws it and records hold it (hidden sizes as text).
ChoiceValue = int | float | bool | str

SHAPE_AXES = (
    "num_steps",
    "num_minibatches",
    "num_epochs",
    "hidden_sizes",
    "normalize_observations",
    "initial_log_std",
)


class ChoiceAxis(TypedDict):
    """A categorical axis as records hold it (a tune's ``tune.json``)."""

    choices: list[ChoiceValue]


@dataclasses.dataclass(frozen=True)
class Choice:
    """A categorical axis: one of `values`, each as likely."""

    values: tuple[ChoiceValue, ...]

    def to_json(self) -> ChoiceAxis:
        return {"choices": list(self.values)}

    def __str__(self) -> str:
        return "{" + ", ".join(str(v) for v in self.values) + "}"


def default_axes(config: TrainConfig, continuous: bool) -> dict[str, Choice]:
    """The default run-shape axes around `config` (see the module)."""
    steps, minibatches = config.num_steps, config.num_minibatches
    axes = {
        "num_steps": Choice(_fractions(steps)),
        "num_minibatches": Choice(_fractions(minibatches)),
        "num_epochs": Choice((5, 10, 20)),
        "hidden_sizes": Choice(("64,64", "256,256")),
        "normalize_observations": Choice((True, False)),
    }
    if continuous:
        axes["initial_log_std"] = Choice((0.0, -0.5, -1.0, -2.0))
    return axes


def _fractions(value: int) -> tuple[int, ...]:
    """`value`, its half and its quarter, where whole."""
    return tuple(value // d for d in (1, 2, 4) if value % d == 0)


def configured(config: TrainConfig, name: str) -> ChoiceValue:
    """Axis `name`'s value in `config`, as the axis holds it (trial 0's)."""
    value = getattr(config, name)
    return ",".join(map(str, value)) if name == "hidden_sizes" else value


def shape_space(
    config: TrainConfig,
    continuous: bool,
    fixed: Collection[str],
    given: Mapping[str, Any],
    searched: bool,
) -> dict[str, Choice]:
    """The run-shape axes a tune searches on a task configured as `config`: where `searched`,
    the default axes, less those the run's settings fix (`fixed`), with those `given` (a space
    file's run-shape entries) in their place; else only those given. Every combination is
    checked to make a valid run of `config`'s budget."""
    axes = default_axes(config, continuous) if searched else {}
    axes = {name: axis for name, axis in axes.items() if name not in fixed}
    for name, value in given.items():
        if name in fixed:
            raise InvalidInput(
                f"{name} is fixed by the run's settings and searched by the space: give one"
            )
        if name == "initial_log_std" and not continuous:
            raise InvalidInput("initial_log_std is searched only where the actions are continuous")
        axes[name] = Choice(_choices(name, value))
        if configured(config, name) not in axes[name].values:
            raise InvalidInput(
                f"the search space: {name}'s values {list(axes[name].values)} leave out the "
                f"task's own {configured(config, name)!r}, trial 0's (the default): list it too, "
                f"or fix {name} as a setting"
            )
    for combination in itertools.product(*(axis.values for axis in axes.values())):
        shape = dict(zip(axes, combination, strict=True))
        try:
            dataclasses.replace(config, **config_values(shape))
        except InvalidInput as error:
            values = ", ".join(f"{name} {value}" for name, value in shape.items())
            raise InvalidInput(f"the run shape {values} makes no valid run: {error}") from None
    return axes


def _choices(name: str, value: Any) -> tuple[ChoiceValue, ...]:
    """A space file's values of run-shape axis `name` (a list, or ``{"choices": [...]}``)."""
    if isinstance(value, Mapping) and set(value) == {"choices"}:
        value = value["choices"]
    if not isinstance(value, list | tuple) or not value:
        raise InvalidInput(
            f"the search space: {name} is a run-shape axis, given as a list of values, "
            f"got {value!r}"
        )
    values = tuple(
        ",".join(map(str, v)) if name == "hidden_sizes" and isinstance(v, list | tuple) else v
        for v in value
    )
    if len(set(map(repr, values))) < len(values):
        raise InvalidInput(f"the search space: {name} lists a value twice: {list(values)}")
    return values


def config_values(shape: Mapping[str, ChoiceValue]) -> dict[str, Any]:
    """Run-shape values as :class:`~fppo_jax.core.config.TrainConfig` takes them (hidden sizes
    ``"64,64"`` as ``(64, 64)``)."""
    values: dict[str, Any] = dict(shape)
    sizes = values.get("hidden_sizes")
    if isinstance(sizes, str):
        try:
            values["hidden_sizes"] = tuple(int(width) for width in sizes.split(","))
        except ValueError:
            raise InvalidInput(
                f"hidden_sizes must be layer widths such as '64,64', got {sizes!r}"
            ) from None
    return values


def split_setting(
    setting: Mapping[str, Any],
) -> tuple[dict[str, Any], dict[str, ChoiceValue]]:
    """A trial's setting as its hyperparameters and its run-shape values."""
    hyperparameters = {k: v for k, v in setting.items() if k not in SHAPE_AXES}
    shape = {k: v for k, v in setting.items() if k in SHAPE_AXES}
    return hyperparameters, shape
