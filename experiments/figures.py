"""The figures README.md shows, drawn from recorded results into results/figures/.

    python experiments/figures.py [--out DIR] [--recompute]

- `objectives.png`: every variant's surrogate and slope against the ratio for A > 0 and A < 0,
  R+ and R- shaded (the paper's Figs. 1 and 3). Computed; it takes seconds.
- `table1_classic.png`: Table 1's classic-control learning curves (5 variants, mean ± std over
  5 seeds), from `results/table1_classic/<task>/`, which `table1_classic.py` writes.
- `escape_speed.png`: the share of one batch in R+ ∪ R- after each epoch under PPO, FPPO-LP and
  FPPO-QP, from the same states and samples (as `notebooks/escape_speed.ipynb` measures it),
  from `results/escape_speed/fractions.csv`. `--recompute` measures it again and rewrites the
  CSV: PPO trains 40 updates on CartPole for each of 8 seeds, then each state's next update
  runs 20 epochs (twice the paper's 10, to see the trend) under each variant. One to two
  minutes on a 2-core CPU.
- `table1_mujoco.png`: Table 1's MuJoCo learning curves, only when `table1_mujoco.py` has
  recorded some (`results/table1_mujoco_<platform>/<task>/`, a GPU job); none are yet.

Nothing is trained without `--recompute`.
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import jax
import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure

from fppo_jax import TrainConfig, hyperparameters, make_env, make_train
from fppo_jax.plots import plot_curves, plot_escape_speed, plot_objectives
from fppo_jax.results import SweepResult

RESULTS = Path(__file__).resolve().parent / "results"
ESCAPE_CSV = RESULTS / "escape_speed" / "fractions.csv"
ESCAPE_VARIANTS = ("ppo", "fppo-lp", "fppo-qp")  # with Table 2's α and k
CLASSIC_TASKS = ("cartpole", "acrobot", "mountaincar")
DPI = 100


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=RESULTS / "figures")
    parser.add_argument(
        "--recompute", action="store_true", help=f"measure the escape speed again into {ESCAPE_CSV}"
    )
    args = parser.parse_args()

    if args.recompute:
        write_escape_speed(measure_escape_speed(), ESCAPE_CSV)
        print(f"wrote {ESCAPE_CSV}")
    figures = {
        "objectives.png": plot_objectives(),
        "table1_classic.png": plot_sweeps([RESULTS / "table1_classic" / t for t in CLASSIC_TASKS]),
        "escape_speed.png": plot_escape_speed(read_escape_speed(ESCAPE_CSV), ESCAPE_VARIANTS),
    }
    mujoco = sorted(path.parent for path in RESULTS.glob("table1_mujoco*/*/curves.csv"))
    if mujoco:
        figures["table1_mujoco.png"] = plot_sweeps(mujoco)
    args.out.mkdir(parents=True, exist_ok=True)
    for name, fig in figures.items():
        fig.savefig(args.out / name, dpi=DPI)
        plt.close(fig)
        print(f"wrote {args.out / name}")


def plot_sweeps(directories: list[Path]) -> Figure:
    """The learning curves of each recorded sweep, side by side."""
    fig, axes = plt.subplots(
        1, len(directories), figsize=(4 * len(directories), 3.1), layout="constrained"
    )
    for ax, directory in zip(np.atleast_1d(axes), directories, strict=True):
        plot_curves(SweepResult.read(directory), ax=ax)
    return fig


def measure_escape_speed(
    seeds: int = 8, warmup_steps: int = 40 * 2048, epochs: int = 20
) -> np.ndarray:
    """[seed, variant, epoch]: PPO trains `warmup_steps` on CartPole for each seed; from each
    state, the next update's batch after each of its `epochs` under each of
    :data:`ESCAPE_VARIANTS`, the same samples and minibatch order for all three."""
    env = make_env("cartpole")
    warmup = make_train(TrainConfig(total_steps=warmup_steps), env)
    keys = jax.random.split(jax.random.key(0), seeds)
    states, _ = jax.jit(jax.vmap(warmup, in_axes=(0, None)))(keys, hyperparameters("ppo"))
    probe = make_train(TrainConfig(total_steps=warmup_steps, num_epochs=epochs), env)
    hps = jax.tree.map(
        lambda *x: jnp.stack(x), *[hyperparameters(variant) for variant in ESCAPE_VARIANTS]
    )
    by_variant = jax.vmap(probe.escape_by_epoch, in_axes=(None, 0))  # one state, every variant
    return np.asarray(jax.jit(jax.vmap(by_variant, in_axes=(0, None)))(states, hps))


def write_escape_speed(fractions: np.ndarray, path: Path) -> None:
    """One row per seed, variant and epoch."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["seed", "variant", "epoch", "fraction_in_negative_regions"])
        for (seed, v, epoch), fraction in np.ndenumerate(fractions):
            writer.writerow([seed, ESCAPE_VARIANTS[v], epoch + 1, f"{fraction:.6f}"])


def read_escape_speed(path: Path) -> np.ndarray:
    """What :func:`write_escape_speed` wrote, [seed, variant, epoch]."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    seeds = 1 + max(int(r["seed"]) for r in rows)
    fractions = np.array([float(r["fraction_in_negative_regions"]) for r in rows])
    return fractions.reshape(seeds, len(ESCAPE_VARIANTS), -1)


if __name__ == "__main__":
    main()
