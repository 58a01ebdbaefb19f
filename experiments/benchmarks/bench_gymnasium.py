"""Gymnasium's MuJoCo task against envpool's (native), alone and trained, in one process.

    python experiments/benchmarks/bench_gymnasium.py \
        [--task Hopper-v4] [--steps 40960] [--repeats 2]

The same task version on both backends, 8 environments (the paper preset's), random actions
or PPO: (a) the environments alone on the host, no JAX: a loop over 8 ``gymnasium.Env``
against one envpool pool of 8, stepped `--steps` times in all, ended episodes reset; (b) this
trainer (``fppo_jax.train`` with ``gymnasium/<task>`` and ``native/<task>``, the paper preset,
`--steps` env steps), its training time (``train_seconds``) apart from compiling. The arms
alternate `--repeats` times; the best of each counts. Writes
experiments/results/bench_gymnasium_<task>.md.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

import fppo_jax
from fppo_jax.envs.native import import_envpool

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: shared modules

from common import add_record_flags, argument_parser, header, refuse_to_replace, write_result

NUM_ENVS = 8


def random_actions(space: Any, steps: int) -> np.ndarray:
    """[step, environment, …] random actions of `space`, a Discrete or a Box, seeded."""
    rng = np.random.default_rng(0)
    shape = (steps // NUM_ENVS, NUM_ENVS)
    if hasattr(space, "n"):  # Discrete: its actions start at `start`
        return rng.integers(space.start, space.start + space.n, shape)
    return rng.uniform(space.low, space.high, (*shape, *space.shape)).astype(np.float32)


def gymnasium_alone(task: str, steps: int) -> float:
    import gymnasium

    envs = [gymnasium.make(task) for _ in range(NUM_ENVS)]
    for seed, env in enumerate(envs):
        env.reset(seed=seed)
    actions = random_actions(envs[0].action_space, steps)
    start = time.perf_counter()
    for row in actions:
        for env, action in zip(envs, row, strict=True):
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset()
    return steps / (time.perf_counter() - start)


def envpool_alone(task: str, steps: int) -> float:
    envpool = import_envpool()
    pool = envpool.make(task, env_type="gymnasium", num_envs=NUM_ENVS, seed=0, num_threads=1)
    pool.reset()
    actions = random_actions(pool.action_space, steps)
    ids = np.arange(NUM_ENVS)
    start = time.perf_counter()
    for row in actions:
        pool.step(row, ids)  # envpool resets an ended environment on its next step
    return steps / (time.perf_counter() - start)


def trained(name: str, steps: int) -> tuple[float, float]:
    """(training env steps/s, compile seconds)."""
    result = fppo_jax.train(name, "ppo", total_steps=steps)
    return steps / result.train_seconds, result.compile_seconds


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--task", default="Hopper-v4", help="an id both Gymnasium and envpool have")
    parser.add_argument("--steps", type=int, default=40_960)
    parser.add_argument("--repeats", type=int, default=2)
    add_record_flags(parser)
    args = parser.parse_args()
    output = args.results / f"bench_gymnasium_{args.task}.md"
    refuse_to_replace([output], args.force)

    alone: dict[str, list[float]] = {"gymnasium": [], "native": []}
    training: dict[str, list[float]] = {"gymnasium": [], "native": []}
    compiling: dict[str, float] = {}
    for repeat in range(args.repeats):
        alone["gymnasium"].append(gymnasium_alone(args.task, args.steps))
        alone["native"].append(envpool_alone(args.task, args.steps))
        for backend in ("gymnasium", "native"):
            rate, seconds = trained(f"{backend}/{args.task}", args.steps)
            training[backend].append(rate)
            compiling.setdefault(backend, seconds)
        print(f"repeat {repeat + 1}: alone {alone}, trained {training}", flush=True)
    best = {
        kind: {b: max(v) for b, v in arms.items()}
        for kind, arms in (("alone", alone), ("trained", training))
    }
    lines = [
        *header(f"{args.task}: Gymnasium's environments against envpool's (native)"),
        "",
        f"{NUM_ENVS} environments, {args.steps:,} env steps an arm, best of {args.repeats} "
        "(arms alternating). (a): the environments alone on the host, random actions, no JAX "
        "(Gymnasium: a Python loop over its environments; envpool: one pool, one thread). (b): "
        "PPO with the paper preset through `fppo_jax.train`, training time only (compiling "
        "apart).",
        "",
        "| | Gymnasium (env steps/s) | native, envpool (env steps/s) | native / Gymnasium |",
        "|---|---|---|---|",
    ]
    for kind, label in (("alone", "(a) environments alone"), ("trained", "(b) fppo-jax, PPO")):
        g, n = best[kind]["gymnasium"], best[kind]["native"]
        lines.append(f"| {label} | {g:,.0f} | {n:,.0f} | {n / g:.2f}× |")
    lines += [
        "",
        f"Compiling (first run of each): Gymnasium {compiling['gymnasium']:.1f} s, native "
        f"{compiling['native']:.1f} s.",
    ]
    write_result(output, lines)
    print(f"wrote {output}")


if __name__ == "__main__":
    main()
