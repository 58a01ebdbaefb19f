"""What training produces, and its files: :class:`TrainResult` of one run, :class:`SweepResult`
of a sweep, the paper's "max average return", and the JSON and CSV they are written as."""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from fppo_jax.checkpoint import save_policy
from fppo_jax.config import SYMBOLS, VARIANT_SPECIFIC
from fppo_jax.envs import Environment
from fppo_jax.files import write_atomically, write_json
from fppo_jax.policy import Policy
from fppo_jax.trainer import METRICS, TrainState


class TrainingDiverged(FloatingPointError):
    """The loss or the parameters became NaN or infinite."""

    def __init__(self, update: int, env_steps: int, checkpoint: str | None = None):
        """`update` counts from 1, as the progress lines do; `checkpoint` says where the last
        good checkpoint is, if any."""
        self.update, self.env_steps = update, env_steps
        kept = f" {checkpoint}." if checkpoint else ""
        super().__init__(
            f"training diverged at update {update} (after {env_steps:,} env steps): the loss or "
            f"the parameters became NaN or infinite.{kept} Lower the learning rate, or check the "
            "environment's observations and rewards."
        )


@dataclasses.dataclass
class TrainResult:
    """The outcome of :func:`train`.

    `metrics` maps each name of :data:`fppo_jax.trainer.METRICS` to one value per update.
    `policy(obs, key=None)` acts on raw observations (one or a batch): the most likely action
    without a key, a sample with one.
    """

    metrics: dict[str, np.ndarray]
    params: dict
    config: dict[str, Any]
    state: TrainState
    policy: Policy
    compile_seconds: float
    train_seconds: float
    env: Environment
    resumed_from: int = 0  # the update a resumed run started from its checkpoint
    stopped_at: int | None = None  # the update where a callback stopped training

    def write(self, directory: str | Path) -> None:
        """``summary.txt`` in `directory`, whole or not at all (``config.json`` and
        ``metrics.csv`` are written as training goes, by ``log_dir``)."""
        directory = Path(directory)
        directory.mkdir(parents=True, exist_ok=True)
        write_atomically(directory / "summary.txt", (self.summary() + "\n").encode())

    def save(self, directory: str | Path, *, overwrite: bool = False) -> Path:
        """Save the trained policy and the run's configuration in `directory`, for
        :func:`fppo_jax.load_policy` and ``fppo-jax eval --checkpoint`` (see
        :func:`fppo_jax.checkpoint.save_policy`); a saved policy already there is refused
        unless `overwrite`. Returns the directory."""
        record = {"config": self.config, "update": len(self.metrics["env_steps"])}
        return save_policy(directory, self.policy, record, overwrite=overwrite)

    def render(self, path: str | Path, *, seed: int = 0, max_steps: int = 1000) -> Path:
        """Save one episode of the trained policy (the most likely actions) on a MuJoCo task
        as a ``.png`` image strip or a ``.gif``; see :mod:`fppo_jax.render`."""
        from fppo_jax.render import render_policy

        return render_policy(self.env, self.policy, path, seed=seed, max_steps=max_steps)

    def summary(self) -> str:
        """A few lines: the run, its speed, its returns and its escape-speed diagnostic."""
        m, c = self.metrics, self.config
        steps = int(m["env_steps"][-1])
        returns = m["average_return"]
        settings = ", ".join(f"{k} = {c[k]:g}" for k in ("alpha", "k", "delta") if k in c)
        settings = ", ".join(filter(None, [settings, f"epsilon = {c['epsilon']:g}"]))
        samples = c["num_envs"] * c["num_steps"]
        trained = steps - self.resumed_from * samples
        speed = f"{trained / self.train_seconds:,.0f} env steps/s" if trained else "nothing left"
        resumed = f", resumed at update {self.resumed_from}" if self.resumed_from else ""
        if self.stopped_at is not None:
            resumed += f", stopped by the callback at update {self.stopped_at}"
        lines = [
            f"{c['variant']} on {c['env']} ({settings}), seed {c['seed']}",
            f"  updates   {len(returns)} × {samples:,} samples = {steps:,} env steps "
            f"(preset {c.get('preset', 'paper')}){resumed}",
            f"  time      compile {self.compile_seconds:.1f} s, train {self.train_seconds:.1f} s "
            f"({speed})",
        ]
        if np.isfinite(returns).any():
            best = int(np.nanargmax(returns))
            lines.append(
                f"  return    final {returns[-1]:.1f}, max {returns[best]:.1f} at "
                f"{int(m['env_steps'][best]):,} steps (mean of the last 100 episodes)"
            )
        else:
            lines.append("  return    no episode finished")
        lines += [
            f"  escape    in R+ ∪ R- after the update: {np.mean(m['negative_fraction_after']):.2%}"
            f" of samples (first epoch: {np.mean(m['negative_fraction_before']):.2%}), mean "
            f"distance past the bound {np.mean(m['negative_distance_after']):.3f}",
            f"  last      policy loss {m['policy_loss'][-1]:.4f}, value loss "
            f"{m['value_loss'][-1]:.4f}, entropy {m['entropy'][-1]:.3f}, approx KL "
            f"{m['approx_kl'][-1]:.4f}, clip fraction {m['clip_fraction'][-1]:.3f}",
        ]
        return "\n".join(lines)


def labels(settings: Sequence[Mapping[str, Any]]) -> list[str]:
    """Each setting in a few characters, e.g. ``fppo-lp α=1.3``: the variant, its own α, k or δ,
    and whatever else differs between the settings."""
    keys = dict.fromkeys(k for s in settings for k in s if k != "variant")
    varying = {k for k in keys if len({s.get(k) for s in settings}) > 1}
    shown = [k for k in keys if k in VARIANT_SPECIFIC or k in varying]
    return [
        " ".join([str(s["variant"]), *[f"{SYMBOLS.get(k, k)}={s[k]:g}" for k in shown if k in s]])
        for s in settings
    ]


@dataclasses.dataclass
class SweepResult:
    """Every run of a sweep: `runs[i]` is run i's setting and seed, `metrics[name][i]` its
    per-update values, `diverged[i]` the update (from 1) where it diverged, or 0."""

    settings: list[dict[str, Any]]
    seeds: list[int]
    runs: list[dict[str, Any]]
    metrics: dict[str, np.ndarray]
    diverged: np.ndarray
    config: dict[str, Any]
    compile_seconds: float
    train_seconds: float

    def setting_metrics(self, index: int) -> dict[str, np.ndarray]:
        """Metrics of setting `index`, [seed, update]."""
        rows = [i for i, run in enumerate(self.runs) if run["setting"] == index]
        return {name: values[rows] for name, values in self.metrics.items()}

    def table(self) -> str:
        """Table 1 style, one row per setting: max average return (SPEC §2) and more, Markdown."""
        lines = [
            "| setting | max average return | at env steps | final average return "
            "| in R± after update |",
            "|---|---|---|---|---|",
        ]
        for index, name in enumerate(labels(self.settings)):
            m = self.setting_metrics(index)
            best, std, at = max_average_return(m["average_return"])
            final = nanmean(m["average_return"][:, -1]) if m["average_return"].size else np.nan
            steps = int(m["env_steps"][0, at]) if at >= 0 else 0
            lines.append(
                f"| {name} | {best:.1f} ± {std:.1f} | {steps:,} | {final:.1f} | "
                f"{np.mean(m['negative_fraction_after']):.2%} |"
            )
        return "\n".join(lines)

    def write(self, directory: str | Path, metrics: Sequence[str] = METRICS) -> None:
        """`curves.csv` (one row per run and update, a column per name in `metrics`) and
        `sweep.json` (everything else), each whole or not at all. Fewer metrics make a smaller
        file to keep."""
        directory = Path(directory)
        directory.mkdir(parents=True, exist_ok=True)
        keys = list(dict.fromkeys(k for s in self.settings for k in s))
        text = io.StringIO(newline="")
        writer = csv.writer(text)
        writer.writerow(["run", "seed", *keys, "update", *metrics])
        for i, run in enumerate(self.runs):
            setting = self.settings[run["setting"]]
            head = [i, run["seed"], *[setting.get(k, "") for k in keys]]
            for u in range(self.metrics["env_steps"].shape[1]):
                values = [self.metrics[name][i, u].item() for name in metrics]
                writer.writerow([*head, u + 1, *values])
        write_atomically(directory / "curves.csv", text.getvalue().encode())
        record = {
            "settings": self.settings,
            "seeds": self.seeds,
            "runs": self.runs,
            "diverged": self.diverged.tolist(),
            "config": self.config,
            "compile_seconds": self.compile_seconds,
            "train_seconds": self.train_seconds,
        }
        write_json(directory / "sweep.json", record)

    @classmethod
    def read(cls, directory: str | Path) -> SweepResult:
        """What :meth:`write` wrote: the metrics its `curves.csv` holds."""
        directory = Path(directory)
        for name in ("sweep.json", "curves.csv"):
            if not (directory / name).is_file():
                raise FileNotFoundError(f"{directory / name} not found: not a sweep's output")
        record = json.loads((directory / "sweep.json").read_text())
        with open(directory / "curves.csv", newline="") as f:
            reader = csv.DictReader(f)
            rows = list(reader)
        num_runs = len(record["runs"])
        num_updates = len(rows) // max(num_runs, 1)
        metrics = {
            name: np.array([float(r[name]) for r in rows]).reshape(num_runs, num_updates)
            for name in METRICS
            if name in reader.fieldnames
        }
        metrics["env_steps"] = metrics["env_steps"].astype(np.int64)
        return cls(
            settings=record["settings"],
            seeds=record["seeds"],
            runs=record["runs"],
            metrics=metrics,
            diverged=np.asarray(record["diverged"]),
            config=record["config"],
            compile_seconds=record["compile_seconds"],
            train_seconds=record["train_seconds"],
        )


def max_average_return(average_return: np.ndarray) -> tuple[float, float, int]:
    """SPEC §2 on [seed, update]: the maximum over updates of the seed-mean curve, the std across
    seeds at that update, and the update's index (NaN, NaN, −1 if no episode ever finished)."""
    curve = nanmean(average_return, axis=0)
    if not np.isfinite(curve).any():
        return np.nan, np.nan, -1
    best = int(np.nanargmax(curve))
    return float(curve[best]), float(np.nanstd(average_return[:, best])), best


def nanmean(x: np.ndarray, axis: int | None = None) -> np.ndarray:
    with warnings.catch_warnings():
        # All-NaN slices (no episode finished yet in any seed) are meant to stay NaN.
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmean(x, axis=axis)
