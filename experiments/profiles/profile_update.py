"""Where one update's time goes: each compiled part of it timed on its own.

    python experiments/profiles/profile_update.py [--repeats 200]

Parts: the environment alone (random actions, the same number of steps as a rollout, one reset
state per environment), the rollout (policy + environment), the epochs of minibatch updates,
and the whole update.
Settings: PureJaxRL's CartPole (see purejaxrl_settings.py). Prints its table and writes it to
experiments/results/profile_update.md.
"""

import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp

from fppo_jax import make_train

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: shared modules

import purejaxrl_settings as pjr
from common import (
    add_record_flags,
    argument_parser,
    env_alone,
    header,
    refuse_to_replace,
    write_result,
)


def seconds_per_call(fn, *args, repeats, blocks=7):
    """The best of `blocks` timings of `repeats` calls: the least disturbed by the machine."""
    jax.block_until_ready(fn(*args))
    best = float("inf")
    for _ in range(blocks):
        start = time.perf_counter()
        for _ in range(repeats):
            out = fn(*args)
        jax.block_until_ready(out)
        best = min(best, (time.perf_counter() - start) / repeats)
    return best


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--repeats", type=int, default=200)
    add_record_flags(parser)
    args = parser.parse_args()
    output = args.results / "profile_update.md"
    refuse_to_replace([output], args.force)

    env, config, hp = pjr.fppo("purejaxrl")
    trainer = make_train(config, env)
    state = jax.jit(trainer.init)(jax.random.key(0), hp)

    rollout = jax.jit(lambda s, k: trainer._rollout(s, hp, k)[0])
    traj = rollout(state, jax.random.key(1))
    update = jax.jit(trainer.update)

    # The batch the epochs consume, built the way `update` builds it.
    from fppo_jax.core.losses import Batch

    flat = lambda x: x.reshape((config.samples_per_update, *x.shape[2:]))  # noqa: E731
    n = traj.reward.shape
    batch = jax.tree.map(
        flat,
        Batch(
            traj.obs,
            traj.action,
            traj.log_prob,
            jnp.zeros(n),
            jnp.ones(n),
            jnp.ones(n),
            traj.distribution,
        ),
    )
    epochs = jax.jit(lambda s, b, k: trainer._epochs(s, hp, b, k))

    parts = {
        "environment alone": seconds_per_call(
            jax.jit(env_alone(env, config.num_envs, config.num_steps, 1)),
            jax.random.key(2),
            repeats=args.repeats,
        ),
        "rollout (policy + env)": seconds_per_call(
            rollout, state, jax.random.key(1), repeats=args.repeats
        ),
        "epochs (minibatch updates)": seconds_per_call(
            epochs, state, batch, jax.random.key(3), repeats=args.repeats
        ),
        "whole update": seconds_per_call(update, state, hp, repeats=args.repeats),
    }
    whole = parts["whole update"]
    lines = [
        *header("Where one update's time goes (CartPole, PureJaxRL's settings)"),
        "",
        f"Each part compiled and timed alone (best of 7 blocks of {args.repeats} calls); one "
        f"update is {config.samples_per_update} env steps. Parts timed alone include a call's "
        "dispatch, so they add up to more than the whole.",
        "",
        "| part | ms | share of an update |",
        "|---|---|---|",
        *[f"| {name} | {s * 1e3:.3f} | {s / whole:.0%} |" for name, s in parts.items()],
        "",
        f"Update throughput called one update at a time: {config.samples_per_update / whole:,.0f} "
        "env steps/s (a whole run in one compiled call is faster: see bench_cartpole.md).",
    ]
    print("\n".join(lines))
    write_result(output, lines)
    print(f"wrote {output}")


if __name__ == "__main__":
    main()
