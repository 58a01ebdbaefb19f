"""What the experiment scripts share: where results go and the rule that a recorded result is
never replaced unasked; the machine, date and command a result records; the paper's Table 1,
the sweeps and the recorded files that several scripts make or read; and what several
measurements time (a compiled call, the environment alone).

Reports rebuilt from what is recorded (``figures.py``, ``verdict.py``, the Markdown summaries of
``table1_mujoco.py`` and ``ablation.py``) are written again freely; what was trained or measured
(curves, run records, benchmark and profile tables) is replaced only with ``--force``.

JAX and fppo_jax are imported by the functions that use them, so that ``gpu_suite.py``, which
runs the other scripts in processes of their own, lists its parts and refuses without them.
"""

from __future__ import annotations

import argparse
import ast
import csv
import datetime
import functools
import json
import subprocess
import sys
import tempfile
import textwrap
import time
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    import jax
    from matplotlib.axes import Axes

    from fppo_jax import SweepResult
    from fppo_jax.envs import Environment

RESULTS = Path(__file__).resolve().parent / "results"
RUN_RECORD = "run.json"  # beside a sweep's curves: the machine, date, wall time, commit, command

PAPER_VARIANTS = ("fppo-lp", "fppo-qp", "ppo", "tr-ppo", "ppo-rb")
CLASSIC_TASKS = ("cartpole", "acrobot", "mountaincar")
TABLE1 = {  # the paper's Table 1, max average return, in PAPER_VARIANTS' order
    "cartpole": (200.0, 200.0, 200.0, 192.7, 200.0),
    "acrobot": (-84.2, -82.0, -88.7, -86.8, -89.2),
    "mountaincar": (-130.6, -131.0, -143.3, -140.2, -146.2),
    "walker2d": (4030.4, 3893.4, 3368.5, 3279.8, 2858.4),
    "ant": (2778.8, 3323.6, 2024.3, 2013.0, 2640.1),
    "reacher": (-6.1, -6.5, -7.6, -6.0, -7.8),
    "hopper": (2726.1, 2908.8, 2364.2, 2341.8, 1997.7),
    "halfcheetah": (4107.0, 4478.3, 4141.7, 3455.8, 3420.1),
    "swimmer": (113.6, 115.5, 100.2, 108.9, 99.8),
}
# What the tables, the figures and the verdict read: the curves stay small enough to keep in the
# repository.
RECORDED_METRICS = (
    "env_steps",
    "average_return",
    "negative_fraction_before",
    "negative_fraction_after",
)
ESCAPE_VARIANTS = ("ppo", "fppo-lp", "fppo-qp")
ESCAPE_FRACTIONS = Path("escape_speed") / "fractions.csv"  # escape_speed.py's, under the results
ABLATION_PARTS = {  # part: the variant and the values of its own hyperparameter (Fig. 6)
    "alpha": ("fppo-lp", "alpha", [1.1, 1.2, 1.3, 1.4, 1.5]),
    "k": ("fppo-qp", "k", [0.1, 0.2, 0.3, 0.4, 0.5]),
}


def argument_parser(doc: str) -> argparse.ArgumentParser:
    """A script's argument parser, described by the first paragraph of its docstring `doc`."""
    return argparse.ArgumentParser(description=doc.split("\n\n")[0])


def add_force_flag(parser: argparse.ArgumentParser) -> None:
    """``--force``: replace what is already recorded."""
    parser.add_argument("--force", action="store_true", help="replace results already recorded")


def add_record_flags(parser: argparse.ArgumentParser) -> None:
    """``--results DIR`` (where results go) and ``--force``."""
    parser.add_argument("--results", type=Path, default=RESULTS, help="where results go")
    add_force_flag(parser)


def add_output_flags(parser: argparse.ArgumentParser, default: Path) -> None:
    """``--output FILE`` (the result file, `default` unless given) and ``--force``."""
    parser.add_argument("--output", type=Path, default=default, help="the result file")
    add_force_flag(parser)


def refuse_to_replace(paths: Iterable[Path], force: bool, elsewhere: str = "--results DIR") -> None:
    """Exit, before any work, if one of `paths` is already recorded and `force` is not set;
    `elsewhere`: the script's own flags that record in other places."""
    existing = [path for path in paths if path.exists()]
    if existing and not force:
        more = f" (and {len(existing) - 1} more)" if len(existing) > 1 else ""
        sys.exit(
            f"{existing[0]}{more} is already recorded: pass --force to replace it, or "
            f"{elsewhere} to record elsewhere and keep both"
        )


def add_smoke_flags(parser: argparse.ArgumentParser, smoke: str) -> None:
    """``--smoke`` (what it runs: `smoke`), ``--results DIR`` and ``--force``, for a script
    whose smoke run writes into a new temporary directory (see :func:`results_of`)."""
    parser.add_argument("--smoke", action="store_true", help=smoke)
    parser.add_argument(
        "--results",
        type=Path,
        help="where results go (default: experiments/results, or a new temporary directory "
        "with --smoke)",
    )
    add_force_flag(parser)


def results_of(args: argparse.Namespace, name: str) -> Path:
    """Where the results of a script with :func:`add_smoke_flags` go: ``--results``, else the
    recorded results, else with ``--smoke`` a new temporary directory (``fppo-<name>-smoke-…``);
    a smoke run never writes into the recorded results."""
    if not args.smoke:
        return args.results or RESULTS
    if args.results is None:
        return Path(tempfile.mkdtemp(prefix=f"fppo-{name}-smoke-"))
    if inside_results(args.results):
        sys.exit(f"--smoke never writes into the recorded results ({RESULTS}); pass another")
    return args.results


def inside_results(path: Path) -> bool:
    """Whether `path` is this repository's recorded results or inside them."""
    path, results = path.resolve(), RESULTS.resolve()
    return path == results or results in path.parents


def machine() -> str:
    """The machine this script runs on, in words (the library's, which its records keep)."""
    from fppo_jax.store.machine import describe_machine

    return describe_machine()


UNCOMMITTED = "with uncommitted changes to the code"


def commit() -> str:
    """The commit the code runs at, and whether the package's or the scripts' code differed from
    it (``unknown`` outside a git checkout)."""
    here = Path(__file__).resolve().parent
    git = functools.partial(subprocess.run, cwd=here, capture_output=True, text=True, check=True)
    try:
        head = git(["git", "rev-parse", "HEAD"]).stdout.strip()
        changed = git(["git", "status", "--porcelain", "--", "../fppo_jax", "*.py"]).stdout
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return head + (f" {UNCOMMITTED}" if changed.strip() else "")


# The code a script runs, taken as it starts: whatever is committed while it runs is not its.
STARTED_AT = commit()


def command() -> str:
    """The command line that is running, as it is typed from the repository root."""
    script, experiments = Path(sys.argv[0]).resolve(), Path(__file__).resolve().parent
    if experiments in script.parents:
        where = script.relative_to(experiments.parent)
    else:  # not a script of this folder (a test, say)
        where = Path("experiments") / script.name
    return " ".join([f"python {where.as_posix()}", *sys.argv[1:]])


def header(title: str) -> list[str]:
    """A Markdown result's first lines: its title, then the machine, date, command and commit
    that made it."""
    return [
        f"# {title}",
        "",
        f"- Machine: {machine()}; {datetime.date.today()}",
        f"- Command: `{command()}`, at {STARTED_AT}",
    ]


def folder_entry_point(doc: str, folder: Path, smoke: dict[str, str]) -> None:
    """A folder's entry point, ``python experiments/<folder>``: lists its scripts, each with
    the first line of its docstring; with ``--smoke``, runs each (or those of ``--scripts``)
    tiny, in a process of its own, with its arguments in `smoke`, into a new temporary
    directory (``{tmp}`` there), and exits 1 if any failed. `smoke` names every script of the
    folder (each ``*.py`` but a helper's ``_*.py``): a new script is refused until it has its
    smoke arguments."""
    parser = argument_parser(doc)
    parser.add_argument("--smoke", action="store_true", help="run each script tiny")
    parser.add_argument(
        "--scripts", nargs="+", default=list(smoke), choices=list(smoke), metavar="SCRIPT"
    )
    args = parser.parse_args()
    # A module named with a leading underscore is a script's helper, not a script.
    scripts = sorted(path.name for path in folder.glob("[!_]*.py"))
    if scripts != sorted(smoke):
        differ = sorted(set(scripts) ^ set(smoke))
        sys.exit(f"{folder.name}/__main__.py does not name the folder's scripts: {differ}")
    if not args.smoke:
        for name in scripts:
            about = ast.get_docstring(ast.parse((folder / name).read_text())) or "–"
            summary = " ".join(about.split("\n\n")[0].split())
            print(f"python experiments/{folder.name}/{name}")
            print(textwrap.fill(summary, 96, initial_indent="    ", subsequent_indent="    "))
        return
    tmp = Path(tempfile.mkdtemp(prefix=f"fppo-{folder.name}-smoke-"))
    failed = []
    for name in args.scripts:
        arguments = [argument.format(tmp=tmp) for argument in smoke[name].split()]
        start = time.perf_counter()
        done = subprocess.run(
            [sys.executable, str(folder / name), *arguments], capture_output=True, text=True
        )
        took = f"in {time.perf_counter() - start:.0f} s"
        if done.returncode:
            failed.append(name)
            print(f"{folder.name}/{name}: FAILED (exit {done.returncode}) {took}", flush=True)
            print("\n".join((done.stdout + done.stderr).splitlines()[-15:]), flush=True)
        else:
            print(f"{folder.name}/{name}: ran {took}", flush=True)
    print(f"what they wrote is in {tmp}")
    if failed:
        sys.exit(f"{len(failed)} of {len(args.scripts)} failed: {', '.join(failed)}")


def write_result(path: Path, lines: Iterable[str]) -> None:
    """Write `lines` to `path`, making its folder if need be."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")


def write_run_record(directory: Path, wall_seconds: float, **more: str) -> None:
    """`directory`'s run record: the machine, date, wall time, commit and command, with
    `more`."""
    record = {
        "machine": machine(),
        "date": str(datetime.date.today()),
        "wall_seconds": round(wall_seconds, 1),
        "commit": STARTED_AT,
        **more,
        "command": command(),
    }
    (directory / RUN_RECORD).write_text(json.dumps(record, indent=1) + "\n")


def read_run_record(directory: Path) -> dict[str, Any]:
    """What :func:`write_run_record` wrote in `directory`."""
    return json.loads((directory / RUN_RECORD).read_text())


def seconds(program: Callable[[], object]) -> float:
    """Wall seconds of one call of `program`, until its results are ready."""
    import jax

    start = time.perf_counter()
    jax.block_until_ready(program())
    return time.perf_counter() - start


def best_interleaved(programs: dict[str, Callable[[], object]], repeats: int) -> dict[str, float]:
    """Each program's best wall seconds over `repeats` rounds that call every program in turn,
    so that load that comes and goes falls on all of them alike; each round is printed."""
    best = dict.fromkeys(programs, float("inf"))
    for repeat in range(repeats):
        for name, program in programs.items():
            best[name] = min(best[name], seconds(program))
        print(f"repeat {repeat + 1}: " + ", ".join(f"{k} {v:.2f} s" for k, v in best.items()))
    return best


def env_alone(
    env: Environment, num_envs: int, num_steps: int, num_rollouts: int, fresh_resets: bool = True
) -> Callable[[jax.Array], jax.Array]:
    """The environment alone, to jit and time: random actions for `num_rollouts` ×
    `num_steps` steps of `num_envs` environments, restarting ended episodes from one reset
    state per environment per rollout, drawn afresh (or, without `fresh_resets`, the first one
    drawn, reused for the whole run, as Brax's auto-reset does; native environments restart
    themselves). It returns the rewards' sum, so that the compiler leaves none of the steps
    out."""
    import jax
    import jax.numpy as jnp

    from fppo_jax.envs import Discrete, draw_resets, resets_itself, where_done

    space = env.action_space

    def random_actions(key: jax.Array, shape: tuple[int, ...]) -> jax.Array:
        if isinstance(space, Discrete):
            return jax.random.randint(key, shape, 0, space.n)
        low, high = jnp.asarray(space.low), jnp.asarray(space.high)
        return jax.random.uniform(key, (*shape, space.size), minval=low, maxval=high)

    own_resets = resets_itself(env)

    def run(key: jax.Array) -> jax.Array:
        init_key, key = jax.random.split(key)
        state, _ = draw_resets(env, init_key, (num_envs,))
        first = state

        def rollout(state, key):
            action_key, step_key, reset_key = jax.random.split(key, 3)
            shape = (num_steps, num_envs)
            actions = random_actions(action_key, shape)
            resets = None if own_resets else first
            if fresh_resets and not own_resets:
                resets = draw_resets(env, reset_key, (num_envs,))[0]

            def step(state, inputs):
                keys, action = inputs
                state, out = jax.vmap(env.step)(keys, state, action)
                if own_resets:
                    return state, out.reward
                return where_done(out.terminated | out.truncated, resets, state), out.reward

            keys = jax.random.split(step_key, shape)
            state, rewards = jax.lax.scan(step, state, (keys, actions))
            return state, rewards.sum()

        return jax.lax.scan(rollout, state, jax.random.split(key, num_rollouts))[1].sum()

    return run


def add_sweep_flags(parser: argparse.ArgumentParser) -> None:
    """``--seeds``, ``--steps``, ``--chunk`` and ``--backend``: what :func:`record_sweep` and
    :func:`sweep_directory` read."""
    from fppo_jax.envs import BACKENDS

    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--steps", type=int, default=1_000_000)
    parser.add_argument("--chunk", type=int, help="runs per compiled call (default: automatic)")
    parser.add_argument("--backend", default="auto", choices=list(BACKENDS))


def sweep_directory(
    args: argparse.Namespace, name: str, parts: Iterable[str | Path]
) -> tuple[str, Path]:
    """The backend `args.backend` gives the first of `args.tasks`, and <results>/<name>_<backend>,
    announced once none of its `parts` this run records is already recorded (or `--force`)."""
    from fppo_jax.envs import choose_backend

    backend, why = choose_backend(args.tasks[0], args.backend)
    directory = args.results / f"{name}_{backend}"
    refuse_to_replace([directory / part for part in parts], args.force)
    print(f"backend {backend}{' (' + why + ')' if why else ''}; results in {directory}")
    return backend, directory


def record_sweep(
    task: str, grid: dict[str, Any], args: argparse.Namespace, directory: Path
) -> SweepResult:
    """`task`'s sweep of `grid` with the command line's seeds, steps, chunk and backend; its
    curves (:data:`RECORDED_METRICS`) and its run record go to `directory`."""
    from fppo_jax import sweep

    start = time.perf_counter()
    result = sweep(
        task,
        grid,
        seeds=args.seeds,
        total_steps=args.steps,
        chunk=args.chunk,
        backend=args.backend,
        progress=True,
    )
    wall = time.perf_counter() - start
    result.write(directory, metrics=RECORDED_METRICS)
    write_run_record(directory, wall)
    return result


def recorded_parts(folder: Path) -> dict[Path, SweepResult]:
    """The parts recorded in `folder` (one task's protocol: ``<results>/study/<task>/paper/``),
    by directory in order of name: each sweep with the run record (:data:`RUN_RECORD`) that
    a script of this folder writes beside it."""
    from fppo_jax import SweepResult

    records = sorted(folder.glob(f"*/{RUN_RECORD}"))
    return {record.parent: SweepResult.read(record.parent) for record in records}


def by_variant(result: SweepResult) -> dict[str, int]:
    return {setting["variant"]: index for index, setting in enumerate(result.settings)}


def read_fractions(path: Path) -> dict[str, np.ndarray]:
    """What ``escape_speed.py`` wrote to `path` (:data:`ESCAPE_FRACTIONS` under its results):
    each task's fractions, [seed, update point, variant (:data:`ESCAPE_VARIANTS`), epoch]."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    by_task: dict[str, np.ndarray] = {}
    for task in dict.fromkeys(r["task"] for r in rows):
        mine = [r for r in rows if r["task"] == task]
        seeds = len({r["seed"] for r in mine})
        points = len({r["update"] for r in mine})
        values = np.array([float(r["fraction"]) for r in mine])
        by_task[task] = values.reshape(seeds, points, len(ESCAPE_VARIANTS), -1)
    return by_task


def ablation_parts(directory: Path, task: str) -> list[str]:
    """The parts of `task`'s ablation (:data:`ABLATION_PARTS`) recorded under `directory`."""
    return [part for part in ABLATION_PARTS if (directory / task / part / RUN_RECORD).exists()]


def draw_ablation(directory: Path, task: str, axes: Sequence[Axes]) -> None:
    """Each recorded ablation part of `task` on its own Axes: max average return against its
    hyperparameter, with Table 2's choice marked."""
    from fppo_jax.analysis.plots import plot_ablation
    from fppo_jax.core.resolution import table2
    from fppo_jax.run.results import SweepResult

    for ax, part in zip(axes, ablation_parts(directory, task), strict=False):
        plot_ablation(SweepResult.read(directory / task / part), axes=[ax])
        variant, name, _ = ABLATION_PARTS[part]
        chosen = table2(task, variant).get(name)
        if chosen is not None:
            ax.axvline(chosen, color="grey", linestyle=":", label=f"Table 2: {name} = {chosen}")
            ax.legend(fontsize="small")
