"""Training throughput on CartPole with PureJaxRL's settings, one seed and vmapped seeds.

    python experiments/bench_cartpole.py [--seeds 8] [--repeats 3]

Measured side by side in one run: the environment alone (random actions in a jitted scan, the
same reset scheme as the trainer: the ceiling), then the whole training program as one
compiled call for one seed and for `--seeds` vmapped seeds. Compilation is timed apart from
running; each run figure is the best of `--repeats`. PureJaxRL's own figures, measured on the
same kind of machine (2-core CPU), are the reference the ratios are taken against.
Writes experiments/results/bench_cartpole.md.
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import purejaxrl_settings as pjr

from fppo_jax import make_train
from fppo_jax.envs import draw_resets, where_done

# PureJaxRL ppo.py on this kind of machine (shared/NOTES.md): 500k steps, compile ~5 s.
PUREJAXRL_ONE_SEED = 141_000
PUREJAXRL_EIGHT_SEEDS = 177_000


def env_alone(env, num_envs: int, num_steps: int, num_rollouts: int):
    """Random actions for num_rollouts × num_steps steps of num_envs environments."""

    def run(key: jax.Array) -> jax.Array:
        init_key, key = jax.random.split(key)
        state, _ = draw_resets(env, init_key, (num_envs,))

        def rollout(state, key):
            action_key, step_key, reset_key = jax.random.split(key, 3)
            shape = (num_steps, num_envs)
            actions = jax.random.randint(action_key, shape, 0, env.action_space.n)
            resets, _ = draw_resets(env, reset_key, shape)

            def step(state, inputs):
                keys, action, reset = inputs
                state, out = jax.vmap(env.step)(keys, state, action)
                return where_done(out.terminated | out.truncated, reset, state), out.reward

            state, rewards = jax.lax.scan(
                step, state, (jax.random.split(step_key, shape), actions, resets)
            )
            return state, rewards.sum()

        return jax.lax.scan(rollout, state, jax.random.split(key, num_rollouts))[1].sum()

    return run


def cpu_model() -> str:
    with open("/proc/cpuinfo") as f:
        names = [line.split(":", 1)[1].strip() for line in f if line.startswith("model name")]
    return names[0] if names else platform.processor()


def timed(fn, *args, repeats: int) -> tuple[float, float, object]:
    """(compile seconds, best run seconds, output) of jax.jit(fn)(*args)."""
    start = time.perf_counter()
    compiled = jax.jit(fn).lower(*args).compile()
    compile_seconds = time.perf_counter() - start
    best, out = float("inf"), None
    for _ in range(repeats):
        start = time.perf_counter()
        out = jax.block_until_ready(compiled(*args))
        best = min(best, time.perf_counter() - start)
    return compile_seconds, best, out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=8)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument(
        "--output", type=Path, default=Path(__file__).parent / "results" / "bench_cartpole.md"
    )
    args = parser.parse_args()

    env, config, hp = pjr.env(), pjr.config(), pjr.hp()
    steps = config.num_updates * config.samples_per_update
    trainer = make_train(config, env)
    keys = jax.random.split(jax.random.key(0), args.seeds)
    hps = jax.tree.map(lambda x: jnp.broadcast_to(x, (args.seeds, *x.shape)), hp)

    rows = []
    for name, fn, fn_args, runs in [
        (
            "environment alone, 1 × 4 envs",
            env_alone(env, config.num_envs, config.num_steps, config.num_updates),
            (jax.random.key(0),),
            1,
        ),
        (
            f"environment alone, {args.seeds} × 4 envs",
            env_alone(env, args.seeds * config.num_envs, config.num_steps, config.num_updates),
            (jax.random.key(0),),
            args.seeds,
        ),
        ("fppo-jax PPO, 1 seed", trainer, (jax.random.key(0), hp), 1),
        (f"fppo-jax PPO, {args.seeds} vmapped seeds", jax.vmap(trainer), (keys, hps), args.seeds),
    ]:
        compile_s, run_s, out = timed(fn, *fn_args, repeats=args.repeats)
        rate = runs * steps / run_s
        final = ""
        if isinstance(out, tuple):
            final = f"{float(np.mean(np.asarray(out[1].average_return)[..., -1])):.1f}"
        rows.append((name, compile_s, run_s, rate, final))
        print(
            f"{name:<36} compile {compile_s:5.1f} s  run {run_s:6.2f} s  {rate:>10,.0f}/s  {final}"
        )

    env_one, env_many, ours_one, ours_many = (r[3] for r in rows)
    flags = (f" --seeds {args.seeds}" if args.seeds != 8 else "") + (
        f" --repeats {args.repeats}" if args.repeats != 3 else ""
    )
    lines = [
        "# CartPole training throughput, PureJaxRL's settings",
        "",
        f"Machine: {cpu_model()}, {os.cpu_count()} cores, no GPU; jax {jax.__version__}; "
        f"{datetime.date.today()}.",
        "",
        f"Command: `python experiments/bench_cartpole.py{flags}`",
        "",
        f"Settings: CartPole-v1 (500-step episodes), {config.num_envs} envs × {config.num_steps} "
        f"steps, {config.num_epochs} epochs × {config.num_minibatches} minibatches, 64×64 tanh, "
        "lr 2.5e-4 annealed, entropy 0.01, no observation or reward normalisation; "
        f"{config.num_updates} updates = {steps:,} env steps per seed. The whole run is one "
        f"compiled call; run time is the best of {args.repeats}, compilation is timed apart.",
        "",
        "| what | compile (s) | run (s) | env steps/s | final average return |",
        "|---|---|---|---|---|",
        *[f"| {n} | {c:.1f} | {r:.2f} | {rate:,.0f} | {f} |" for n, c, r, rate, f in rows],
        "",
        "Ratios:",
        f"- 1 seed vs PureJaxRL's {PUREJAXRL_ONE_SEED:,} env steps/s: "
        f"**{ours_one / PUREJAXRL_ONE_SEED:.2f}×** (goal 1.2×); of the environment alone: "
        f"{ours_one / env_one:.2f}.",
        f"- {args.seeds} vmapped seeds vs PureJaxRL's {PUREJAXRL_EIGHT_SEEDS:,}: "
        f"**{ours_many / PUREJAXRL_EIGHT_SEEDS:.2f}×** (goal 1.2×); of the environment alone: "
        f"{ours_many / env_many:.2f}.",
        "",
        "PureJaxRL's figures were measured on this kind of machine (PureJaxRL `ppo.py`, patched "
        "only for gymnax 1.0's step signature); they are not re-measured here.",
    ]
    args.output.parent.mkdir(parents=True, exist_ok=True)
    args.output.write_text("\n".join(lines) + "\n")
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
