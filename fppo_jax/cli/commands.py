"""What each ``fppo-jax`` command does with its parsed flags: ``train`` one policy, ``sweep``
a grid, ``study`` candidates against a baseline, ``tune`` every variant with the same budget,
``eval`` (and render) or ``export`` a trained policy, ``table``, ``compare``, ``merge`` and
``plot`` sweeps' results, ``list`` the tasks and variants."""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypedDict

import numpy as np

from fppo_jax.analysis.studies import study
from fppo_jax.cli.flags import config_overrides, hyperparameters_given, options
from fppo_jax.cli.slurm import array_part
from fppo_jax.core.config import PRESETS, describe_update, preset_config
from fppo_jax.core.resolution import TABLE2
from fppo_jax.core.variants import BUILTINS, EPSILON
from fppo_jax.envs import BACKENDS, NAMESPACES, TASKS, make_env
from fppo_jax.errors import InvalidInput
from fppo_jax.run.api import train
from fppo_jax.run.distributed import is_main_process
from fppo_jax.run.merge import merge
from fppo_jax.run.results import SweepResult, labels
from fppo_jax.run.sweeps import sweep
from fppo_jax.stats.decidable import plan_lines
from fppo_jax.stats.sequential import Design
from fppo_jax.stats.statistics import CONFIDENCE, STATISTICS, sample_std
from fppo_jax.store.checkpoint import Checkpoints
from fppo_jax.store.files import DirectoryLock, writable_directory
from fppo_jax.store.record import RunRecord
from fppo_jax.store.saved_policy import (
    ARRAYS_FILE,
    POLICY_FILE,
    check_no_saved_policy,
    load_policy,
    read_policy,
)


def _train(args: argparse.Namespace) -> int:
    if args.render:  # refused now rather than after training
        from fppo_jax.export.render import check_render_path, check_renderable

        check_render_path(args.render)
        check_renderable(args.env)
    finished = args.save_policy is not None and _holds_final_policy(args)
    if args.save_policy and not finished:  # refused now rather than after training
        check_no_saved_policy(
            args.save_policy, replace=f"remove its {POLICY_FILE} and {ARRAYS_FILE}"
        )
        writable_directory(args.save_policy)
    result = train(
        args.env,
        args.variant,
        seed=args.seed,
        backend=args.backend,
        **hyperparameters_given(args),
        **options(args),
        **config_overrides(args),
    )
    if not is_main_process():
        return 0
    print(result.summary())
    if args.output:  # written by train
        print(f"wrote {args.output}/config.json, metrics.csv, tensorboard/, summary.txt")
    if finished:
        print(f"kept {args.save_policy}/policy.json, policy.npz: this run's final policy")
    elif args.save_policy:
        print(f"wrote {result.save(args.save_policy)}/policy.json, policy.npz")
    if args.render:
        from fppo_jax.export.render import RenderingUnavailable

        try:
            print(f"wrote {result.render(args.render)}")
        except (RenderingUnavailable, TypeError) as error:
            print(f"fppo-jax: not rendered: {error}", file=sys.stderr)
            return 2
    return 0


def _holds_final_policy(args: argparse.Namespace) -> bool:
    """Whether a resumed run's --save-policy directory holds the policy it finished with: the
    newest checkpoint's run, at that checkpoint's update, its last. Resuming a finished run
    then changes nothing, where saving again would refuse the directory."""
    checkpoint_dir, saved_policy = args.checkpoint_dir, Path(args.save_policy) / POLICY_FILE
    if not (
        args.resume and checkpoint_dir and Path(checkpoint_dir).is_dir() and saved_policy.exists()
    ):
        return False
    saved = read_policy(args.save_policy)[1]  # checked whole: a damaged one is refused
    checkpoints = Checkpoints(checkpoint_dir)
    try:
        newest = checkpoints.latest_record()
    finally:
        checkpoints.close()
    if newest is None or newest["kind"] != "train":
        return False
    run = RunRecord.from_json(newest["config"], f"the newest checkpoint in {checkpoint_dir}")
    policy_run = RunRecord.from_json(saved["config"], f"the policy in {args.save_policy}")
    return policy_run == run and saved["update"] == newest["update"] == run.num_updates


def _sweep(args: argparse.Namespace) -> int:
    grid = {"variant": args.variant, **hyperparameters_given(args)}
    part = array_part() if args.part == "auto" else args.part
    if part is None and "SLURM_ARRAY_TASK_ID" in os.environ and is_main_process():
        print(
            f"fppo-jax: note: SLURM array task {os.environ['SLURM_ARRAY_TASK_ID']} trains the "
            "whole sweep; --part auto would train this task's share of it",
            file=sys.stderr,
        )
    result = sweep(
        args.env,
        grid,
        seeds=args.seeds,
        part=part,
        chunk=args.chunk,
        data_parallel=args.data_parallel,
        backend=args.backend,
        **options(args),
        **config_overrides(args),
    )
    if not is_main_process():
        return 0
    runs, record = len(result.runs), RunRecord.from_json(result.config)
    share = "" if part is None else f" (part {part[0]} of {part[1]})"
    print(
        f"{runs} runs{share} on {record.env} in {result.train_seconds:.1f} s "
        f"(+{result.compile_seconds:.1f} s compiling), {record.runs_per_call} per call"
    )
    print(result.table())
    if args.output:  # written by the sweep as each group of runs finished
        print(f"wrote {args.output}/curves.csv, sweep.json")
    return 0


class Evaluation(TypedDict, total=False):
    """A study's evaluation keywords: how often its runs are evaluated, over how many episodes."""

    eval_every: int
    eval_episodes: int


def _evaluation(args: argparse.Namespace) -> Evaluation:
    """A study's evaluation flags, given only where its runs are evaluated: the plan records
    them then, and only then."""
    if args.eval_every is None:
        return {}
    return {"eval_every": args.eval_every, "eval_episodes": args.eval_episodes}


def _study(args: argparse.Namespace) -> int:
    part = array_part() if args.part == "auto" else args.part
    design = Design(args.group_size, args.max_seeds, args.level, args.margin)
    if args.quiet:  # else the study prints it on stderr with its progress
        for line in plan_lines(design, len(args.tasks) * len(args.candidates)):
            print(line)
    result = study(
        args.tasks,
        args.candidates,
        args.baseline,
        output=args.output,
        max_seeds=args.max_seeds,
        group_size=args.group_size,
        level=args.level,
        margin=args.margin,
        endpoint=args.endpoint,
        groups=args.groups,
        chunk=args.chunk,
        backend=args.backend,
        reuse=args.reuse,
        part=part,
        tuned=args.tuned,
        tune=_tune_arguments(args) if args.tune else None,
        with_defaults=args.with_defaults,
        across_tasks=args.across_tasks,
        progress=not args.quiet,
        **_evaluation(args),
        **hyperparameters_given(args),
        **config_overrides(args),
    )
    if part is not None:
        print(
            f"part {part[0]} of {part[1]} of the next look recorded in {args.output} (or "
            "nothing was left to train); once every part is, the same command without --part "
            "joins them and decides"
        )
        return 0
    for row in result.decisions:
        # With its progress, the study said each decision on stderr as it was made; said here
        # again, the terminal showed it twice. Unless --quiet, only those still waiting.
        if args.quiet or not row["final"]:
            print(
                f"{row['task']}: {row['candidate']} against {row['baseline']}: {row['decision']} "
                f"with {row['seeds']} seeds ({row['reason']})"
            )
    print(f"wrote {args.output}/plan.json, decisions.json, report.md")
    if not result.finished:
        print("not finished: the same command again goes on")
    return 0


def _tune_arguments(args: argparse.Namespace) -> dict[str, Any]:
    """What a command's search flags give :func:`~fppo_jax.tune`."""
    return {
        "trials": args.trials,
        "seeds": args.seeds_per_trial,
        "eta": args.eta,
        "scheduler": args.scheduler,
        "budget": args.budget,
        "finalists": args.finalists,
        "validation_seeds": args.validation_seeds,
        "race_level": args.race_level,
        "space": args.space,
        "sampler": args.sampler,
        "sampler_seed": args.sampler_seed,
        "storage": args.storage,
    }


def _tune(args: argparse.Namespace) -> int:
    from fppo_jax.analysis.tuning import tune

    part = array_part() if args.part == "auto" else args.part
    result = tune(
        args.tasks,
        args.variants,
        output=args.output,
        score=args.score,
        eval_episodes=args.eval_episodes,
        baseline=args.baseline,
        rungs=args.rungs,
        chunk=args.chunk,
        part=part,
        backend=args.backend,
        progress=not args.quiet,
        **_tune_arguments(args),
        **config_overrides(args),
    )
    if part is not None:
        print(
            f"part {part[0]} of {part[1]} of each task's next rung recorded in {args.output} (or "
            "nothing was left to train); once every part is, the same command without --part "
            "joins them and goes on (--rungs 0: joins them alone)"
        )
        return 0
    if not result.finished:
        print(f"wrote {args.output}/tune.json and the rungs so far; the same command goes on")
        return 0
    for task, arms in result.results.items():
        for arm, found in arms.items():
            chosen = found["chosen"]
            if chosen is None:
                what = "every trial diverged"
            elif chosen["score"] is None:
                what = f"trial {chosen['trial']}, no episode finished"
            else:
                what = f"trial {chosen['trial']}, score {chosen['score']:.1f}"
            print(f"{task}: {arm}: {what}")
    print(f"wrote {args.output}/tune.json, results.json, report.md")
    return 0


def _eval(args: argparse.Namespace) -> int:
    from fppo_jax.run.evaluation import evaluate

    if args.render:
        from fppo_jax.export.render import check_render_path

        check_render_path(args.render)
    policy, record = read_policy(args.checkpoint)
    run = RunRecord.from_json(record["config"], f"the record of the policy in {args.checkpoint}")
    if run.env not in TASKS:
        raise InvalidInput(
            f"the policy's environment {run.env!r} is not a registered task; load the "
            "policy with fppo_jax.load_policy and evaluate it on your environment"
        )
    if args.render:
        from fppo_jax.export.render import check_renderable

        check_renderable(run.env)
    env = make_env(run.env, args.backend or run.backend or "auto")
    steps = record["update"] * run.config.samples_per_update
    source = "saved policy" if record["kind"] == "policy" else "checkpoint"
    print(
        f"{run.setting['variant']} on {run.env}, seed {run.seed}: {source} at update "
        f"{record['update']} ({steps:,} env steps); {args.episodes} "
        f"episode{'s' if args.episodes > 1 else ''} each"
    )
    for name, deterministic in (("deterministic", True), ("stochastic", False)):
        returns = evaluate(env, policy, args.episodes, seed=args.seed, deterministic=deterministic)
        shown = f"{returns.mean():.1f}"
        if returns.size > 1:  # one episode has no spread
            shown += f" ± {sample_std(returns):.1f} (mean ± sample std; "
            shown += f"min {returns.min():.1f}, max {returns.max():.1f})"
        print(f"  {name:<13} return {shown}")
    if args.render:
        from fppo_jax.export.render import RenderingUnavailable, drawable, render_policy

        try:
            path = render_policy(drawable(env, run.env), policy, args.render, seed=args.seed)
            print(f"wrote {path}")
        except RenderingUnavailable as error:
            print(f"fppo-jax: not rendered: {error}", file=sys.stderr)
            return 2
    return 0


def _table(args: argparse.Namespace) -> int:
    given = [flag for flag in ("endpoint", "ci") if getattr(args, flag) is not None]
    if args.stat == "paper" and given:
        flags = " and ".join(f"--{flag}" for flag in given)
        raise InvalidInput(
            f"{flags}: --stat paper (the default), Table 1's max average return of the "
            "seed-mean curve, scores no run alone and has no interval; "
            f"{'they are' if len(given) > 1 else 'it is'} for --stat {' or '.join(STATISTICS)}"
        )
    endpoint = args.endpoint or "final"
    result = SweepResult.read(args.directory)
    print(result.table(args.stat, endpoint, args.ci or CONFIDENCE))
    if args.stat != "paper":  # the paper's statistic has no interval
        _warn_of_missing_intervals(result, endpoint)
    return 0


def _compare(args: argparse.Namespace) -> int:
    result = SweepResult.read(args.directory)
    print(result.compare(args.baseline, args.endpoint, args.ci))
    _warn_of_missing_intervals(result, args.endpoint)
    return 0


def _warn_of_missing_intervals(result: SweepResult, endpoint: str) -> None:
    """A line per setting with fewer than two scored runs: a bootstrap resamples a setting's
    runs, so with one its interval is the point itself (or, with none, empty), and says
    nothing of how far another seed would land."""
    for name, scores in zip(labels(result.settings), result.scores(endpoint), strict=True):
        count = int(np.isfinite(scores).sum())
        if count < 2:
            runs = "no run" if count == 0 else "1 run"
            print(
                f"fppo-jax: warning: {name} has {runs} with a {endpoint} score: its confidence "
                "interval cannot be computed (a bootstrap needs 2 runs or more)",
                file=sys.stderr,
            )


def _merge(args: argparse.Namespace) -> int:
    result = merge([SweepResult.read(directory) for directory in args.directories])
    # Held from the check to the write, as a sweep holds its output: of two merges into one
    # directory, one writes and the other is refused.
    lock = DirectoryLock(writable_directory(args.output), "a merged sweep")
    try:
        if (args.output / "sweep.json").exists():
            raise InvalidInput(f"{args.output} already holds a sweep; merge into a new directory")
        result.write(args.output, metrics=list(result.metrics))
    finally:
        lock.release()
    settings, seeds = len(result.settings), len(result.seeds)
    print(
        f"merged {len(args.directories)} sweeps: {len(result.runs)} runs ({settings} settings, "
        f"{seeds} seeds) in {args.output}/curves.csv, sweep.json"
    )
    return 0


def _plot(args: argparse.Namespace) -> int:
    from fppo_jax.analysis.plots import plot_sweep

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
    print("variants (or module:attribute, a surrogate of one's own):")
    for name, s in BUILTINS.items():
        params = ", ".join(f"{k} {v}" for k, v in s.defaults.items()) or "-"
        print(f"  {name:<11} defaults: epsilon {EPSILON}; {params}")
    return 0


def _export(args: argparse.Namespace) -> int:
    from fppo_jax.export.onnx_export import export_onnx

    if os.path.lexists(args.onnx):
        raise InvalidInput(f"{args.onnx} already exists; remove it or choose another path")
    writable_directory(Path(args.onnx).parent)
    print(f"wrote {export_onnx(load_policy(args.checkpoint), args.onnx)}")
    return 0


COMMANDS: dict[str, Callable[[argparse.Namespace], int]] = {
    "train": _train,
    "sweep": _sweep,
    "study": _study,
    "tune": _tune,
    "table": _table,
    "compare": _compare,
    "merge": _merge,
    "plot": _plot,
    "eval": _eval,
    "export": _export,
    "list": lambda args: _list(),
}
