"""The escape speed on the same data (the paper's mechanism): after each epoch of one update, the
fraction of its batch in R+ ∪ R- under PPO, FPPO-LP and FPPO-QP, the three from the same state,
batch and minibatch order.

    python experiments/paper/escape_speed.py                  # CartPole, Acrobot, Hopper, Walker2d
    python experiments/paper/escape_speed.py \
        --tasks cartpole --seeds 2 --points 2 4 --results /tmp/e

For each task and seed, PPO trains from scratch (the task's `paper` preset). At each update
point the next rollout is collected once and each variant (Table 2's α and k) runs that
update's epochs on its batch, from the same parameters and in the same minibatch order,
recording the fraction after every epoch. The probed rollout is not trained on: PPO goes on
from where it left the environments. MuJoCo tasks run on `--backend` (default: auto).
Writes results/escape_speed.md and results/escape_speed/fractions.csv (one row per task, seed,
update, variant and epoch), which `figures.py` draws.
"""

from __future__ import annotations

import csv
import dataclasses
import functools
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from fppo_jax import make_env, make_train
from fppo_jax.core.config import describe, resolve_config
from fppo_jax.core.resolution import resolve_hyperparameters
from fppo_jax.envs import BACKENDS, MUJOCO_TASKS, choose_backend
from fppo_jax.stats.statistics import sample_std

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: shared modules

from common import (
    ESCAPE_FRACTIONS,
    ESCAPE_VARIANTS,
    add_record_flags,
    argument_parser,
    header,
    refuse_to_replace,
    write_result,
)


@dataclasses.dataclass(frozen=True)
class Measured:
    """One task's fractions, [seed, point, variant, epoch], and how they were made."""

    task: str
    backend: str
    points: tuple[int, ...]
    fractions: np.ndarray
    settings: dict[str, dict]
    description: str
    seconds: float


def measure(task: str, seeds: int, points: Sequence[int], backend: str) -> Measured:
    """PPO trains `seeds` runs of `task`; at each of `points` (updates done) every variant runs
    the next update's epochs on one batch collected from the same state."""
    start = time.perf_counter()
    chosen = choose_backend(task, backend)[0]
    env = make_env(task, chosen)
    config = resolve_config(task, None, {})
    if max(points) >= config.num_updates:
        raise ValueError(f"{task}: update points must be below its {config.num_updates} updates")
    trainer = make_train(config, env)
    resolved = [resolve_hyperparameters(variant, task) for variant in ESCAPE_VARIANTS]
    ppo = resolved[0][0]
    variants = jax.tree.map(lambda *x: jnp.stack(x), *[hp for hp, _ in resolved])

    @functools.partial(jax.jit, static_argnums=1)
    def train(states, updates: int):
        return jax.vmap(lambda s: trainer.run(s, ppo, updates)[0])(states)

    @jax.jit
    @jax.vmap
    def probe(state):
        rollout_key = jax.random.split(state.key, 3)[1]
        collected = trainer.collect(state, ppo, rollout_key)
        batch, envs = collected.batch, collected.envs
        by_variant = jax.vmap(trainer.escape_by_epoch, in_axes=(None, 0, None))
        return dataclasses.replace(state, envs=envs), by_variant(state, variants, batch)

    keys = jax.random.split(jax.random.key(0), seeds)
    states = jax.jit(jax.vmap(trainer.init, in_axes=(0, None)))(keys, ppo)
    fractions, done = [], 0
    for point in points:
        states = train(states, point - done) if point > done else states
        states, by_epoch = probe(states)
        fractions.append(np.asarray(by_epoch))
        done = point
        print(f"{task}: update {point} probed", flush=True)
    return Measured(
        task,
        chosen,
        tuple(points),
        np.stack(fractions, axis=1),
        {v: settings for v, (_, settings) in zip(ESCAPE_VARIANTS, resolved, strict=True)},
        describe(config, "paper"),
        time.perf_counter() - start,
    )


def write_fractions(measured: Sequence[Measured], path: Path) -> None:
    """One row per task, seed, update point, variant and epoch, as `common.read_fractions`
    reads them."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["task", "seed", "update", "variant", "epoch", "fraction"])
        for m in measured:
            for (seed, p, v, epoch), fraction in np.ndenumerate(m.fractions):
                variant = ESCAPE_VARIANTS[v]
                row = [m.task, seed, m.points[p], variant, epoch + 1, f"{fraction:.6f}"]
                writer.writerow(row)


def below_ppo(fractions: np.ndarray) -> list[float]:
    """For FPPO-LP and FPPO-QP, the share of (seed, point, epoch) where fewer samples are left
    in R+ ∪ R- than under PPO."""
    return [float(np.mean(fractions[:, :, v] < fractions[:, :, 0])) for v in (1, 2)]


def report(measured: Sequence[Measured]) -> list[str]:
    lines = [
        *header("Escape speed on the same data"),
        "- How: for each task and seed, PPO trains from scratch; at each update point the next "
        "rollout is collected once, and PPO, FPPO-LP and FPPO-QP (Table 2's α and k) each run "
        "that update's epochs on its batch from the same parameters, in the same minibatch "
        "order. The figure is the fraction of the batch in R+ ∪ R- after each epoch, mean ± "
        "sample std over seeds. The probed rollout is not trained on.",
        "",
        "## Summary",
        "",
        "Mean over seeds, update points and epochs; the last two columns are the share of "
        "(seed, update, epoch) where FPPO leaves fewer samples in R+ ∪ R- than PPO on the same "
        "batch.",
        "",
        "| task | backend | seeds × points | PPO | FPPO-LP | FPPO-QP | LP < PPO | QP < PPO |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for m in measured:
        means = m.fractions.mean(axis=(0, 1, 3))
        lp, qp = below_ppo(m.fractions)
        seeds, points = m.fractions.shape[:2]
        lines.append(
            f"| {m.task} | {m.backend} | {seeds} × {points} | "
            + " | ".join(f"{x:.2%}" for x in means)
            + f" | {lp:.0%} | {qp:.0%} |"
        )
    for m in measured:
        epochs = m.fractions.shape[-1]
        shown = sorted({1, 2, epochs // 2, epochs})
        alpha, k = m.settings["fppo-lp"]["alpha"], m.settings["fppo-qp"]["k"]
        lines += [
            "",
            f"## {m.task} ({m.backend}; FPPO-LP α = {alpha}, FPPO-QP k = {k})",
            "",
            f"{m.description}; {m.seconds:.0f} s. After epoch e, mean ± sample std over "
            f"{m.fractions.shape[0]} seeds:",
            "",
            "| update | variant | " + " | ".join(f"epoch {e}" for e in shown) + " |",
            "|---|---|" + "---|" * len(shown),
        ]
        for p, point in enumerate(m.points):
            for v, variant in enumerate(ESCAPE_VARIANTS):
                cells = [
                    f"{m.fractions[:, p, v, e - 1].mean():.2%} ± "
                    f"{sample_std(m.fractions[:, p, v, e - 1]):.2%}"
                    for e in shown
                ]
                lines.append(f"| {point} | {variant} | " + " | ".join(cells) + " |")
    return lines


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--tasks", nargs="+", default=["cartpole", "acrobot", "hopper", "walker2d"])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument(
        "--points", nargs="+", type=int, default=[5, 20, 40], help="updates done before a probe"
    )
    parser.add_argument("--backend", default="auto", choices=list(BACKENDS))
    add_record_flags(parser)
    args = parser.parse_args()
    fractions, path = args.results / ESCAPE_FRACTIONS, args.results / "escape_speed.md"
    refuse_to_replace([fractions, path], args.force)
    points = sorted(set(args.points))
    measured = [
        measure(task, args.seeds, points, args.backend if task in MUJOCO_TASKS else "auto")
        for task in args.tasks
    ]
    write_fractions(measured, fractions)
    write_result(path, report(measured))
    print(f"wrote {path} and {fractions}")


if __name__ == "__main__":
    main()
