"""Where a vmapped run's time goes, operation by operation, from XLA's own trace.

    python experiments/profiles/profile_ops.py [--workload purejaxrl|paper] [--seeds 8] [--steps N]

One whole run (`--seeds` vmapped seeds, one compiled call) is traced with `jax.profiler`.
Each operation XLA's CPU runtime executed is charged its own time (its span less the operations
it ran inside it, with the end of an asynchronous run) and attributed to the part of the update
it was compiled from, by the trainer's named scopes (rollout, advantages, epochs: shuffle,
minibatches, gradient, optimizer; escape), and to its kind (matrix products, sorts, gathers,
element-wise fusions and the rest). Tracing adds a fixed cost to every operation, which
inflates the many small ones: the shares are a guide to where time goes, and the untraced
run's time is stated beside them.
Writes experiments/results/profile_ops_<workload>_<seeds>seeds.md.
"""

from __future__ import annotations

import collections
import math
import re
import sys
import tempfile
from pathlib import Path

import jax
import jax.numpy as jnp

from fppo_jax import make_train
from fppo_jax.core.config import Hyperparameters
from fppo_jax.core.losses import Batch
from fppo_jax.core.trainer import Trainer, TrainState

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: shared modules

import purejaxrl_settings as pjr
from common import (
    add_record_flags,
    argument_parser,
    header,
    refuse_to_replace,
    seconds,
    write_result,
)

# The trainer's named scopes: an operation belongs to the innermost of them on its name path.
PARTS = (
    "rollout",
    "advantages",
    "epochs",
    "shuffle",
    "minibatches",
    "gradient",
    "optimizer",
    "escape",
)
KINDS = (
    ("matrix products", re.compile(r"^(ynn_fusion|dot|.*convolution)")),
    ("sorts", re.compile(r"^sort")),
    ("gathers and scatters", re.compile(r"^.*(gather|scatter|dynamic-slice|dynamic-update)")),
    ("concatenations and copies", re.compile(r"^(.*concatenate|copy|wrapped_copy|transpose)")),
    ("loops and conditionals", re.compile(r"^(while|cond|conditional|call)")),
    ("element-wise fusions and reductions", re.compile(r".")),
)
# The runtime's own events: dispatching operations and waiting on its threads.
RUNTIME = ("ThunkExecutor::Execute", "SlinkyThreadPool::Await")
OUTSIDE = "outside the named parts (the update's bookkeeping, loop carries)"


def parts(hlo: str) -> dict[str, str]:
    """The part of the update each instruction of the optimised program `hlo` was compiled
    from: the trainer's scopes on its JAX name path (e.g. ``epochs / gradient``), or where XLA
    kept no name for it, those of the instruction that runs its computation."""
    computation, where, scopes, caller = "", {}, {}, {}
    for line in hlo.splitlines():
        header = re.match(r"^(?:ENTRY )?%?([\w.-]+) \(", line)
        if header:
            computation = header.group(1)
            continue
        instruction = re.match(r"^\s*(?:ROOT )?%?([\w.-]+) = ", line)
        if not instruction:
            continue
        name = instruction.group(1)
        where[name] = computation
        op_name = re.search(r'op_name="([^"]*)"', line)
        if op_name:
            path = [re.sub(r"^(transpose\(|jvp\()+|\)+$", "", c) for c in op_name[1].split("/")]
            named = list(dict.fromkeys(c for c in path if c in PARTS))
            if named:
                scopes[name] = " / ".join(named)
        for called in re.findall(r"(?:calls|body|condition|to_apply)=%?([\w.-]+)", line):
            caller[called] = name
        for branches in re.findall(r"branch_computations=\{([^}]*)\}", line):
            for called in re.findall(r"%?([\w.-]+)", branches):
                caller[called] = name

    def part(name: str) -> str:
        while name not in scopes and where.get(name) in caller:
            name = caller[where[name]]
        return scopes.get(name, OUTSIDE)

    return {name: part(name) for name in where}


def kind_of(name: str) -> str:
    return next(kind for kind, pattern in KINDS if pattern.match(name))


def self_times(trace: jax.profiler.ProfileData) -> collections.Counter:
    """Each operation's own time (ns) over the trace's XLA runtime threads."""
    own: collections.Counter = collections.Counter()
    for plane in trace.planes:
        for line in plane.lines:
            if not line.name.startswith("tf_XLAEigen"):
                continue
            events = sorted(
                ((e.start_ns, e.duration_ns, e.name) for e in line.events),
                key=lambda e: (e[0], -e[1]),
            )
            stack: list[tuple[float, float, str]] = []
            for start, duration, name in events:
                while stack and stack[-1][0] + stack[-1][1] <= start:
                    stack.pop()
                if stack:
                    own[stack[-1][2]] -= duration
                own[name] += duration
                stack.append((start, duration, name))
    return own


def table(title: str, totals: collections.Counter, whole: float) -> list[str]:
    rows = [f"| {title} | ms | share |", "|---|---|---|"]
    for name, ns in totals.most_common():
        rows.append(f"| {name} | {ns / 1e6:,.1f} | {ns / whole:.1%} |")
    return rows


def matmul_flops_per_step(trainer: Trainer) -> int:
    """The floating-point operations of one minibatch step's matrix products: the forward pass
    of every layer of the policy and value function (2·B·in·out each) and the backward passes
    (twice that, less the first layers' input gradients, which nothing needs)."""
    params = trainer.networks.init(jax.random.key(0), trainer.env.observation_size)
    kernels = [
        (jax.tree_util.keystr(path), leaf.shape)
        for path, leaf in jax.tree_util.tree_leaves_with_path(params)
        if path[-1].key == "kernel"
    ]
    flops = {name: 2 * trainer.config.minibatch_size * math.prod(shape) for name, shape in kernels}
    first_layers = sum(f for name, f in flops.items() if "Dense_0" in name)
    return 3 * sum(flops.values()) - first_layers


def epochs_rate(
    trainer: Trainer, keys: jax.Array, hps: Hyperparameters, repeats: int = 20
) -> tuple[float, float]:
    """One update's epochs of minibatch steps alone, vmapped over the seeds of `keys` and
    `hps`, `repeats` times in one compiled call so that the call's own cost is spread: (seconds
    per update, their matrix products' FLOPs per second)."""
    config = trainer.config
    state = jax.jit(jax.vmap(trainer.init))(keys, hps)
    batch = jax.jit(jax.vmap(lambda s, h, k: trainer.collect(s, h, k).batch))(state, hps, keys)

    def repeated(state: TrainState, hp: Hyperparameters, batch: Batch, key: jax.Array):
        def once(total: jax.Array, key: jax.Array) -> tuple[jax.Array, None]:
            params, _, losses, _, _ = trainer._epochs(state, hp, batch, key)
            # Everything the epochs compute reaches the result, so none of it is left out.
            leaves = [jnp.sum(leaf) for leaf in jax.tree.leaves(params)]
            return total + jnp.sum(losses) + sum(leaves), None

        return jax.lax.scan(once, jnp.zeros(()), jax.random.split(key, repeats))[0]

    program = jax.jit(jax.vmap(repeated)).lower(state, hps, batch, keys).compile()
    best = min(seconds(lambda: program(state, hps, batch, keys)) for _ in range(5)) / repeats
    steps = config.num_epochs * config.num_minibatches
    return best, len(keys) * steps * matmul_flops_per_step(trainer) / best


def large_matmul_rate(size: int = 1024) -> float:
    """FLOPs per second of one `size` × `size` matrix product: what this machine's matrix
    products reach when they are large."""
    a = jax.random.normal(jax.random.key(0), (size, size))
    product = jax.jit(jnp.matmul).lower(a, a).compile()
    return 2 * size**3 / min(seconds(lambda: product(a, a)) for _ in range(20))


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--workload", choices=sorted(pjr.WORKLOADS), default="purejaxrl")
    parser.add_argument("--seeds", type=int, default=8)
    parser.add_argument("--steps", type=int, default=100_000, help="env steps per seed")
    add_record_flags(parser)
    args = parser.parse_args()
    out = args.results / f"profile_ops_{args.workload}_{args.seeds}seeds.md"
    refuse_to_replace([out], args.force)

    env, config, hp = pjr.fppo(args.workload, args.steps)
    trainer = make_train(config, env)
    hps = jax.tree.map(lambda x: jnp.broadcast_to(x, (args.seeds, *x.shape)), hp)
    keys = jax.random.split(jax.random.key(0), args.seeds)
    compiled = jax.jit(jax.vmap(trainer)).lower(keys, hps).compile()
    part_of = parts(compiled.as_text())
    untraced = min(seconds(lambda: compiled(keys, hps)) for _ in range(3))
    epochs_seconds, flop_rate = epochs_rate(trainer, keys, hps)
    reference_rate = large_matmul_rate()

    with tempfile.TemporaryDirectory() as folder:
        with jax.profiler.trace(folder):
            jax.block_until_ready(compiled(keys, hps))
        (path,) = Path(folder).rglob("*.xplane.pb")
        own = self_times(jax.profiler.ProfileData.from_file(str(path)))

    by_part: collections.Counter = collections.Counter()
    by_kind: collections.Counter = collections.Counter()
    by_both: collections.Counter = collections.Counter()
    for event, ns in own.items():
        # An operation run asynchronously ends in an event of its own, "end: <name>".
        name = event.removeprefix("end: ")
        if name in RUNTIME:
            part, kind = "the runtime", "dispatching and waiting"
        else:
            part, kind = part_of.get(name, OUTSIDE), kind_of(name)
        by_part[part] += ns
        by_kind[kind] += ns
        by_both[f"{part}: {kind}"] += ns
    whole = sum(own.values())

    seeds_vmapped = "one seed" if args.seeds == 1 else f"the {args.seeds} seeds vmapped"
    lines = [
        *header(f"Where a vmapped run's time goes: {pjr.WORKLOADS[args.workload]['title']}"),
        f"- {args.seeds} vmapped seed{'s' if args.seeds > 1 else ''} × {args.steps:,} env steps, "
        "one compiled call: "
        f"{untraced:.2f} s untraced (best of 3, {args.seeds * args.steps / untraced:,.0f} env "
        f"steps/s). The traced run's operations took {whole / 1e9:.2f} s of thread time in all "
        "(two runtime threads; tracing inflates small operations).",
        f"- One update's epochs alone ({config.num_epochs} × {config.num_minibatches} "
        f"minibatch steps of {config.minibatch_size} samples, {seeds_vmapped}), "
        f"untraced (20 in one call): {epochs_seconds * 1e3:.2f} ms each. Their matrix products "
        f"alone ({matmul_flops_per_step(trainer):,} FLOPs a step and seed: the policy's and value "
        f"function's forward and backward passes) divided by that time: "
        f"**{flop_rate / 1e9:.0f} GFLOP/s**; one 1024 × 1024 matrix product runs at "
        f"{reference_rate / 1e9:.0f} GFLOP/s here.",
        "",
        *table("part of the update", by_part, whole),
        "",
        *table("kind of operation", by_kind, whole),
        "",
        "The ten largest (part: kind):",
        "",
        *table("part: kind", collections.Counter(dict(by_both.most_common(10))), whole),
    ]
    write_result(out, lines)
    print("\n".join(lines))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
