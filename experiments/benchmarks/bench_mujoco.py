"""Training throughput on a MuJoCo task, per backend: the environment alone, this trainer, and
Brax's PPO on MJX.

    # CPU: native against MJX
    python experiments/benchmarks/bench_mujoco.py --env hopper --shape paper
    # Table 1's sweep
    python experiments/benchmarks/bench_mujoco.py --env hopper --shape paper --runs 25
    # CPU, MJX's best shape
    python experiments/benchmarks/bench_mujoco.py --env hopper --num-envs 128
    python experiments/benchmarks/bench_mujoco.py --env ant --preset massive --backends mjx  # GPU

Measured side by side in one run, on the same task, environment count and samples per update,
for each backend (`--backends`, default native and mjx):
(a) the environment alone: random actions in a jitted scan, vmapped over the environments,
    restarting ended episodes as (b) does (from one reset state per environment per rollout on
    MJX; native environments reset themselves);
(b) this trainer (`fppo_jax.train`, PPO), the whole run one compiled call, compile timed apart;
(c) on MJX, Brax's own trainer, `brax.training.agents.ppo.train`, with the same environments,
    unroll length, minibatches, epochs and 64×64 networks; its figure is its own
    ``training/sps`` for the last of its three training epochs, evaluation off (the first two
    epochs both compile: under JAX 0.10 Brax's epoch function is compiled again for the
    second call).
`--shape paper` times the paper preset's own update (8 environments × 256 steps, 32
minibatches × 10 epochs); otherwise the unroll, minibatches and epochs are the flags'.
`--mjx-updates` times fewer updates on MJX, which is slow on a CPU. `--runs R` trains R runs
side by side as one sweep in (b) (Table 1 trains 25 per task) and steps R × N environments in
(a); (c) is then left out. Writes
experiments/results/bench_mujoco_<env>[_<R>runs]_<N>envs_<platform>.md.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp

import fppo_jax
from fppo_jax.core.config import describe_update, preset_config
from fppo_jax.envs import make_env

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: shared modules

from common import (
    add_record_flags,
    argument_parser,
    env_alone,
    header,
    machine,
    refuse_to_replace,
    write_result,
)


def timed(fn, *args) -> tuple[float, float]:
    """(compile seconds, run seconds) of jax.jit(fn)(*args)."""
    start = time.perf_counter()
    compiled = jax.jit(fn).lower(*args).compile()
    compile_seconds = time.perf_counter() - start
    start = time.perf_counter()
    jax.block_until_ready(compiled(*args))
    return compile_seconds, time.perf_counter() - start


def brax_ppo(env_name: str, config, total_steps: int) -> tuple[float, float]:
    """(c): Brax's PPO trainer on the same task and shape; (its third epoch's sps, wall s)."""
    from brax.training.agents.ppo import networks as ppo_networks
    from brax.training.agents.ppo import train as ppo

    if not hasattr(jax, "device_put_replicated"):
        # Brax 0.14 calls this, which JAX 0.10 removed; one device is all it is given here.
        def device_put_replicated(x, devices):
            return jax.tree.map(
                lambda a: jax.device_put(jnp.stack([a] * len(devices)), devices[0]), x
            )

        jax.device_put_replicated = device_put_replicated

    reports = []
    start = time.perf_counter()
    ppo.train(
        environment=make_env(env_name, "mjx").env,
        num_timesteps=total_steps,
        episode_length=1000,
        num_envs=config.num_envs,
        unroll_length=config.num_steps,
        batch_size=config.num_envs // config.num_minibatches,
        num_minibatches=config.num_minibatches,
        num_updates_per_batch=config.num_epochs,
        learning_rate=3e-4,
        entropy_cost=0.0,
        discounting=0.99,
        gae_lambda=0.95,
        clipping_epsilon=0.2,
        max_grad_norm=0.5,
        normalize_observations=True,
        # Its `bootstrap_on_timeout=True` needs an info key its own wrappers do not set in
        # 0.14; bootstrapping or not costs the same, so the default is timed.
        network_factory=functools.partial(
            ppo_networks.make_ppo_networks,
            policy_hidden_layer_sizes=(64, 64),
            value_hidden_layer_sizes=(64, 64),
        ),
        num_evals=4,
        run_evals=False,
        progress_fn=lambda step, metrics: reports.append(dict(metrics)),
    )
    wall = time.perf_counter() - start
    rates = [float(m["training/sps"]) for m in reports if "training/sps" in m]
    return rates[-1], wall


def measure(args: argparse.Namespace, backend: str, config, updates: int) -> list[tuple]:
    """Rows (a), (b) and, on MJX, (c) of one backend: (name, steps/s, compile s, ratio)."""
    config = dataclasses.replace(config, total_steps=updates * config.samples_per_update)
    total_steps = config.total_steps
    env = make_env(args.env, backend)
    label = {"mjx": "MJX", "native": "native"}[backend]
    alone = env_alone(env, args.runs * config.num_envs, config.num_steps, config.num_updates)
    alone_compile, alone_seconds = timed(alone, jax.random.key(0))
    alone_rate = args.runs * total_steps / alone_seconds
    print(f"{label} (a) env alone: {alone_rate:,.0f} steps/s", flush=True)

    fields = ("num_envs", "num_steps", "num_minibatches", "num_epochs", "resets_per_rollout")
    shape = {name: getattr(config, name) for name in fields}
    if args.runs == 1:
        ours = fppo_jax.train(
            args.env, "ppo", backend=backend, total_steps=total_steps, preset=args.preset, **shape
        )
    else:
        ours = fppo_jax.sweep(
            args.env,
            {"variant": ["ppo"]},
            seeds=args.runs,
            backend=backend,
            total_steps=total_steps,
            preset=args.preset,
            **shape,
        )
    ours_rate = args.runs * total_steps / ours.train_seconds
    how = "`train`" if args.runs == 1 else f"`sweep` of {args.runs} runs"
    print(f"{label} (b) fppo-jax: {ours_rate:,.0f} steps/s", flush=True)
    rows = [
        (f"{label} (a) environment alone, random actions", alone_rate, alone_compile, "—"),
        (
            f"{label} (b) fppo-jax {how} (PPO)",
            ours_rate,
            ours.compile_seconds,
            f"(b)/(a) = {ours_rate / alone_rate:.2f}",
        ),
    ]
    if backend == "mjx" and not args.skip_brax and args.runs == 1:
        brax_rate, brax_wall = brax_ppo(args.env, config, total_steps)
        print(f"MJX (c) Brax PPO: {brax_rate:,.0f} steps/s ({brax_wall:.1f} s in all)", flush=True)
        rows.append(
            (
                "MJX (c) Brax `ppo.train`",
                brax_rate,
                None,
                f"(b)/(c) = {ours_rate / brax_rate:.2f}",
            )
        )
    return rows


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--env", default="hopper")
    parser.add_argument("--preset", default="paper", choices=["paper", "massive"])
    parser.add_argument(
        "--shape", choices=["paper"], help="the paper preset's own update shape, not the flags'"
    )
    parser.add_argument("--backends", nargs="+", default=["native", "mjx"])
    parser.add_argument("--num-envs", type=int, help="default: the preset's")
    parser.add_argument("--num-steps", type=int, default=16, help="unroll length per update")
    parser.add_argument("--minibatches", type=int, default=4)
    parser.add_argument("--epochs", type=int, default=4)
    parser.add_argument("--updates", type=int, default=40, help="updates timed per trainer")
    parser.add_argument("--mjx-updates", type=int, help="updates timed on MJX (default: --updates)")
    parser.add_argument("--skip-brax", action="store_true", help="leave out (c)")
    parser.add_argument(
        "--runs", type=int, default=1, help="runs trained side by side as one sweep (no (c))"
    )
    add_record_flags(parser)
    args = parser.parse_args()

    shape = {"num_steps": args.num_steps, "num_minibatches": args.minibatches}
    shape["num_epochs"] = args.epochs
    if args.preset == "massive" or args.shape == "paper":
        shape = {}  # the preset's own shape
    if args.num_envs:
        shape["num_envs"] = args.num_envs
    probe = preset_config(args.preset, **shape)
    config = preset_config(
        args.preset, total_steps=probe.samples_per_update, resets_per_rollout=1, **shape
    )
    platform_name = jax.devices()[0].platform
    runs = f"{args.runs}runs_" if args.runs > 1 else ""
    path = args.results / f"bench_mujoco_{args.env}_{runs}{config.num_envs}envs_{platform_name}.md"
    refuse_to_replace([path], args.force)
    print(f"{args.env}: {describe_update(config)} on {machine()}", flush=True)
    rows, timed_updates = [], {}
    for backend in args.backends:
        updates = args.mjx_updates if backend == "mjx" and args.mjx_updates else args.updates
        timed_updates[backend] = updates
        rows += measure(args, backend, config, updates)
    rates = {row[0].split(" ")[0]: row[1] for row in rows if "(b)" in row[0]}
    if {"native", "MJX"} <= set(rates):
        ratio = rates["native"] / rates["MJX"]
        rows.append(("native (b) / MJX (b)", None, None, f"{ratio:.1f}×"))

    steps = ", ".join(
        f"{updates * config.samples_per_update:,} env steps on {backend}"
        for backend, updates in timed_updates.items()
    )
    sweep_shape, runs_of = "", ""
    if args.runs > 1:
        sweep_shape = f" per run, {args.runs} runs as one sweep (env steps/s count them all)"
        runs_of = f"{args.runs} runs × "
    title = f"Training throughput on {args.env}, {runs_of}{config.num_envs} environments: "
    lines = [
        *header(title + " and ".join(args.backends)),
        f"- Shape: preset {args.preset}, {describe_update(config)}{sweep_shape}; {steps}; "
        "on MJX one reset "
        "state per environment per rollout in (a) and (b), Brax's auto-reset in (c); native "
        "environments reset themselves",
        "",
        "| | env steps/s | compile (s) | ratio |",
        "|---|---|---|---|",
    ]
    for name, rate, compile_seconds, ratio in rows:
        shown_rate = "" if rate is None else f"{rate:,.0f}"
        shown = "in epochs 1–2" if compile_seconds is None else f"{compile_seconds:.1f}"
        lines.append(f"| {name} | {shown_rate} | {'' if rate is None else shown} | {ratio} |")
    write_result(path, lines)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
