"""Training throughput on CartPole against PureJaxRL's PPO, measured in the same process.

    python experiments/benchmarks/bench_cartpole.py [--repeats 3] [--smoke]

PureJaxRL's `ppo.py` (from `--purejaxrl`, default ../shared/anchors/purejaxrl beside the
repository; it needs `distrax`) and `fppo_jax.make_train` run the same settings, neither
normalising observations or rewards, on gymnax CartPole-v1 (500-step episodes):
- PureJaxRL's own CartPole settings: 4 envs × 128 steps, 4 minibatches × 4 epochs, lr 2.5e-4
  annealed, entropy 0.01; 500k steps at 1 and 8 seeds, 100k steps at 64;
- the paper's protocol: 8 envs × 256 steps, 32 minibatches × 10 epochs, lr 3e-4, entropy 0;
  200k steps at 1 and 8 seeds.
Each whole run (or vmapped batch of runs) is one compiled call, compiled apart from the timing.
One seed is timed twice: as each trainer runs a single run (PureJaxRL's `jax.jit(train)(key)`,
as its own script does; fppo-jax's `train`, which takes the run axis off), where the goal is
set, and vmapped over a batch of one, as 8 and 64 seeds are.
The arms are interleaved and each figure is the best of `--repeats` (2 at 64 seeds): run it on
a quiet machine, since load that comes and goes between arms skews even interleaved timings.
fppo-jax reports its whole metrics (losses, KL, clip and escape-speed fractions) per update.
Writes experiments/results/bench_cartpole.md.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from pathlib import Path

import jax
import jax.numpy as jnp

from fppo_jax import make_train
from fppo_jax.run.execution import one_run

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: shared modules

import purejaxrl_settings as pjr
from common import (
    RESULTS,
    add_output_flags,
    argument_parser,
    header,
    refuse_to_replace,
    seconds,
    write_result,
)

REPO = Path(__file__).resolve().parents[2]
PUREJAXRL = REPO.parent / "shared" / "anchors" / "purejaxrl"

# (workload, seeds, vmapped, steps per seed, goal: fppo-jax / PureJaxRL, None where none is set)
ARMS = (
    ("purejaxrl", 1, False, 500_000, 1.3),
    ("purejaxrl", 1, True, 500_000, None),
    ("purejaxrl", 8, True, 500_000, 1.2),
    ("purejaxrl", 64, True, 100_000, 1.2),
    ("paper", 1, False, 200_000, 1.3),
    ("paper", 1, True, 200_000, None),
    ("paper", 8, True, 200_000, 1.2),
)


def purejaxrl_program(
    module, workload: str, seeds: int, vmapped: bool, steps: int
) -> Callable[[], object]:
    """PureJaxRL's whole run (vmapped over `seeds`, or its single run), compiled; a call
    trains it."""
    train = module.make_train(pjr.purejaxrl(workload, steps))
    keys = jax.random.split(jax.random.PRNGKey(0), seeds)
    if not vmapped:
        compiled_single = jax.jit(train).lower(keys[0]).compile()
        return lambda: compiled_single(keys[0])
    compiled = jax.jit(jax.vmap(train)).lower(keys).compile()
    return lambda: compiled(keys)


def fppo_program(workload: str, seeds: int, vmapped: bool, steps: int) -> Callable[[], object]:
    """fppo-jax's whole run with the same settings (vmapped over `seeds`, or a single run as
    `train` runs it), compiled."""
    env, config, hp = pjr.fppo(workload, steps)
    trainer = make_train(config, env)
    hps = jax.tree.map(lambda x: jnp.broadcast_to(x, (seeds, *x.shape)), hp)
    keys = jax.random.split(jax.random.key(0), seeds)
    along_runs = jax.vmap if vmapped else one_run
    compiled = jax.jit(along_runs(trainer)).lower(keys, hps).compile()
    return lambda: compiled(keys, hps)


def how(seeds: int, vmapped: bool) -> str:
    """An arm's seeds, as the table names them."""
    return f"{seeds}, vmapped" if vmapped else f"{seeds}, a single run"


def compiled_in(make: Callable[[], Callable[[], object]]) -> tuple[Callable[[], object], float]:
    start = time.perf_counter()
    program = make()
    return program, time.perf_counter() - start


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--purejaxrl", type=Path, default=PUREJAXRL, help="its ppo.py's folder")
    parser.add_argument(
        "--smoke", action="store_true", help="each workload's single run, 8,192 steps, 1 repeat"
    )
    add_output_flags(parser, RESULTS / "bench_cartpole.md")
    args = parser.parse_args()
    refuse_to_replace([args.output], args.force, elsewhere="--output FILE")
    if not (args.purejaxrl / "ppo.py").exists():
        sys.exit(f"PureJaxRL's ppo.py is not in {args.purejaxrl}: pass --purejaxrl DIR")
    sys.path.insert(0, str(args.purejaxrl))
    import ppo as purejaxrl  # found only once its folder is on the path

    repeats = 1 if args.smoke else args.repeats
    arms = (
        [(w, n, v, 8192, g) for w, n, v, _, g in ARMS if n == 1 and not v] if args.smoke else ARMS
    )
    programs = []
    for workload, seeds, vmapped, steps, _ in arms:
        theirs, their_compile = compiled_in(
            lambda w=workload, n=seeds, v=vmapped, s=steps: purejaxrl_program(purejaxrl, w, n, v, s)
        )
        ours, our_compile = compiled_in(
            lambda w=workload, n=seeds, v=vmapped, s=steps: fppo_program(w, n, v, s)
        )
        programs.append((theirs, ours, their_compile, our_compile))
        print(
            f"{workload}, {how(seeds, vmapped)}: compiled "
            f"({their_compile:.1f} s, {our_compile:.1f} s)"
        )
    best = [[float("inf"), float("inf")] for _ in arms]
    for repeat in range(repeats):
        for i, ((workload, seeds, vmapped, _, _), (theirs, ours, _, _)) in enumerate(
            zip(arms, programs, strict=True)
        ):
            if seeds >= 64 and repeat >= 2:
                continue
            best[i][0] = min(best[i][0], seconds(theirs))
            best[i][1] = min(best[i][1], seconds(ours))
            print(f"repeat {repeat + 1}: {workload}, {how(seeds, vmapped)}: {best[i]}", flush=True)

    lines = [
        *header("CartPole training throughput against PureJaxRL, in the same process"),
        "- PureJaxRL's `ppo.py` (patched only for gymnax 1.0) and `fppo_jax.make_train` with the "
        "same settings on gymnax CartPole-v1, no observation or reward normalisation in either; "
        "each whole run one compiled call (vmapped over the seeds, or one seed as each trainer "
        "runs a single run), compilation apart; arms "
        f"interleaved, best of {repeats} ({min(repeats, 2)} at 64 seeds). fppo-jax computes its "
        "every metric per update, the escape-speed fractions included.",
        "",
        "| workload | seeds | steps per seed | PureJaxRL env steps/s | fppo-jax env steps/s | "
        "ratio | goal | compile PureJaxRL / fppo-jax (s) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for (workload, seeds, vmapped, steps, goal), (theirs, ours), (*_, c_theirs, c_ours) in zip(
        arms, best, programs, strict=True
    ):
        rate_theirs, rate_ours = seeds * steps / theirs, seeds * steps / ours
        ratio = rate_ours / rate_theirs
        aim = "—" if goal is None else f"{goal}× ({'met' if ratio >= goal else 'missed'})"
        lines.append(
            f"| {pjr.WORKLOADS[workload]['title']} | {how(seeds, vmapped)} | {steps:,} | "
            f"{rate_theirs:,.0f} | {rate_ours:,.0f} | **{ratio:.2f}×** | {aim} | "
            f"{c_theirs:.1f} / {c_ours:.1f} |"
        )
    write_result(args.output, lines)
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
