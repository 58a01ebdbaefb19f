"""What :func:`~fppo_jax.run.api.train` produces: :class:`TrainResult`, one run's metrics, policy
and record, its summary, and the policy saved or rendered."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np

from fppo_jax.core.networks import Params
from fppo_jax.core.policy import Policy
from fppo_jax.core.resolution import VARIANT_SPECIFIC
from fppo_jax.core.trainer import TrainState
from fppo_jax.envs import Environment, backend_name, resets_itself
from fppo_jax.store.files import write_atomically
from fppo_jax.store.saved_policy import PolicyOrigin, save_policy


@dataclasses.dataclass
class TrainResult:
    """The outcome of :func:`train`.

    `metrics` maps each name of :data:`fppo_jax.core.trainer.METRICS` to one value per update.
    `policy(obs, key=None)` acts on raw observations (one or a batch): the most likely action
    without a key, a sample with one.
    """

    metrics: dict[str, np.ndarray]
    params: Params
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
        :func:`fppo_jax.store.saved_policy.save_policy`); a saved policy already there is refused
        unless `overwrite`. Returns the directory."""
        record = PolicyOrigin(config=self.config, update=len(self.metrics["env_steps"]))
        return save_policy(directory, self.policy, record, overwrite=overwrite)

    def render(self, path: str | Path, *, seed: int = 0, max_steps: int = 1000) -> Path:
        """Save one episode of the trained policy (the most likely actions) on a MuJoCo task
        as a ``.png`` image strip, a ``.gif`` or an ``.mp4``; see :mod:`fppo_jax.export.render` (a
        native MuJoCo run is drawn on MJX, by :func:`~fppo_jax.export.render.drawable`)."""
        from fppo_jax.export.render import drawable, render_policy

        env = drawable(self.env, self.config["env"])
        return render_policy(env, self.policy, path, seed=seed, max_steps=max_steps)

    def summary(self) -> str:
        """A few lines: the run, its speed, its returns and its escape-speed diagnostic."""
        m, c = self.metrics, self.config
        steps = int(m["env_steps"][-1])
        returns = m["average_return"]
        own = (c.get("surrogates") or {}).get(c["variant"], {}).get("hyperparameters", {})
        shown = dict.fromkeys((*VARIANT_SPECIFIC, *own))
        settings = ", ".join(f"{k} = {c[k]:g}" for k in shown if k in c)
        settings = ", ".join(filter(None, [settings, f"epsilon = {c['epsilon']:g}"]))
        samples = c["num_envs"] * c["num_steps"]
        trained = steps - self.resumed_from * samples
        speed = f"{trained / self.train_seconds:,.0f} env steps/s" if trained else "nothing left"
        backend = backend_name(c.get("backend"))  # a MuJoCo run's, which physics stepped it
        resumed = f", resumed at update {self.resumed_from}" if self.resumed_from else ""
        if resumed and resets_itself(self.env):
            resumed += " in fresh environments"
        if self.stopped_at is not None:
            resumed += f", stopped by the callback at update {self.stopped_at}"
        shape = ", ".join(filter(None, [f"preset {c.get('preset', 'paper')}", backend]))
        lines = [
            f"{c['variant']} on {c['env']} ({settings}), seed {c['seed']}",
            f"  updates   {len(returns)} × {samples:,} samples = {steps:,} env steps "
            f"({shape}){resumed}",
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
