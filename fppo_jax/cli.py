"""The ``fppo-jax`` command line: ``train`` one policy, ``sweep`` a grid, ``eval`` (and render)
a saved or checkpointed policy, ``table``, ``compare``, ``merge`` and ``plot`` sweeps' results,
``list`` the tasks and variants."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import math
import os
import sys
import warnings
from collections.abc import Iterator, Mapping, Sequence
from decimal import Decimal, InvalidOperation
from pathlib import Path
from typing import Any, NoReturn

from fppo_jax import __version__
from fppo_jax.api import train
from fppo_jax.checkpoint import CheckpointsUnavailable, DamagedCheckpoint
from fppo_jax.config import (
    HYPERPARAMETER_DEFAULTS,
    PRESETS,
    TABLE2,
    TrainConfig,
    describe_update,
    parse_seeds,
    preset_config,
)
from fppo_jax.distributed import initialize, is_main_process
from fppo_jax.envs import BACKENDS, NAMESPACES, TASKS, make_env
from fppo_jax.extras import install_hint
from fppo_jax.files import writable_directory
from fppo_jax.objectives import DEFAULTS, EPSILON, VARIANTS
from fppo_jax.options import Options
from fppo_jax.results import SweepResult, TrainingDiverged, merge
from fppo_jax.saved_policy import (
    ARRAYS_FILE,
    POLICY_FILE,
    check_no_saved_policy,
    load_policy,
)
from fppo_jax.statistics import CONFIDENCE, ENDPOINTS, STATISTICS
from fppo_jax.sweep import sweep

# The host options' defaults, declared once, with the options.
_OPTION_DEFAULTS = {field.name: field.default for field in dataclasses.fields(Options)}


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text}")
    return value


def _seeds(text: str) -> list[int]:
    try:
        return parse_seeds(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def _part(text: str) -> tuple[int, int]:
    try:
        k, n = (int(x) for x in text.split("/"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected K/N such as 2/8, got {text!r}") from None
    if not 1 <= k <= n:
        raise argparse.ArgumentTypeError(f"expected K/N with 1 <= K <= N, got {text!r}")
    return k, n


def slurm_part(environ: Mapping[str, str] = os.environ) -> tuple[int, int] | None:
    """The part of a SLURM job array's task: (its index from 1, the array's task count)."""
    if "SLURM_ARRAY_TASK_ID" not in environ or "SLURM_ARRAY_TASK_COUNT" not in environ:
        return None
    task, first = int(environ["SLURM_ARRAY_TASK_ID"]), int(environ.get("SLURM_ARRAY_TASK_MIN", 0))
    return task - first + 1, int(environ["SLURM_ARRAY_TASK_COUNT"])


def _path(text: str) -> Path:
    if not text:
        raise argparse.ArgumentTypeError("an empty path: name one ('.' for this directory)")
    return Path(text)


def _confidence(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not 0 < value < 1:
        raise argparse.ArgumentTypeError(f"a confidence level in (0, 1) such as 0.95, got {text}")
    return value


def _sizes(text: str) -> tuple[int, ...]:
    try:
        sizes = tuple(int(part) for part in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated widths such as 64,64, got {text!r}"
        ) from None
    return sizes


# The most values one start:stop:step may give: far more than a sweep trains, so more is a
# mistyped step.
MAX_RANGE = 1000


def _values(text: str) -> list[float]:
    """``1.1:1.5:0.1`` (inclusive, never past its stop) or ``0.1,0.2,0.4``; finite numbers."""
    # Decimal, so that 1.1:1.5:0.1 steps by exactly 0.1 and ends on 1.5, neither short nor past.
    try:
        parts = [Decimal(part) for part in text.split(":" if ":" in text else ",")]
    except InvalidOperation:
        raise argparse.ArgumentTypeError(
            f"expected start:stop:step or a comma list of numbers, got {text!r}"
        ) from None
    if not all(part.is_finite() and math.isfinite(part) for part in parts):
        raise argparse.ArgumentTypeError(f"values must be finite numbers, got {text!r}")
    if ":" not in text:
        return [float(part) for part in parts]
    if len(parts) != 3 or parts[2] <= 0 or parts[1] < parts[0]:
        raise argparse.ArgumentTypeError(
            f"expected start:stop:step with stop >= start and step > 0, got {text!r}"
        )
    start, stop, step = parts
    if (stop - start) / step >= MAX_RANGE:
        raise argparse.ArgumentTypeError(f"{text} gives more than {MAX_RANGE} values")
    return [float(start + i * step) for i in range(int((stop - start) // step) + 1)]


def _names(text: str) -> list[str]:
    names = [name.strip() for name in text.split(",")]
    bad = [name for name in names if name not in VARIANTS]
    if bad:
        raise argparse.ArgumentTypeError(
            f"unknown variant {bad[0]!r}; valid variants: {', '.join(VARIANTS)}"
        )
    return names


# Today's short flags, kept as aliases of the flags named after TrainConfig's fields.
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
_PARSERS = {"int": _positive_int, "int | None": _positive_int, "tuple[int, ...]": _sizes}


def _add_config_flags(command: argparse.ArgumentParser) -> None:
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
        group.add_argument(*flags, dest=field.name, type=_PARSERS[field.type], help=text)


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


def _add_backend_flag(command: argparse.ArgumentParser, default: str | None) -> None:
    command.add_argument(
        "--backend",
        default=default,
        choices=list(BACKENDS),
        help="what runs a MuJoCo task: "
        + "; ".join(f"{name}: {text}" for name, text in BACKENDS.items())
        + ("" if default else " (default: the run's own)"),
    )


def _add_score_flags(command: argparse.ArgumentParser) -> None:
    command.add_argument(
        "--endpoint",
        default="final",
        choices=list(ENDPOINTS),
        help="each run's score: " + "; ".join(f"{k}: {v}" for k, v in ENDPOINTS.items()),
    )
    command.add_argument(
        "--ci",
        type=_confidence,
        default=CONFIDENCE,
        help="the confidence intervals' level",
    )


def _add_run_flags(command: argparse.ArgumentParser) -> None:
    """The task, the preset, the run's shape and how it is driven, shared by train and sweep."""
    command.add_argument(
        "--env",
        default="cartpole",
        help="a registered task (fppo-jax list) or a namespaced id such as gymnax/Pendulum-v1",
    )
    _add_backend_flag(command, "auto")
    command.add_argument(
        "--preset",
        default="paper",
        choices=list(PRESETS),
        help="run shape: paper (8 envs × 256 steps, 32 minibatches × 10 epochs) or massive "
        "(2048 envs × 16 steps, 16 minibatches × 4 epochs, for a GPU); the run-shape flags "
        "override it",
    )
    _add_config_flags(command)
    command.add_argument(
        "--output",
        type=_path,
        help="directory for config.json (at once), metrics.csv and TensorBoard files (as "
        "training goes) and the results",
    )
    command.add_argument("--quiet", action="store_true", help="no progress bar or lines")
    command.add_argument(
        "--config",
        type=_path,
        metavar="FILE",
        help="settings from FILE (JSON, or YAML: .yaml/.yml), a run's own config.json for one: "
        "its run again; flags given beside it override it, and an unknown key is refused",
    )
    command.add_argument(
        "--checkpoint-dir",
        type=_path,
        metavar="DIR",
        help="save the full training state in DIR every --checkpoint-every updates",
    )
    command.add_argument(
        "--resume",
        action="store_true",
        help="continue from the newest intact checkpoint in --checkpoint-dir (if there is "
        "one); with a larger --steps, a finished run goes on",
    )
    command.add_argument(
        "--checkpoint-every",
        type=_positive_int,
        metavar="N",
        help="updates between checkpoints (default: a twentieth of the run)",
    )
    command.add_argument(
        "--keep",
        type=_positive_int,
        default=_OPTION_DEFAULTS["keep"],
        help="checkpoints kept (the newest)",
    )
    command.add_argument(
        "--eval-every",
        type=_positive_int,
        metavar="N",
        help="every N updates and at the end, record eval_return: the deterministic "
        "policy's mean return over --eval-episodes episodes",
    )
    command.add_argument(
        "--eval-episodes",
        type=_positive_int,
        default=_OPTION_DEFAULTS["eval_episodes"],
        help="episodes per evaluation",
    )
    command.add_argument(
        "--wandb-project",
        metavar="NAME",
        help=f"also log to this Weights & Biases project ({install_hint('wandb')}; "
        "WANDB_MODE=offline works without an account)",
    )
    command.add_argument(
        "--devices",
        type=_positive_int,
        metavar="N",
        help="devices to train on (default: all that JAX sees, every process's in a "
        "multi-process run)",
    )
    command.add_argument(
        "--distributed",
        action="store_true",
        help="join a multi-process run (jax.distributed): JAX_COORDINATOR_ADDRESS, "
        "JAX_NUM_PROCESSES and JAX_PROCESS_ID, or detected from SLURM / Open MPI",
    )


def _driver_options(args: argparse.Namespace) -> dict:
    """The flags of how a run is driven, as train's and sweep's arguments."""
    return {
        "progress": not args.quiet,
        "log_dir": args.output,
        "checkpoint_dir": args.checkpoint_dir,
        "resume": args.resume,
        "checkpoint_every": args.checkpoint_every,
        "keep": args.keep,
        "eval_every": args.eval_every,
        "eval_episodes": args.eval_episodes,
        "wandb_project": args.wandb_project,
        "devices": args.devices,
    }


def _config_overrides(args: argparse.Namespace) -> dict:
    """The preset and the run-shape flags given, as :class:`TrainConfig` fields."""
    given = {field.name: getattr(args, field.name) for field in dataclasses.fields(TrainConfig)}
    return {"preset": args.preset, **{k: v for k, v in given.items() if v is not None}}


HYPERPARAMETER_HELP = {
    "alpha": "FPPO-LP pulling factor (>= 1), or the RB variants' rollback coefficient (>= 0)",
    "k": "FPPO-QP quadratic coefficient (>= 0)",
    "delta": "TR variants' KL bound (> 0)",
    "epsilon": f"clip range, 0 < epsilon < 1 (default {EPSILON:g})",
    **{
        name: name.replace("_", " ") + f" (default {v:g})"
        for name, v in HYPERPARAMETER_DEFAULTS.items()
    },
}


class _Parser(argparse.ArgumentParser):
    """A command's parser whose errors are one line, pointing at --help, not the usage."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


class _Defaults(argparse.ArgumentDefaultsHelpFormatter):
    """Shows a flag's default where it has one worth reading (not None, not off)."""

    def _get_help_string(self, action: argparse.Action) -> str:
        if action.default in (None, False):
            return action.help or ""
        return super()._get_help_string(action)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="fppo-jax",
        description="Train PPO and its fast variants (FPPO-LP, FPPO-QP, TR-PPO, PPO-RB, TR-PPO-RB) "
        "with a fully jitted JAX trainer.",
    )
    parser.add_argument("--version", action="version", version=f"fppo-jax {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    parser.set_defaults(commands=commands.choices)
    formatter = _Defaults

    run = commands.add_parser(
        "train",
        help="train one policy",
        description="Train one policy and print progress and a summary. FPPO-LP's alpha and "
        "FPPO-QP's k default to the paper's Table 2 for the task; other variants' "
        "hyperparameters to the paper's values. --output DIR gets config.json at once, "
        "metrics.csv and TensorBoard event files (tensorboard/) as training goes, then "
        "summary.txt. "
        "--checkpoint-dir DIR saves the full state as it goes; run the same command with "
        "--resume to continue a stopped run exactly where its last checkpoint left it.",
        formatter_class=formatter,
    )
    run.add_argument("--variant", default="fppo-lp", choices=list(VARIANTS), help="surrogate")
    for name, text in HYPERPARAMETER_HELP.items():
        run.add_argument(f"--{name.replace('_', '-')}", type=float, help=text)
    run.add_argument("--seed", type=int, default=0, help="random seed")
    run.add_argument(
        "--render",
        type=_path,
        metavar="PATH",
        help="MuJoCo tasks: save an episode of the trained policy as an .mp4, a .gif or a "
        ".png strip",
    )
    run.add_argument(
        "--save-policy",
        type=_path,
        metavar="DIR",
        help="save the trained policy and the run's configuration in DIR, for fppo-jax eval "
        "and fppo_jax.load_policy",
    )
    _add_run_flags(run)

    grid = commands.add_parser(
        "sweep",
        help="train a grid of settings × seeds as one compiled program",
        description="Train every combination of the given values, times the seeds, as one "
        "vmapped program. Values are start:stop:step (inclusive) or comma lists; alpha, k and "
        "delta apply to the variants that take them. --output DIR writes curves.csv and "
        "sweep.json, which `fppo-jax table` and `fppo-jax plot` read.",
        formatter_class=formatter,
    )
    grid.add_argument(
        "--variant", type=_names, default="fppo-lp", help="variants, e.g. ppo,fppo-lp,fppo-qp"
    )
    for name, text in HYPERPARAMETER_HELP.items():
        grid.add_argument(f"--{name.replace('_', '-')}", type=_values, help=text)
    grid.add_argument(
        "--seeds",
        type=_seeds,
        default="5",  # parsed by _seeds, shown as typed
        help="per setting: N (seeds 0 … N−1), a range 10:20 (seeds 10 … 19) or a list 0,3,7",
    )
    grid.add_argument(
        "--chunk", type=_positive_int, help="runs per compiled call (default: what fits in memory)"
    )
    grid.add_argument(
        "--part",
        type=_part,
        metavar="K/N",
        help="train only the K-th of N equal shares of the sweep's runs (its run order), e.g. "
        "one node's share; fppo-jax merge joins the parts. Under a SLURM job array, without "
        "--part: the array task's share (SLURM_ARRAY_TASK_ID of SLURM_ARRAY_TASK_COUNT)",
    )
    grid.add_argument(
        "--data-parallel",
        type=_positive_int,
        metavar="N",
        help="devices each run's environments are split over (default 1: the devices share "
        "the runs)",
    )
    _add_run_flags(grid)

    table = commands.add_parser(
        "table",
        help="print a sweep's summary per setting (Markdown)",
        description="One row per setting. --stat paper (the default) is Table 1's: the max "
        "average return (the maximum over updates of the seed-mean curve, ± the sample std "
        "there), which is biased upward; iqm, mean or median give that statistic of each run's "
        "--endpoint score with a percentile bootstrap confidence interval, and the sample std.",
        formatter_class=formatter,
    )
    table.add_argument("directory", type=_path, help="a sweep's --output directory")
    table.add_argument(
        "--stat",
        default="paper",
        choices=["paper", *STATISTICS],
        help="paper: Table 1's max average return; or that statistic of each run's score, "
        "with its bootstrap CI",
    )
    _add_score_flags(table)
    compare = commands.add_parser(
        "compare",
        help="each setting of a sweep against a baseline: probability of improvement, with CIs",
        description="For every setting but the baseline: the probability that one of its runs "
        "scores above one of the baseline's (P(X > Y) + ½ P(X = Y)) and the difference in IQM, "
        "each with a percentile bootstrap confidence interval over both settings' runs.",
        formatter_class=formatter,
    )
    compare.add_argument("directory", type=_path, help="a sweep's --output directory")
    compare.add_argument("--baseline", default="ppo", help="a setting's label or a variant")
    _add_score_flags(compare)
    merged = commands.add_parser(
        "merge",
        help="join sweeps of other seeds (parts of one sweep) into one sweep's output",
        description="Join the runs of sweeps that differ only in their seeds (or settings of the "
        "same grid) into one curves.csv and sweep.json, which table, compare and plot read. "
        "Parts of different tasks or protocols, and a run two parts both hold, are refused.",
        formatter_class=formatter,
    )
    merged.add_argument("directories", type=_path, nargs="+", help="sweeps' --output directories")
    merged.add_argument("--output", type=_path, required=True, help="where the merged sweep goes")
    plot = commands.add_parser(
        "plot", help="write a sweep's learning curves (and α/k chart) as PNG"
    )
    plot.add_argument("directory", type=_path, help="a sweep's --output directory")

    evaluation = commands.add_parser(
        "eval",
        help="report a trained policy's return, or render it",
        description="Run the policy saved in DIR (of `fppo-jax train --save-policy DIR`), or "
        "that of the newest checkpoint in DIR (of `--checkpoint-dir DIR`), for whole episodes "
        "on its task, with its most likely actions (deterministic) and with sampled ones "
        "(stochastic), and report the returns. --render PATH also saves an episode of the "
        "deterministic policy on a MuJoCo task (.mp4, .gif or .png strip).",
        formatter_class=formatter,
    )
    evaluation.add_argument(
        "--checkpoint",
        "--policy",
        dest="checkpoint",
        type=_path,
        required=True,
        metavar="DIR",
        help="a checkpoint directory or a saved policy",
    )
    evaluation.add_argument(
        "--episodes",
        type=_positive_int,
        default=_OPTION_DEFAULTS["eval_episodes"],
        help="episodes each",
    )
    _add_backend_flag(evaluation, None)
    evaluation.add_argument("--seed", type=int, default=0, help="random seed of the episodes")
    evaluation.add_argument(
        "--render",
        type=_path,
        metavar="PATH",
        help="MuJoCo tasks: save an episode of the deterministic policy as an .mp4, a .gif or "
        "a .png strip",
    )

    export = commands.add_parser(
        "export",
        help="write a trained policy as an ONNX model",
        description="Write the deterministic policy saved in DIR (or that of the newest "
        "checkpoint in DIR) as an ONNX model: input `observation` [batch, size] float32, output "
        f"`action` (see fppo_jax.onnx_export). Needs the onnx extra: {install_hint('onnx')}.",
        formatter_class=formatter,
    )
    export.add_argument(
        "--policy",
        "--checkpoint",
        dest="checkpoint",
        type=_path,
        required=True,
        metavar="DIR",
        help="a saved policy or a checkpoint directory",
    )
    export.add_argument(
        "--onnx", type=_path, required=True, metavar="FILE", help="the model file to write"
    )

    commands.add_parser("list", help="list the tasks and the variants")
    return parser


def _train(args: argparse.Namespace) -> int:
    if args.render:  # refused now rather than after training
        from fppo_jax.render import check_render_path, check_renderable

        check_render_path(args.render)
        check_renderable(args.env)
    if args.save_policy:  # refused now rather than after training
        check_no_saved_policy(
            args.save_policy, replace=f"remove its {POLICY_FILE} and {ARRAYS_FILE}"
        )
        writable_directory(args.save_policy)
    optimisation = {
        name: getattr(args, name)
        for name in HYPERPARAMETER_DEFAULTS
        if getattr(args, name) is not None
    }
    result = train(
        args.env,
        args.variant,
        args.alpha,
        k=args.k,
        delta=args.delta,
        epsilon=EPSILON if args.epsilon is None else args.epsilon,
        seed=args.seed,
        backend=args.backend,
        **_driver_options(args),
        **_config_overrides(args),
        **optimisation,
    )
    if not is_main_process():
        return 0
    print(result.summary())
    if args.output:  # written by train
        print(f"wrote {args.output}/config.json, metrics.csv, tensorboard/, summary.txt")
    if args.save_policy:
        print(f"wrote {result.save(args.save_policy)}/policy.json, policy.npz")
    if args.render:
        from fppo_jax.render import RenderingUnavailable

        try:
            print(f"wrote {result.render(args.render)}")
        except (RenderingUnavailable, TypeError) as error:
            print(f"fppo-jax: not rendered: {error}", file=sys.stderr)
            return 2
    return 0


def _sweep(args: argparse.Namespace) -> int:
    grid = {"variant": args.variant}
    grid.update({name: getattr(args, name) for name in HYPERPARAMETER_HELP if getattr(args, name)})
    part = args.part or slurm_part()
    result = sweep(
        args.env,
        grid,
        seeds=args.seeds,
        part=part,
        chunk=args.chunk,
        data_parallel=args.data_parallel,
        backend=args.backend,
        **_driver_options(args),
        **_config_overrides(args),
    )
    if not is_main_process():
        return 0
    runs = len(result.runs)
    share = "" if part is None else f" (part {part[0]} of {part[1]})"
    print(
        f"{runs} runs{share} on {result.config['env']} in {result.train_seconds:.1f} s "
        f"(+{result.compile_seconds:.1f} s compiling), {result.config['runs_per_call']} per call"
    )
    print(result.table())
    if args.output:  # written by the sweep as each group of runs finished
        print(f"wrote {args.output}/curves.csv, sweep.json")
    return 0


def _eval(args: argparse.Namespace) -> int:
    from fppo_jax.evaluation import evaluate
    from fppo_jax.saved_policy import read_policy

    if args.render:
        from fppo_jax.render import check_render_path

        check_render_path(args.render)
    policy, record = read_policy(args.checkpoint)
    config = record["config"]
    if config["env"] not in TASKS:
        raise ValueError(
            f"the policy's environment {config['env']!r} is not a registered task; load the "
            "policy with fppo_jax.load_policy and evaluate it on your environment"
        )
    if args.render:
        from fppo_jax.render import check_renderable

        check_renderable(config["env"])
    env = make_env(config["env"], args.backend or config.get("backend", "auto"))
    steps = record["update"] * config["num_envs"] * config["num_steps"]
    source = "saved policy" if record["kind"] == "policy" else "checkpoint"
    print(
        f"{config['variant']} on {config['env']}, seed {config['seed']}: {source} at update "
        f"{record['update']} ({steps:,} env steps); {args.episodes} episodes each"
    )
    for name, deterministic in (("deterministic", True), ("stochastic", False)):
        returns = evaluate(env, policy, args.episodes, seed=args.seed, deterministic=deterministic)
        print(
            f"  {name:<13} return {returns.mean():.1f} ± {returns.std():.1f} "
            f"(min {returns.min():.1f}, max {returns.max():.1f})"
        )
    if args.render:
        from fppo_jax.render import RenderingUnavailable, drawable, render_policy

        try:
            path = render_policy(drawable(env, config["env"]), policy, args.render, seed=args.seed)
            print(f"wrote {path}")
        except RenderingUnavailable as error:
            print(f"fppo-jax: not rendered: {error}", file=sys.stderr)
            return 2
    return 0


def _table(args: argparse.Namespace) -> int:
    result = SweepResult.read(args.directory)
    print(result.table(args.stat, args.endpoint, args.ci))
    return 0


def _compare(args: argparse.Namespace) -> int:
    result = SweepResult.read(args.directory)
    print(result.compare(args.baseline, args.endpoint, args.ci))
    return 0


def _merge(args: argparse.Namespace) -> int:
    if (args.output / "sweep.json").exists():
        raise ValueError(f"{args.output} already holds a sweep; merge into a new directory")
    result = merge([SweepResult.read(directory) for directory in args.directories])
    result.write(args.output, metrics=list(result.metrics))
    settings, seeds = len(result.settings), len(result.seeds)
    print(
        f"merged {len(args.directories)} sweeps: {len(result.runs)} runs ({settings} settings, "
        f"{seeds} seeds) in {args.output}/curves.csv, sweep.json"
    )
    return 0


def _plot(args: argparse.Namespace) -> int:
    from fppo_jax.plots import plot_sweep

    for path in plot_sweep(SweepResult.read(args.directory), args.directory):
        print(f"wrote {path}")
    return 0


def _list() -> int:
    print("tasks:")
    for task in TASKS.values():
        print(
            f"  {task.name:<12} {task.description}; {task.total_steps:,} steps, "
            f"fppo-lp alpha {TABLE2[task.name]['alpha']}, fppo-qp k {TABLE2[task.name]['k']}; "
            f"backends: {', '.join(task.backends)}" + (f" ({task.native})" if task.native else "")
        )
    print("namespaces (any id the library has, e.g. --env gymnax/Pendulum-v1):")
    for name, text in NAMESPACES.items():
        print(f"  {name + '/':<12} {text}")
    print("backends (--backend):")
    for name, text in BACKENDS.items():
        print(f"  {name:<10} {text}")
    print("presets:")
    for name in PRESETS:
        config = preset_config(name, total_steps=10**9)
        print(f"  {name:<10} {describe_update(config)} per update")
    print("variants:")
    for name in VARIANTS:
        params = ", ".join(f"{k} {v}" for k, v in DEFAULTS[name].items()) or "-"
        print(f"  {name:<10} defaults: epsilon {EPSILON}; {params}")
    return 0


@contextlib.contextmanager
def _warnings_as_lines() -> Iterator[None]:
    """A damaged checkpoint reported in a line of the command's own, as its errors are; any
    other warning as before."""
    with warnings.catch_warnings():
        show = warnings.showwarning

        def shown(message: Warning | str, category: type[Warning], *rest: Any) -> None:
            if issubclass(category, DamagedCheckpoint):
                print(f"fppo-jax: warning: {message}", file=sys.stderr)
            else:
                show(message, category, *rest)

        warnings.showwarning = shown
        yield


def _export(args: argparse.Namespace) -> int:
    from fppo_jax.onnx_export import export_onnx

    if os.path.lexists(args.onnx):
        raise ValueError(f"{args.onnx} already exists; remove it or choose another path")
    writable_directory(Path(args.onnx).parent)
    print(f"wrote {export_onnx(load_policy(args.checkpoint), args.onnx)}")
    return 0


# What a run's config.json records beside its settings (metric_log.environment_record).
RECORD_ONLY = ("versions", "platform")


def settings_file(path: Path, command: argparse.ArgumentParser) -> dict[str, Any]:
    """The settings in `path` (JSON or YAML) as defaults of `command`'s flags: a run's own
    ``config.json`` (train) or a sweep's (sweep, its grid as the grid's flags), or a file of
    flag names written by hand. Raises ValueError naming any key that is not a setting."""
    text = Path(path).read_text()
    try:
        if Path(path).suffix in (".yaml", ".yml"):
            import yaml

            settings = yaml.safe_load(text)
        else:
            settings = json.loads(text)
    except ImportError:
        raise ValueError(f"{path}: reading YAML needs PyYAML (pip install pyyaml)") from None
    except Exception as error:
        raise ValueError(f"{path} cannot be read as settings: {error}") from None
    if not isinstance(settings, dict):
        raise ValueError(f"{path} must hold a mapping of settings, got {type(settings).__name__}")
    settings = {k: v for k, v in settings.items() if k not in RECORD_ONLY}
    if isinstance(settings.get("devices"), list):  # the record's device kinds, not a count
        del settings["devices"]
    settings.update(settings.pop("grid", None) or {})
    if "runs_per_call" in settings:
        settings["chunk"] = settings.pop("runs_per_call")
    if isinstance(settings.get("part"), list):
        settings["part"] = tuple(settings["part"])
    valid = set(vars(command.parse_args([]))) - {"commands", "command", "config"}
    unknown = sorted(set(settings) - valid)
    if unknown:
        raise ValueError(
            f"{path}: unknown setting{'s' if len(unknown) > 1 else ''} {', '.join(unknown)}; "
            f"valid: {', '.join(sorted(valid))}"
        )
    return settings


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "config", None) is not None:
        command = args.commands[args.command]
        try:
            command.set_defaults(**settings_file(args.config, command))
        except (ValueError, FileNotFoundError) as error:
            print(f"fppo-jax: error: {error}", file=sys.stderr)
            return 2
        args = parser.parse_args(argv)
    if getattr(args, "distributed", False):
        initialize()
    commands = {
        "train": _train,
        "sweep": _sweep,
        "table": _table,
        "compare": _compare,
        "merge": _merge,
        "plot": _plot,
        "eval": _eval,
        "export": _export,
        "list": lambda a: _list(),
    }
    with _warnings_as_lines():
        try:
            return commands[args.command](args)
        except (
            ValueError,
            FileNotFoundError,
            ImportError,
            MemoryError,
            TrainingDiverged,
            CheckpointsUnavailable,
        ) as error:
            print(f"fppo-jax: error: {error}", file=sys.stderr)
            return 2


if __name__ == "__main__":
    sys.exit(main())
