"""The ``fppo-jax`` command line's parser: its commands and their flags."""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from fppo_jax import __version__
from fppo_jax.cli.flags import (
    Defaults,
    Parser,
    add_backend_flag,
    add_hyperparameter_flags,
    add_option_flags,
    add_policy_flag,
    add_render_flag,
    add_run_flags,
    add_score_flags,
    add_shape_flags,
    count,
    float_value,
    level,
    looks,
    margin,
    names,
    part,
    path,
    seeds,
    values,
    variant,
    variants,
)
from fppo_jax.cli.tune_parser import add_search_flags, add_tune
from fppo_jax.core.surrogates import Surrogate
from fppo_jax.core.variants import DEFAULT_VARIANT, VARIANTS
from fppo_jax.errors import install_hint
from fppo_jax.run.options import Options
from fppo_jax.stats.statistics import ENDPOINTS, STATISTICS, STUDY_ENDPOINTS


def build_parser(surrogates: Sequence[Surrogate] = ()) -> argparse.ArgumentParser:
    """The command line, with flags for the hyperparameters of the built-ins and of
    `surrogates` (one's own, named by ``--variant module:attribute``)."""
    parser = argparse.ArgumentParser(
        prog="fppo-jax",
        description=f"Train PPO and its variants ({', '.join(v for v in VARIANTS if v != 'ppo')}"
        ") with a fully jitted JAX trainer, and compare them.",
        epilog="Compiled programs are cached in ~/.cache/fppo-jax (under $XDG_CACHE_HOME if "
        "set): FPPO_JAX_CACHE_DIR=DIR moves the cache, FPPO_JAX_CACHE_DIR=off turns it off.",
        allow_abbrev=False,
    )
    parser.add_argument("--version", action="version", version=f"fppo-jax {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, parser_class=Parser)
    parser.set_defaults(commands=commands.choices)
    _add_train(commands, surrogates)
    _add_sweep(commands, surrogates)
    _add_study(commands, surrogates)
    add_tune(commands)
    _add_reading(commands)
    _add_policy_commands(commands)

    commands.add_parser("list", help="list the tasks and the variants")
    return parser


def command_line_names() -> set[str]:
    """Every name the command line gives a value: its commands' flags (``--num-envs`` as
    num_envs), their destinations and the other defaults (what ``--config FILE`` may set)."""
    parser = build_parser()
    names: set[str] = set()
    for command in (parser, *parser.get_default("commands").values()):
        names.update(command._defaults)
        for action in command._actions:
            names.add(action.dest)
            names.update(flag.lstrip("-").replace("-", "_") for flag in action.option_strings)
    return names


def _add_train(
    commands: argparse._SubParsersAction[Parser], surrogates: Sequence[Surrogate]
) -> None:
    """``train``: one policy."""
    formatter = Defaults
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
    run.add_argument(
        "--variant",
        type=variant,
        default=DEFAULT_VARIANT,
        help=f"the surrogate: {', '.join(VARIANTS)}, or module:attribute for one's own "
        "(fppo_jax.surrogate)",
    )
    add_hyperparameter_flags(run, surrogates, float_value)
    run.add_argument("--seed", type=int, default=0, help="random seed")
    add_render_flag(run, "the trained policy")
    run.add_argument(
        "--save-policy",
        type=path,
        metavar="DIR",
        help="save the trained policy and the run's configuration in DIR, for fppo-jax eval "
        "and fppo_jax.load_policy",
    )
    add_run_flags(run)


def _add_sweep(
    commands: argparse._SubParsersAction[Parser], surrogates: Sequence[Surrogate]
) -> None:
    """``sweep``: a grid of settings × seeds as one program."""
    formatter = Defaults
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
        "--variant",
        type=variants,
        default=DEFAULT_VARIANT,
        help="variants, e.g. ppo,fppo-lp,fppo-qp, or module:attribute for a surrogate of one's own",
    )
    add_hyperparameter_flags(grid, surrogates, values)
    grid.add_argument(
        "--seeds",
        type=seeds,
        default="5",  # parsed by the seeds type, shown as typed
        help="per setting: N (seeds 0 … N−1), a range 10:20 (seeds 10 … 19) or a list 0,3,7",
    )
    grid.add_argument(
        "--chunk",
        type=count,
        help="runs per compiled call, the sweep's group size, the same for every part "
        "(default: as many of the whole sweep's runs as fit in memory)",
    )
    grid.add_argument(
        "--part",
        type=part,
        metavar="K/N",
        help="train only the K-th of N shares of the sweep's groups of --chunk runs (its run "
        "order), e.g. one node's share; fppo-jax merge joins the parts into the sweep run "
        "unsplit with that --chunk, bit for bit (give --chunk when the runs fit in one group). "
        "auto: a SLURM job array task's share, the array being the split (K = "
        "(SLURM_ARRAY_TASK_ID - SLURM_ARRAY_TASK_MIN) / SLURM_ARRAY_TASK_STEP + 1, N = "
        "SLURM_ARRAY_TASK_COUNT); without --part, no split",
    )
    grid.add_argument(
        "--data-parallel",
        type=count,
        metavar="N",
        help="devices each run's environments are split over (default 1: the devices share "
        "the runs)",
    )
    add_run_flags(grid)


def _add_study(
    commands: argparse._SubParsersAction[Parser], surrogates: Sequence[Surrogate]
) -> None:
    """``study``: candidates against a baseline, seeds added until decided."""
    formatter = Defaults
    studied = commands.add_parser(
        "study",
        help="candidates against a baseline, adding seeds until a preregistered test decides",
        description="Compare each candidate with the baseline on each task. Before any run, "
        "--output gets plan.json (the comparisons, endpoints, test, error level, seed schedule "
        "and commit); then seeds are trained in groups (one sweep per task and group) until a "
        "group-sequential Mann-Whitney test (O'Brien-Fleming-type alpha-spending, Holm across "
        "comparisons) decides each comparison better or worse (or, with --margin, "
        "equivalent), or --max-seeds is reached. A "
        "decided comparison stops training; the baseline trains while a candidate on its task "
        "is undecided. decisions.json and report.md say what was decided, with how many seeds "
        "and why. The same command again goes on where the study stopped; a changed plan is "
        "refused.",
        formatter_class=formatter,
    )
    studied.add_argument(
        "--candidates",
        type=variants,
        required=True,
        help="variants, e.g. spo,dpo, or module:attribute for a surrogate of one's own",
    )
    studied.add_argument(
        "--baseline",
        type=variant,
        default="ppo",
        help="the variant each candidate is tested against",
    )
    studied.add_argument(
        "--tasks", type=names, required=True, help="tasks, e.g. hopper,walker2d (fppo-jax list)"
    )
    add_hyperparameter_flags(studied, surrogates, float_value)
    add_shape_flags(studied)
    _add_study_design(studied)
    _add_study_running(studied)


def _add_study_design(studied: Parser) -> None:
    """The study's test: its seed schedule, error level and endpoint, as the plan records them."""
    studied.add_argument("--max-seeds", type=count, default=30, help="seeds per setting at most")
    studied.add_argument(
        "--group-size", type=count, default=5, help="seeds per setting added at each look"
    )
    studied.add_argument(
        "--level",
        type=level,
        default=0.05,
        help="the chance of any wrong decision in the family when candidates and baseline "
        "score alike, at most",
    )
    studied.add_argument(
        "--margin",
        type=margin,
        metavar="M",
        help="decide a comparison equivalent when P(candidate > baseline) is shown within "
        "1/2 ± M (its repeated confidence interval inside that range; the chance of a false "
        "equivalent in the family at most --level); default: no margin, no equivalent decision",
    )
    studied.add_argument(
        "--endpoint",
        default="final",
        choices=STUDY_ENDPOINTS,
        help="the score decided on (the others, and max, are reported; eval needs "
        "--eval-every): " + "; ".join(f"{name}: {ENDPOINTS[name]}" for name in STUDY_ENDPOINTS),
    )


def _add_study_running(studied: Parser) -> None:
    """The study's flags for where and how far it runs: its directory, its looks, the runs it
    reuses, an array task's part."""
    studied.add_argument(
        "--groups",
        type=looks,
        metavar="N",
        help="train at most N more looks now, then stop (the same command goes on later); "
        "0 trains none: it decides on what is recorded, and reports",
    )
    studied.add_argument(
        "--output", type=path, required=True, metavar="DIR", help="the study's directory"
    )
    studied.add_argument(
        "--reuse",
        type=path,
        nargs="+",
        metavar="DIR",
        help="recorded sweeps under DIR whose runs (same task, protocol and setting, at a "
        "group's seeds) are taken instead of trained; decisions.json names each",
    )
    studied.add_argument(
        "--part",
        type=part,
        metavar="K/N",
        help="train only the K-th of N shares of the next look's groups and stop, deciding "
        "nothing (auto: a SLURM job array task's share; each share is whole groups of --chunk "
        "runs); the same command without --part, once every share is recorded, joins them and "
        "decides",
    )
    studied.add_argument(
        "--chunk",
        type=count,
        help="runs per compiled call, the same for every share (default: as many of a look's "
        "runs as fit in memory)",
    )
    studied.add_argument(
        "--tuned",
        type=path,
        metavar="DIR",
        help="train each arm at the setting that the tune in DIR (fppo-jax tune) chose for it "
        "on each task; the plan records the tune's digest, and the tune's seeds are refused",
    )
    studied.add_argument(
        "--with-defaults",
        action="store_true",
        help="with --tuned: also train each arm's default setting (the tune's trial 0) on the "
        "same seeds at the same looks (or take its recorded runs with --reuse); the report "
        "gives each arm's gain from tuning and the defaults compared, untested, beside the "
        "decisions, which stay the tuned ones",
    )
    studied.add_argument(
        "--across-tasks",
        action="store_true",
        help="with --tuned: one trial per arm for every task, the best mean over the tune's "
        "tasks of its scores normalised per task at the deepest rung its trials reached on "
        "all of them, instead of each task's best (docs/tuning.md)",
    )
    tuning = studied.add_argument_group(
        "tuning first (--tune)",
        "--tune tunes every arm in --output/tune with the same budget, scoring on the study's "
        "endpoint, then studies the settings its validation race chose: the flags of "
        "fppo-jax tune",
    )
    tuning.add_argument(
        "--tune", action="store_true", help="tune every arm first (instead of --tuned DIR)"
    )
    add_search_flags(tuning)
    add_option_flags(studied, only=("eval_every", "eval_episodes"))


def _add_reading(commands: argparse._SubParsersAction[Parser]) -> None:
    """``table``, ``compare``, ``merge`` and ``plot``: what reads a sweep's output."""
    formatter = Defaults
    table = commands.add_parser(
        "table",
        help="print a sweep's summary per setting (Markdown)",
        description="One row per setting. --stat paper (the default) is Table 1's: the max "
        "average return (the maximum over updates of the seed-mean curve, ± the sample std "
        "there), which is biased upward; iqm, mean or median give that statistic of each run's "
        "--endpoint score with a percentile bootstrap confidence interval, and the sample std.",
        formatter_class=formatter,
    )
    table.add_argument("directory", type=path, help="a sweep's --output directory")
    table.add_argument(
        "--stat",
        default="paper",
        choices=["paper", *STATISTICS],
        help="paper: Table 1's max average return; or that statistic of each run's score, "
        "with its bootstrap CI",
    )
    add_score_flags(table, only_for="--stat " + ", ".join(STATISTICS))
    compare = commands.add_parser(
        "compare",
        help="each setting of a sweep against a baseline: probability of improvement, with CIs",
        description="For every setting but the baseline: the probability that one of its runs "
        "scores above one of the baseline's (P(X > Y) + ½ P(X = Y)) and the difference in IQM, "
        "each with a percentile bootstrap confidence interval over both settings' runs.",
        formatter_class=formatter,
    )
    compare.add_argument("directory", type=path, help="a sweep's --output directory")
    compare.add_argument("--baseline", default="ppo", help="a setting's label or a variant")
    add_score_flags(compare)
    merged = commands.add_parser(
        "merge",
        help="join sweeps of other seeds or settings (parts of one study) into one output",
        description="Join the runs of sweeps that differ only in their seeds or settings into "
        "one curves.csv and sweep.json, which table, compare and plot read. "
        "Parts of different tasks or protocols, and a run two parts both hold, are refused.",
        formatter_class=formatter,
    )
    merged.add_argument("directories", type=path, nargs="+", help="sweeps' --output directories")
    merged.add_argument("--output", type=path, required=True, help="where the merged sweep goes")
    plot = commands.add_parser(
        "plot", help="write a sweep's learning curves (and α/k chart) as PNG"
    )
    plot.add_argument("directory", type=path, help="a sweep's --output directory")


def _add_policy_commands(commands: argparse._SubParsersAction[Parser]) -> None:
    """``eval`` and ``export``: what reads a trained policy."""
    formatter = Defaults
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
    add_policy_flag(evaluation, "--checkpoint")
    evaluation.add_argument(
        "--episodes",
        type=count,
        default=Options.eval_episodes,
        help="episodes each",
    )
    add_backend_flag(evaluation, None)
    evaluation.add_argument("--seed", type=int, default=0, help="random seed of the episodes")
    add_render_flag(evaluation, "the deterministic policy")

    export = commands.add_parser(
        "export",
        help="write a trained policy as an ONNX model",
        description="Write the deterministic policy saved in DIR (or that of the newest "
        "checkpoint in DIR) as an ONNX model: input `observation` [batch, size] float32, output "
        "`action` (see fppo_jax.export.onnx_export). Needs the onnx extra: "
        f"{install_hint('onnx')}.",
        formatter_class=formatter,
    )
    add_policy_flag(export, "--policy")
    export.add_argument(
        "--onnx", type=path, required=True, metavar="FILE", help="the model file to write"
    )
