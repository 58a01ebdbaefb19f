"""What each of the trainer's extras costs under vmap: the same vmapped program with one extra
taken out at a time.

    python experiments/profiles/profile_vmap.py [--workload purejaxrl|paper] [--seeds 8]
        [--steps 500000] [--repeats 3]

One of the CartPole workloads measured against PureJaxRL (`purejaxrl_settings.py`), `--seeds`
vmapped seeds, the whole run one compiled call. The arms, each compiled apart and timed
interleaved (best of `--repeats`):
- as is;
- with `jax.random.permutation` shuffling the minibatches (as PureJaxRL does) in place of
  `fppo_jax.core.permutation`'s packed-key sort;
- without the escape-speed pass (the policy over the whole batch after the last epoch);
- with PPO's surrogate alone in the loss (no select over six, and so no per-minibatch KL);
- without the non-finite guard (the select of the old state after a non-finite update);
- with a plain scan of the chunk's updates in place of `Trainer.run`'s loop of the updates left
  of the run (under vmap that loop runs to the last run's end and selects);
- without any of them.
The arms without an extra are measurements only: what the package computes is the first arm's.
Writes experiments/results/profile_vmap_<workload>_<seeds>seeds.md.
"""

from __future__ import annotations

import contextlib
import functools
import sys
from pathlib import Path
from unittest import mock

import jax
import jax.numpy as jnp

import fppo_jax.core.objectives as objectives
import fppo_jax.core.trainer as trainer_module
import fppo_jax.core.variants as variants
from fppo_jax import make_train
from fppo_jax.core.trainer import Trainer

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: shared modules

import purejaxrl_settings as pjr
from common import (
    add_record_flags,
    argument_parser,
    best_interleaved,
    header,
    refuse_to_replace,
    write_result,
)


class WithoutEscape(Trainer):
    def _escape(self, params, batch, epsilon):
        return jnp.zeros(()), jnp.zeros(())


class PlainScan(Trainer):
    def run(self, state, hp, num_updates):
        return jax.lax.scan(lambda s, _: self.update(s, hp), state, None, length=num_updates)


class WithoutAny(WithoutEscape, PlainScan):
    pass


# Each a context manager factory that swaps one piece of the package for the arm's compilation.
ppo_surrogate_only = functools.partial(
    mock.patch.object,
    objectives.Objective,
    "__call__",
    lambda o, r, a, kl=None: variants.ppo(r, a, o.epsilon),
)
jax_permutation = functools.partial(
    mock.patch.object, trainer_module, "permutation", jax.random.permutation
)
without_guard = functools.partial(
    mock.patch.object, trainer_module, "_keep_if_finite", lambda new, old, losses: new
)


def compiled(kind: type[Trainer], *patches, workload: str, seeds: int, steps: int) -> object:
    env, config, hp = pjr.fppo(workload, steps)
    base = make_train(config, env)
    trainer = kind(base.config, base.env, base.networks)
    hps = jax.tree.map(lambda x: jnp.broadcast_to(x, (seeds, *x.shape)), hp)
    keys = jax.random.split(jax.random.key(0), seeds)
    with contextlib.ExitStack() as stack:
        for patch in patches:
            stack.enter_context(patch())
        program = jax.jit(jax.vmap(trainer)).lower(keys, hps).compile()
    return lambda: program(keys, hps)


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--workload", choices=sorted(pjr.WORKLOADS), default="purejaxrl")
    parser.add_argument("--seeds", type=int, default=8)
    parser.add_argument("--steps", type=int, default=500_000)
    parser.add_argument("--repeats", type=int, default=3)
    add_record_flags(parser)
    args = parser.parse_args()
    path = args.results / f"profile_vmap_{args.workload}_{args.seeds}seeds.md"
    refuse_to_replace([path], args.force)
    arm = functools.partial(compiled, workload=args.workload, seeds=args.seeds, steps=args.steps)
    arms = {
        "as is": arm(Trainer),
        "with `jax.random.permutation`'s shuffle (as PureJaxRL's)": arm(Trainer, jax_permutation),
        "without the escape-speed pass": arm(WithoutEscape),
        "PPO's surrogate alone": arm(Trainer, ppo_surrogate_only),
        "without the non-finite guard": arm(Trainer, without_guard),
        "a plain scan of updates": arm(PlainScan),
        "without any of them": arm(WithoutAny, ppo_surrogate_only, without_guard),
    }
    best = best_interleaved(arms, args.repeats)
    base, n, steps = best["as is"], args.seeds, args.steps
    lines = [
        *header("What each extra costs under vmap"),
        f"- {pjr.WORKLOADS[args.workload]['title']}: {n} vmapped seeds × {steps:,} steps, one "
        f"compiled call per arm, interleaved, best of {args.repeats}.",
        "",
        "| arm | run (s) | env steps/s | time against as is |",
        "|---|---|---|---|",
        *[
            f"| {name} | {wall:.2f} | {n * steps / wall:,.0f} | {wall / base:.3f} |"
            for name, wall in best.items()
        ],
    ]
    write_result(path, lines)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
