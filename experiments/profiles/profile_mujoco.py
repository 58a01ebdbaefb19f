"""Where an MJX update's time goes beyond the environment's own, and what running each update
inside a `lax.cond` costs.

    python experiments/profiles/profile_mujoco.py [--env hopper] [--num-envs 128] [--updates 20]
        [--minibatches 4] [--repeats 3]

At the shape of bench_mujoco.py's MJX rows (16-step unrolls, 4 minibatches × 4 epochs, one reset
state per environment per rollout, PPO; `--minibatches 16` at 2,048 environments is the
`massive` preset's), each arm one compiled program of `--updates` updates of one run,
interleaved, best of `--repeats`:
- the environment alone, random actions (bench_mujoco.py's (a));
- the same, each environment's first reset state reused for the whole run instead of one drawn
  afresh per rollout, as Brax's auto-reset does (what bench_mujoco.py's (c) pays for resets);
- the rollout alone: the policy acting and the environments stepping, the parameters fixed;
- the whole update, as `Trainer.run` runs it (a loop of the updates left of the run);
- the whole update inside a `lax.cond` in a loop of the chunk's length, as `Trainer.run` ran it
  before (the `cond` skipped updates past the run's end).
The difference between two arms is what the second adds. Writes
experiments/results/profile_mujoco_<env>_<N>envs_<platform>.md.
"""

from __future__ import annotations

import dataclasses
import functools
import sys
from pathlib import Path

import jax
import jax.numpy as jnp

from fppo_jax import hyperparameters, make_train
from fppo_jax.core.config import describe_update, preset_config
from fppo_jax.core.trainer import METRICS, Metrics, Trainer
from fppo_jax.envs import make_env

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: shared modules

from common import (
    add_record_flags,
    argument_parser,
    best_interleaved,
    env_alone,
    header,
    refuse_to_replace,
    write_result,
)


class InCond(Trainer):
    """The trainer with each update in a `lax.cond`, as `Trainer.run` was before."""

    def run(self, state, hp, num_updates):
        def step(state, _):
            active = state.update < self.config.num_updates
            return jax.lax.cond(active, self.update, self._past_end, state, hp)

        return jax.lax.scan(step, state, None, length=num_updates)

    def _past_end(self, state, hp):
        nan = jnp.asarray(jnp.nan, jnp.float32)
        return state, Metrics(jnp.asarray(-1, jnp.int32), *[nan] * (len(METRICS) - 1))


def rollouts_alone(trainer: Trainer, updates: int):
    """`updates` rollouts from a state, its parameters fixed; the rewards' sum."""

    def run(state, hp):
        def rollout(state, _):
            key, rollout_key = jax.random.split(state.key)
            trajectory, envs = trainer._rollout(state, hp, rollout_key)
            return dataclasses.replace(state, envs=envs, key=key), trajectory.reward.sum()

        return jax.lax.scan(rollout, state, None, length=updates)

    return run


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--env", default="hopper")
    parser.add_argument("--num-envs", type=int, default=128)
    parser.add_argument("--updates", type=int, default=20)
    parser.add_argument("--minibatches", type=int, default=4)
    parser.add_argument("--repeats", type=int, default=3)
    add_record_flags(parser)
    args = parser.parse_args()
    platform = jax.devices()[0].platform
    path = args.results / f"profile_mujoco_{args.env}_{args.num_envs}envs_{platform}.md"
    refuse_to_replace([path], args.force)

    shape = {"num_envs": args.num_envs, "num_steps": 16, "num_epochs": 4}
    shape["num_minibatches"] = args.minibatches
    samples = args.num_envs * shape["num_steps"]
    config = preset_config(
        "paper", total_steps=args.updates * samples, resets_per_rollout=1, **shape
    )
    env = make_env(args.env, "mjx")
    trainer = make_train(config, env)
    in_cond = InCond(trainer.config, trainer.env, trainer.networks)
    hp = hyperparameters("ppo")
    state = jax.jit(trainer.init)(jax.random.key(0), hp)
    run = functools.partial(Trainer.run, num_updates=args.updates)
    arms = {
        "the environment alone": (env_alone(env, args.num_envs, 16, args.updates), (state.key,)),
        "the environment alone, its first reset states reused": (
            env_alone(env, args.num_envs, 16, args.updates, fresh_resets=False),
            (state.key,),
        ),
        "the rollout alone": (rollouts_alone(trainer, args.updates), (state, hp)),
        "the whole update (`Trainer.run`)": (functools.partial(run, trainer), (state, hp)),
        "the whole update inside a `lax.cond`": (functools.partial(run, in_cond), (state, hp)),
    }
    programs = {}
    for name, (fn, inputs) in arms.items():
        compiled = jax.jit(fn).lower(*inputs).compile()
        programs[name] = functools.partial(compiled, *inputs)
        print(f"compiled {name}", flush=True)
    best = best_interleaved(programs, args.repeats)

    alone = best["the environment alone"]
    lines = [
        *header(f"Where an MJX update's time goes: {args.env}, {args.num_envs} environments"),
        f"- Shape: {describe_update(config)}, one reset state per environment per rollout, "
        f"PPO; {args.updates} updates of one run per compiled call, arms interleaved, best of "
        f"{args.repeats}",
        "",
        "| arm | per update (ms) | env steps/s | beyond the environment alone (ms) |",
        "|---|---|---|---|",
        *[
            f"| {name} | {1000 * wall / args.updates:.1f} | "
            f"{args.updates * samples / wall:,.0f} | {1000 * (wall - alone) / args.updates:+.1f} |"
            for name, wall in best.items()
        ],
    ]
    write_result(path, lines)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
