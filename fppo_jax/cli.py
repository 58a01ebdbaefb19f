"""The ``fppo-jax`` command line: ``train`` one policy, ``list`` the tasks and variants."""

from __future__ import annotations

import argparse
import csv
import json
import sys
from collections.abc import Sequence
from pathlib import Path

from fppo_jax.api import TrainingDiverged, TrainResult, train
from fppo_jax.config import HYPERPARAMETER_DEFAULTS, TrainConfig
from fppo_jax.envs import TASKS
from fppo_jax.objectives import DEFAULTS, VARIANTS


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text}")
    return value


def _sizes(text: str) -> tuple[int, ...]:
    try:
        sizes = tuple(int(part) for part in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected comma-separated widths such as 64,64, got {text!r}"
        ) from None
    return sizes


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="fppo-jax",
        description="Train PPO and its fast variants (FPPO-LP, FPPO-QP, TR-PPO, PPO-RB, TR-PPO-RB) "
        "with a fully jitted JAX trainer.",
    )
    commands = parser.add_subparsers(dest="command", required=True)

    run = commands.add_parser(
        "train",
        help="train one policy",
        description="Train one policy and print progress and a summary. FPPO-LP's alpha and "
        "FPPO-QP's k default to the paper's Table 2 for the task; other variants' "
        "hyperparameters to the paper's values.",
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    run.add_argument("--env", default="cartpole", choices=list(TASKS), help="task")
    run.add_argument(
        "--variant", default="fppo-lp", choices=list(VARIANTS), help="surrogate objective"
    )
    run.add_argument(
        "--alpha",
        type=float,
        help="FPPO-LP pulling factor (>= 1), or the RB variants' rollback coefficient (>= 0)",
    )
    run.add_argument("--k", type=float, help="FPPO-QP quadratic coefficient (>= 0)")
    run.add_argument("--delta", type=float, help="TR variants' KL bound (> 0)")
    run.add_argument("--epsilon", type=float, default=0.2, help="clip range, 0 < epsilon < 1")
    run.add_argument(
        "--steps",
        type=_positive_int,
        help="total env steps (default: the task's budget in the paper)",
    )
    run.add_argument("--seed", type=int, default=0, help="random seed")
    defaults = TrainConfig()
    run.add_argument(
        "--num-envs", type=_positive_int, default=defaults.num_envs, help="parallel environments"
    )
    run.add_argument(
        "--num-steps",
        type=_positive_int,
        default=defaults.num_steps,
        help="steps per environment per update",
    )
    run.add_argument(
        "--minibatches",
        type=_positive_int,
        default=defaults.num_minibatches,
        help="minibatches per epoch",
    )
    run.add_argument(
        "--epochs", type=_positive_int, default=defaults.num_epochs, help="epochs per update"
    )
    run.add_argument(
        "--hidden",
        type=_sizes,
        default=defaults.hidden_sizes,
        help="hidden layer widths, e.g. 64,64",
    )
    for name, default in HYPERPARAMETER_DEFAULTS.items():
        run.add_argument(
            f"--{name.replace('_', '-')}", type=float, default=default, help=name.replace("_", " ")
        )
    run.add_argument("--no-obs-norm", action="store_true", help="do not normalise observations")
    run.add_argument("--no-reward-norm", action="store_true", help="do not scale rewards")
    run.add_argument("--no-value-clip", action="store_true", help="do not clip the value loss")
    run.add_argument(
        "--anneal-lr", action="store_true", help="decay the learning rate linearly to 0"
    )
    run.add_argument(
        "--output", type=Path, help="directory for metrics.csv, config.json and summary.txt"
    )
    run.add_argument("--quiet", action="store_true", help="no progress lines (one compiled call)")

    commands.add_parser("list", help="list the tasks and the variants")
    return parser


def write_run(result: TrainResult, directory: Path) -> None:
    """metrics.csv (one row per update), config.json and summary.txt in `directory`."""
    directory.mkdir(parents=True, exist_ok=True)
    names = list(result.metrics)
    with open(directory / "metrics.csv", "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(names)
        for row in zip(*(result.metrics[name].tolist() for name in names), strict=True):
            writer.writerow(row)
    config = {
        **result.config,
        "compile_seconds": result.compile_seconds,
        "train_seconds": result.train_seconds,
    }
    (directory / "config.json").write_text(json.dumps(config, indent=2) + "\n")
    (directory / "summary.txt").write_text(result.summary() + "\n")


def _train(args: argparse.Namespace) -> int:
    overrides = {name: getattr(args, name) for name in HYPERPARAMETER_DEFAULTS}
    result = train(
        args.env,
        args.variant,
        args.alpha,
        k=args.k,
        delta=args.delta,
        epsilon=args.epsilon,
        seed=args.seed,
        total_steps=args.steps,
        progress=not args.quiet,
        num_envs=args.num_envs,
        num_steps=args.num_steps,
        num_minibatches=args.minibatches,
        num_epochs=args.epochs,
        hidden_sizes=args.hidden,
        normalize_observations=not args.no_obs_norm,
        normalize_rewards=not args.no_reward_norm,
        clip_value_loss=not args.no_value_clip,
        anneal_learning_rate=args.anneal_lr,
        **overrides,
    )
    print(result.summary())
    if args.output:
        write_run(result, args.output)
        print(f"wrote {args.output}/metrics.csv, config.json, summary.txt")
    return 0


def _list() -> int:
    print("tasks:")
    for task in TASKS.values():
        print(
            f"  {task.name:<12} {task.description}; {task.total_steps:,} steps, "
            f"fppo-lp alpha {task.fppo_lp_alpha}, fppo-qp k {task.fppo_qp_k}"
        )
    print("variants:")
    for name in VARIANTS:
        params = ", ".join(f"{k} {v}" for k, v in DEFAULTS[name].items()) or "-"
        print(f"  {name:<10} defaults: epsilon 0.2; {params}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return _train(args) if args.command == "train" else _list()
    except (ValueError, TrainingDiverged) as error:
        print(f"fppo-jax: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
