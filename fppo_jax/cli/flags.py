"""The command line's flags: argument types that turn text into checked values, and the flags
generated from the fields that declare them once (:class:`~fppo_jax.core.config.TrainConfig`'s run
shape, :class:`~fppo_jax.run.options.Options`' way of driving a run), read back as keyword
arguments of ``train`` and ``sweep``."""

from __future__ import annotations

import argparse
import dataclasses
import math
from collections.abc import Callable, Sequence
from decimal import Decimal, InvalidOperation
from pathlib import Path
from typing import Any, NoReturn

from fppo_jax.core.checks import check_part, parse_seeds, positive_int
from fppo_jax.core.config import PRESETS, TrainConfig
from fppo_jax.core.objectives import hyperparameter_names
from fppo_jax.core.resolution import HYPERPARAMETER_DEFAULTS, resolve
from fppo_jax.core.surrogates import Surrogate
from fppo_jax.core.variants import BUILTINS, EPSILON
from fppo_jax.envs import BACKENDS
from fppo_jax.errors import InvalidInput
from fppo_jax.run.options import Options
from fppo_jax.stats.sequential import check_level, check_margin
from fppo_jax.stats.statistics import CONFIDENCE, ENDPOINTS, check_confidence


def _argument(parse: Callable[[str], Any]) -> Callable[[str], Any]:
    """`parse` as an argparse type: its ValueError becomes the flag's one-line error."""

    def parsed(text: str) -> Any:
        try:
            return parse(text)
        except ValueError as error:
            raise argparse.ArgumentTypeError(str(error)) from None

    parsed.__name__ = parse.__name__
    return parsed


@_argument
def count(text: str) -> int:
    """A positive integer (a count of updates, episodes, devices …)."""
    try:
        number = int(text)
    except ValueError:
        raise InvalidInput(f"expected a positive integer, got {text!r}") from None
    return positive_int("the value", number)


@_argument
def looks(text: str) -> int:
    """A count of a study's looks to train now, 0 (none: decide and report) or more."""
    if not (text.isascii() and text.isdigit()):
        raise InvalidInput(f"expected a count of looks, 0 or more, got {text!r}")
    return int(text)


seeds = _argument(parse_seeds)


@_argument
def part(text: str) -> tuple[int, int] | str:
    """``K/N``: the K-th of N shares of a sweep (a study's look, a tune's rung); or ``auto``: a
    SLURM job array task's share, read from SLURM's variables when the command starts
    (``cli.slurm.array_part``)."""
    if text == "auto":
        return text
    try:
        k, n = (int(x) for x in text.split("/"))
    except ValueError:
        raise InvalidInput(f"expected K/N such as 2/8, or auto, got {text!r}") from None
    return check_part((k, n), shown=text)


@_argument
def path(text: str) -> Path:
    if not text:
        raise InvalidInput("an empty path: name one ('.' for this directory)")
    return Path(text)


def _number(text: str) -> float | str:
    """`text` as a float, or as it is (which a check refuses, showing it) if it is none."""
    try:
        return float(text)
    except ValueError:
        return text


@_argument
def confidence(text: str) -> float:
    """A confidence level in (0, 1), such as 0.95."""
    return check_confidence(_number(text))


@_argument
def sizes(text: str) -> tuple[int, ...]:
    """Hidden layers' widths: ``64,64``."""
    try:
        return tuple(int(part) for part in text.split(","))
    except ValueError:
        raise InvalidInput(f"expected comma-separated widths such as 64,64, got {text!r}") from None


# The most values one start:stop:step may give: far more than a sweep trains, so more is a
# mistyped step.
MAX_RANGE = 1000


@_argument
def values(text: str) -> list[float]:
    """``1.1:1.5:0.1`` (inclusive, never past its stop) or ``0.1,0.2,0.4``; finite numbers."""
    # Decimal, so that 1.1:1.5:0.1 steps by exactly 0.1 and ends on 1.5, neither short nor past.
    try:
        parts = [Decimal(part) for part in text.split(":" if ":" in text else ",")]
    except InvalidOperation:
        raise InvalidInput(
            f"expected start:stop:step or a comma list of numbers, got {text!r}"
        ) from None
    if not all(part.is_finite() and math.isfinite(part) for part in parts):
        raise InvalidInput(f"values must be finite numbers, got {text!r}")
    if ":" not in text:
        return [float(part) for part in parts]
    if len(parts) != 3 or parts[2] <= 0 or parts[1] < parts[0]:
        raise InvalidInput(
            f"expected start:stop:step with stop >= start and step > 0, got {text!r}"
        )
    start, stop, step = parts
    if (stop - start) / step >= MAX_RANGE:
        raise InvalidInput(f"{text} gives more than {MAX_RANGE} values")
    return [float(start + i * step) for i in range(int((stop - start) // step) + 1)]


@_argument
def level(text: str) -> float:
    """An error level in (0, 1), such as 0.05."""
    return check_level(_number(text))


@_argument
def margin(text: str) -> float:
    """An equivalence margin on P(candidate > baseline), in (0, 0.5), such as 0.2."""
    return check_margin(_number(text))


@_argument
def names(text: str) -> list[str]:
    """A comma list of names: ``hopper,walker2d``."""
    listed = [name.strip() for name in text.split(",")]
    if not all(listed):
        raise InvalidInput(f"expected a comma list of names such as hopper,walker2d, got {text!r}")
    return listed


@_argument
def variant(text: str) -> Surrogate:
    """A built-in variant's name, or ``module:attribute`` naming a surrogate of one's own."""
    return resolve(text.strip())


@_argument
def variants(text: str) -> list[Surrogate]:
    """A comma list of variants: ``ppo,fppo-lp,mypackage.mymodule:mine``."""
    return [resolve(name.strip()) for name in text.split(",")]


# The flags that name variants: train's and sweep's, and study's.
VARIANT_FLAGS = ("--variant", "--candidates", "--baseline")


def surrogates_named(argv: Sequence[str]) -> list[Surrogate]:
    """The surrogates of one's own that `argv`'s variant flags (:data:`VARIANT_FLAGS`) name
    (``module:attribute``), imported, so that their hyperparameters get flags before the
    command line is parsed."""
    named = []
    for i, token in enumerate(argv):
        flag, equals, value = token.partition("=")
        if flag in VARIANT_FLAGS and equals:
            named += value.split(",")
        elif token in VARIANT_FLAGS and i + 1 < len(argv):
            named += argv[i + 1].split(",")
    return own_surrogates([name for name in named if ":" in name])  # the rest: the parser's


def own_surrogates(variants: Sequence[object]) -> list[Surrogate]:
    """The surrogates of one's own among `variants` (built-ins' names are skipped)."""
    return [
        s
        for s in (resolve(v.strip() if isinstance(v, str) else v) for v in variants)
        if not s.builtin
    ]


float_value = _argument(float)

# A field's type, as its dataclass declares it, and the argparse type of its flag.
_TYPES: dict[str, Callable[[str], Any]] = {
    "int": count,
    "int | None": count,
    "float": float_value,
    "float | None": float_value,
    "str | None": str,
    "str | Path | None": path,
    "tuple[int, ...]": sizes,
}


def _type_of(owner: type, field: dataclasses.Field[Any]) -> Callable[[str], Any]:
    if field.type not in _TYPES:
        raise TypeError(
            f"{owner.__name__}.{field.name} is a {field.type}, which has no command-line flag "
            "type: add one to fppo_jax.cli.flags._TYPES"
        )
    return _TYPES[field.type]


# Short flags, kept as aliases of the flags named after TrainConfig's fields.
ALIASES = {
    "total_steps": "--steps",
    "num_minibatches": "--minibatches",
    "num_epochs": "--epochs",
    "hidden_sizes": "--hidden",
    "normalize_observations": "--no-obs-norm",
    "normalize_rewards": "--no-reward-norm",
    "clip_value_loss": "--no-value-clip",
    "anneal_learning_rate": "--anneal-lr",
}


def add_config_flags(command: argparse.ArgumentParser) -> None:
    """A flag per :class:`TrainConfig` field, named after it, over the preset's value."""
    group = command.add_argument_group(
        "run shape", "TrainConfig's fields; each defaults to the preset's value, shown per preset"
    )
    for field in dataclasses.fields(TrainConfig):
        flag, alias = "--" + field.name.replace("_", "-"), ALIASES.get(field.name)
        text = field.metadata["help"] + _preset_values(field.name, field.default)
        if field.type == "bool":
            group.add_argument(
                flag, dest=field.name, action=argparse.BooleanOptionalAction, help=text
            )
            if alias:  # --no-obs-norm turns a default-on field off; --anneal-lr one on
                on = alias.startswith("--no-")
                same = ("--no-" + flag[2:]) if on else flag
                group.add_argument(
                    alias,
                    dest=field.name,
                    action="store_false" if on else "store_true",
                    default=None,
                    help=f"same as {same}",
                )
            continue
        flags = [flag, alias] if alias else [flag]
        group.add_argument(*flags, dest=field.name, type=_type_of(TrainConfig, field), help=text)


def config_overrides(args: argparse.Namespace) -> dict[str, Any]:
    """The preset and the run-shape flags given, as :class:`TrainConfig` fields."""
    given = {field.name: getattr(args, field.name) for field in dataclasses.fields(TrainConfig)}
    return {"preset": args.preset, **{k: v for k, v in given.items() if v is not None}}


def _preset_values(name: str, default: Any) -> str:
    """What a field is unless given, for its help: per preset where a preset sets it
    (" (paper: 8; massive: 2048)"), else its default, where it is worth reading."""
    if name == "total_steps":
        return ""  # its help names its default: the task's budget
    if name == "anneal_learning_rate":
        return " (default: on for the MuJoCo tasks under the paper preset, else off)"
    set_by = {preset: shape[name] for preset, shape in PRESETS.items() if name in shape}
    if set_by:
        return " (" + "; ".join(f"{preset}: {_shown(v)}" for preset, v in set_by.items()) + ")"
    if isinstance(default, bool):
        return f" (default: {'on' if default else 'off'})"
    return "" if default is None else f" (default: {_shown(default)})"


def _shown(value: Any) -> str:
    return ",".join(map(str, value)) if isinstance(value, tuple | list) else str(value)


def _option_flag(field: dataclasses.Field[Any]) -> str:
    return field.metadata["flag"] or "--" + field.name.replace("_", "-")


def _option_dest(field: dataclasses.Field[Any]) -> str:
    return _option_flag(field)[2:].replace("-", "_")


def add_option_flags(command: argparse.ArgumentParser, only: tuple[str, ...] | None = None) -> None:
    """A flag per :class:`Options` field that has one (or those named `only`), and ``--quiet``
    (the command line shows progress unless told not to)."""
    command.add_argument("--quiet", action="store_true", help="no progress bar or lines")
    for field in Options.flagged():
        if only is not None and field.name not in only:
            continue
        flag, text = _option_flag(field), field.metadata["help"]
        if field.type == "bool":
            command.add_argument(flag, dest=_option_dest(field), action="store_true", help=text)
            continue
        command.add_argument(
            flag,
            dest=_option_dest(field),
            type=_type_of(Options, field),
            default=field.default,
            metavar=field.metadata["metavar"],
            help=text,
        )


def options(args: argparse.Namespace) -> dict[str, Any]:
    """The flags of :func:`add_option_flags`, as ``train``'s and ``sweep``'s arguments."""
    given = {field.name: getattr(args, _option_dest(field)) for field in Options.flagged()}
    return {"progress": not args.quiet, **given}


def add_backend_flag(command: argparse.ArgumentParser, default: str | None) -> None:
    command.add_argument(
        "--backend",
        default=default,
        choices=list(BACKENDS),
        help="what runs a MuJoCo task: "
        + "; ".join(f"{name}: {text}" for name, text in BACKENDS.items())
        + ("" if default else " (default: the run's own)"),
    )


def add_policy_flag(command: argparse.ArgumentParser, first: str) -> None:
    """``--checkpoint`` and ``--policy``, one flag under two names (`first` shown first): a
    saved policy's directory or a checkpoint directory."""
    names = [first, *({"--checkpoint", "--policy"} - {first})]
    command.add_argument(
        *names,
        dest="checkpoint",
        type=path,
        required=True,
        metavar="DIR",
        help="a saved policy or a checkpoint directory",
    )


def add_render_flag(command: argparse.ArgumentParser, which: str) -> None:
    command.add_argument(
        "--render",
        type=path,
        metavar="PATH",
        help=f"MuJoCo tasks: save an episode of {which} as an .mp4, a .gif or a .png strip",
    )


def add_score_flags(command: argparse.ArgumentParser, only_for: str = "") -> None:
    """--endpoint and --ci. `only_for`: the statistics that use them, where others do not;
    then they default to None, so that the command can tell them given from left out."""
    endpoint = "each run's score: " + "; ".join(f"{k}: {v}" for k, v in ENDPOINTS.items())
    level = "the confidence intervals' level"
    if only_for:
        endpoint += f" ({only_for} only; default: final)"
        level += f" ({only_for} only; default: {CONFIDENCE})"
    command.add_argument(
        "--endpoint", default=None if only_for else "final", choices=list(ENDPOINTS), help=endpoint
    )
    command.add_argument(
        "--ci", type=confidence, default=None if only_for else CONFIDENCE, help=level
    )


def hyperparameter_help(surrogates: Sequence[Surrogate] = ()) -> dict[str, str]:
    """A flag's help per hyperparameter of the built-ins and of `surrogates`, from their
    declarations (which variants take it, its range and default), then ε and the
    optimisation settings."""
    everyone = [*BUILTINS.values(), *surrogates]
    helps = {
        name: "; ".join(
            f"{s.name}: {s.ranges.get(name, 'any')}, default {s.defaults[name]:g}"
            for s in everyone
            if name in s.defaults
        )
        for name in hyperparameter_names(everyone)
    }
    helps["epsilon"] = f"clip range, 0 < epsilon < 1 (default {EPSILON:g})"
    for name, v in HYPERPARAMETER_DEFAULTS.items():
        helps[name] = name.replace("_", " ") + f" (default {v:g})"
    return helps


def add_hyperparameter_flags(
    command: argparse.ArgumentParser,
    surrogates: Sequence[Surrogate],
    parse: Callable[[str], Any],
) -> None:
    """A flag per hyperparameter (:func:`hyperparameter_help`), each value read by `parse`;
    the names are kept as the command's ``hyperparameter_flags``."""
    helps = hyperparameter_help(surrogates)
    for name, text in helps.items():
        command.add_argument(f"--{name.replace('_', '-')}", dest=name, type=parse, help=text)
    command.set_defaults(hyperparameter_flags=tuple(helps))


def hyperparameters_given(args: argparse.Namespace) -> dict[str, Any]:
    """The hyperparameter flags given (see :func:`add_hyperparameter_flags`)."""
    given = {name: getattr(args, name) for name in args.hyperparameter_flags}
    return {name: value for name, value in given.items() if value is not None}


def add_shape_flags(command: argparse.ArgumentParser) -> None:
    """The backend, the preset and the run-shape flags over it."""
    add_backend_flag(command, "auto")
    command.add_argument(
        "--preset",
        default="paper",
        choices=list(PRESETS),
        help="run shape: paper (8 envs × 256 steps, 32 minibatches × 10 epochs) or massive "
        "(2048 envs × 16 steps, 16 minibatches × 4 epochs, for a GPU); the run-shape flags "
        "override it",
    )
    add_config_flags(command)


def add_run_flags(command: argparse.ArgumentParser) -> None:
    """The task, the preset, the run's shape and how it is driven, shared by train and sweep."""
    command.add_argument(
        "--env",
        default="cartpole",
        help="a registered task (fppo-jax list) or a namespaced id such as gymnax/Pendulum-v1",
    )
    add_shape_flags(command)
    command.add_argument(
        "--config",
        type=path,
        metavar="FILE",
        help="settings from FILE (JSON, or YAML: .yaml/.yml), a run's own config.json for one: "
        "its run again; flags given beside it override it, and an unknown key is refused",
    )
    add_option_flags(command)
    command.add_argument(
        "--distributed",
        action="store_true",
        help="join a multi-process run (jax.distributed): JAX_COORDINATOR_ADDRESS, "
        "JAX_NUM_PROCESSES and JAX_PROCESS_ID, or detected from SLURM / Open MPI",
    )


class Parser(argparse.ArgumentParser):
    """A command's parser whose errors are one line, pointing at --help, not the usage, and
    which takes no abbreviated flag: ``--vari mod:attr`` would pass the variant flags unseen
    (:func:`surrogates_named`), and its surrogate's flags with it."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **{**kwargs, "allow_abbrev": False})

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")

    def parse_known_args(  # type: ignore[override]  # argparse's overloads, one signature here
        self, args: Sequence[str] | None = None, namespace: argparse.Namespace | None = None
    ) -> tuple[argparse.Namespace, list[str]]:
        return super().parse_known_args(
            None if args is None else _dashed_values_joined(self, list(args)), namespace
        )


def _dashed_values_joined(parser: argparse.ArgumentParser, args: list[str]) -> list[str]:
    """`args` with a dash-and-digit value given to a flag that takes one (``--part -1/2``) joined
    to it (``--part=-1/2``): argparse takes such a token for a flag, all but plain negative
    numbers, and would say only "expected one argument"; joined, the flag's own check names
    the value and what it must be."""
    takes_one = {name for a in parser._actions if a.nargs is None for name in a.option_strings}
    joined: list[str] = []
    for token in args:
        if joined and joined[-1] in takes_one and token[:1] == "-" and token[1:2].isdigit():
            joined[-1] = f"{joined[-1]}={token}"
        else:
            joined.append(token)
    return joined


class Defaults(argparse.ArgumentDefaultsHelpFormatter):
    """Shows a flag's default where it has one worth reading (not None, not off)."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        if action.default in (None, False):
            return action.help or ""
        return super()._get_help_string(action)
