"""The ``tune`` command's flags."""

from __future__ import annotations

import argparse

from fppo_jax.cli.flags import (
    Defaults,
    Parser,
    add_shape_flags,
    count,
    level,
    looks,
    names,
    part,
    path,
    variants,
)


def add_tune(commands: argparse._SubParsersAction[Parser]) -> None:
    """``tune``: every arm tuned with the same budget, each rung one program."""
    tuned = commands.add_parser(
        "tune",
        help="tune every variant with the same budget (halving or racing, then a validation "
        "race against the default)",
        description="Tune each variant on each task with the same budget: --trials settings "
        "per variant (trial 0 its default, the others drawn by Optuna from the search space, "
        "the same points on the axes every variant shares), all variants' trials of a task as "
        "one compiled program per rung. --scheduler halving trains each with --seeds-per-trial "
        "tuning seeds and keeps the best 1/eta of each variant's trials after each rung, going "
        "on from where they stopped; --scheduler racing trains full runs, --seeds-per-trial "
        "fresh seeds a round for the trials still in, within --budget full runs per variant "
        "and task, dropping a trial shown worse than the incumbent. Then each variant's "
        "--finalists and its default race on --validation-seeds seeds: a finalist replaces the "
        "default only if shown better (one-sided Wilcoxon signed-rank, paired by seed, Holm, "
        "--race-level). Before any run --output gets tune.json (the plan); each rung is "
        "recorded as it ends, and the same command again goes on from there (a changed plan "
        "is refused). At the end results.json holds each variant's chosen setting and "
        "report.md the tuning report; fppo-jax study --tuned DIR tests them on fresh seeds.",
        formatter_class=Defaults,
    )
    tuned.add_argument(
        "--variants",
        type=variants,
        required=True,
        help="variants, e.g. ppo,spo, or module:attribute for a surrogate of one's own",
    )
    tuned.add_argument(
        "--tasks", type=names, required=True, help="tasks, e.g. cartpole,acrobot (fppo-jax list)"
    )
    add_search_flags(tuned)
    tuned.add_argument(
        "--score",
        default="eval",
        choices=["eval", "train"],
        help="what ranks trials: the deterministic policy's evaluation return (the study's "
        "eval endpoint) or the training return",
    )
    tuned.add_argument(
        "--eval-episodes", type=count, default=10, help="episodes of each evaluation (--score eval)"
    )
    tuned.add_argument(
        "--baseline",
        help="the variant whose default the report measures sampled settings against (default: "
        "ppo if tuned, else the first)",
    )
    tuned.add_argument(
        "--rungs",
        type=looks,
        metavar="N",
        help="train at most N more rungs now, then stop (the same command goes on later); 0 "
        "trains none, but joins the parts of a rung that --part recorded",
    )
    tuned.add_argument(
        "--chunk",
        type=count,
        help="runs per compiled call, a multiple of --seeds-per-trial: a rung's runs train in "
        "groups of that many, the same for every part and the join (default: the plan's; for a "
        "new tune, one trial's seeds where the tasks step in JAX on a CPU, so that one program "
        "trains every rung, else each rung's runs in one call)",
    )
    tuned.add_argument(
        "--part",
        type=part,
        metavar="K/N",
        help="train only the K-th of N shares of the groups of --chunk runs of each task's next "
        "rung, record it and stop, ranking nothing (auto: a SLURM job array task's share); the "
        "same command without --part, once every share is recorded, joins them into the rung "
        "trained unsplit, bit for bit, and goes on",
    )
    tuned.add_argument(
        "--output", type=path, required=True, metavar="DIR", help="the tune's directory"
    )
    add_shape_flags(tuned)
    tuned.add_argument("--quiet", action="store_true", help="no progress lines")


def add_search_flags(parser: argparse._ActionsContainer) -> None:
    """The trials, how they are drawn, how the search spends its budget, and the validation
    race: the flags of ``tune``, and of ``study --tune``."""
    parser.add_argument("--trials", type=count, default=27, help="settings per variant and task")
    parser.add_argument(
        "--seeds-per-trial",
        type=count,
        default=2,
        help="tuning seeds each setting trains with (1000000 on: studies count from 0)",
    )
    parser.add_argument("--eta", type=count, default=3, help="the halving rate (at least 2)")
    parser.add_argument(
        "--space",
        type=path,
        metavar="FILE",
        help="a search space (JSON or YAML) replacing intervals of the default: "
        '{"learning_rate": {"low": 1e-4, "high": 1e-3, "scale": "log"}, "fppo-lp": {"alpha": '
        "[1, 1.5]}}",
    )
    parser.add_argument(
        "--sampler",
        default="qmc",
        choices=["qmc", "random"],
        help="how trials are drawn: Optuna's scrambled Sobol sequence, or at random",
    )
    parser.add_argument("--sampler-seed", type=int, default=0, help="the sampler's seed")
    parser.add_argument(
        "--storage",
        metavar="URL|FILE.log",
        help="Optuna's storage (default: optuna.db, a SQLite file in --output), which many "
        "tunes may share: a database URL, such as postgresql://user@host/db (the postgres "
        "extra's driver) or sqlite:////shared/tunes.db, or a journal file ending .log on a "
        "shared filesystem",
    )
    _add_race_flags(parser)


def _add_race_flags(tuned: argparse._ActionsContainer) -> None:
    """How the search spends its budget, and the validation race."""
    tuned.add_argument(
        "--scheduler",
        default="halving",
        choices=["halving", "racing"],
        help="the search: successive halving over updates, or racing over seeds",
    )
    tuned.add_argument(
        "--budget",
        type=count,
        metavar="N",
        help="full runs per variant and task, the validation race's included (racing: its "
        "rounds; halving: a cap its schedule must fit)",
    )
    tuned.add_argument(
        "--finalists", type=count, default=3, help="trials per variant that race its default"
    )
    tuned.add_argument(
        "--validation-seeds",
        type=count,
        default=10,
        help="seeds of the validation race (2000000 on: apart from tuning and test seeds)",
    )
    tuned.add_argument(
        "--race-level",
        type=level,
        default=0.05,
        help="the level at which a finalist must beat the default (and racing drops a trial)",
    )
