"""``train(env, variant, alpha)``: one run, checked before compiling, with progress and results."""

from __future__ import annotations

import dataclasses
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import numpy as np

from fppo_jax.checkpoint import Checkpoints, ConfigMismatch, check_same_run
from fppo_jax.config import (
    HYPERPARAMETER_DEFAULTS,
    Hyperparameters,
    TrainConfig,
    hyperparameters,
    preset_config,
)
from fppo_jax.distributed import is_main_process, make_mesh
from fppo_jax.envs import TASKS, Environment, as_environment
from fppo_jax.execution import (
    PROGRESS_LINES,
    Program,
    Progress,
    compile_program,
    execute,
    reporter,
    updates_per_call,
)
from fppo_jax.metric_log import MetricLog
from fppo_jax.objectives import DEFAULTS as VARIANT_DEFAULTS
from fppo_jax.objectives import VARIANTS
from fppo_jax.policy import Policy
from fppo_jax.trainer import Trainer, TrainState, make_train

# The paper's Table 2: FPPO-LP's α and FPPO-QP's k per task (to be moved to fppo_jax.config).
TABLE2: dict[str, dict[str, float]] = {
    "cartpole": {"alpha": 1.3, "k": 0.4},
    "acrobot": {"alpha": 1.3, "k": 0.4},
    "mountaincar": {"alpha": 1.3, "k": 0.4},
    "hopper": {"alpha": 1.3, "k": 0.2},
    "walker2d": {"alpha": 1.3, "k": 0.1},
    "halfcheetah": {"alpha": 1.3, "k": 0.4},
    "ant": {"alpha": 1.3, "k": 0.4},
    "reacher": {"alpha": 1.1, "k": 0.4},
    "swimmer": {"alpha": 1.1, "k": 0.1},
}

CONFIG_FIELDS = tuple(field.name for field in dataclasses.fields(TrainConfig))


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


def train(
    env: str | Environment | Any = "cartpole",
    variant: str = "fppo-lp",
    alpha: float | None = None,
    *,
    k: float | None = None,
    delta: float | None = None,
    epsilon: float = 0.2,
    seed: int = 0,
    total_steps: int | None = None,
    preset: str = "paper",
    progress: bool | Callable[[Progress], None] = False,
    checkpoint_dir: str | Path | None = None,
    resume: bool = False,
    checkpoint_every: int | None = None,
    keep: int = 3,
    log_dir: str | Path | None = None,
    devices: int | None = None,
    **overrides: Any,
) -> TrainResult:
    """Train one policy with `variant` on `env` and return its metrics, parameters and policy.

    `env` is a registered name (:data:`fppo_jax.envs.TASKS`), a gymnax environment or an
    :class:`~fppo_jax.envs.Environment`. For a registered task, FPPO-LP's α and FPPO-QP's k
    default to the paper's Table 2 and `total_steps` to the paper's budget. `preset` names the
    run's shape (:data:`fppo_jax.config.PRESETS`): ``"paper"`` (SPEC §2: 8 environments × 256
    steps) or ``"massive"`` (2048 environments × 16 steps, for a GPU). `overrides` are
    :class:`TrainConfig` fields (``num_envs``, ``num_steps``, ``num_minibatches``, …) and
    optimisation settings (``learning_rate``, ``gamma``, ``gae_lambda``, ``entropy_coef``,
    ``value_coef``, ``max_grad_norm``). Everything is checked before compiling.

    `progress`: ``True`` shows a progress bar on a terminal, or prints a line per chunk of
    updates on stderr otherwise; a callable receives a :class:`Progress`; ``False`` (with no
    checkpoints and no log) runs the whole training as one compiled call.

    `checkpoint_dir`: save the full training state there every `checkpoint_every` updates
    (default: a twentieth of the run), keeping the newest `keep` (see
    :mod:`fppo_jax.checkpoint`). With ``resume=True`` the run continues from the newest intact
    checkpoint there, if any, and ends exactly as if it had never stopped; a checkpoint of a
    differently configured run is refused with the differing fields named. Without `resume`,
    a directory that already holds checkpoints is refused, so that none is overwritten.
    `log_dir`: write ``metrics.csv`` and TensorBoard event files there as training goes.

    `devices`: how many of the devices JAX sees (default: all) share the run; its environments
    are split across them and the parameters replicated (see :mod:`fppo_jax.distributed`). In a
    multi-process run only process 0 reports progress and writes the log.

    Raises :class:`TrainingDiverged` if the loss or the parameters stop being finite (the last
    good checkpoint stays on disk).
    """
    config, hp, settings = _resolve(
        env, variant, alpha, k, delta, epsilon, total_steps, preset, overrides
    )
    mesh = make_mesh(devices, config.num_envs)
    if checkpoint_dir is not None and jax.process_count() > 1:
        raise ValueError("checkpoints are written by single-process runs only")
    environment = as_environment(env)
    name = env_name(env, environment)
    run_config = {**settings, "env": name, "seed": seed, "preset": preset}
    run_config.update(dataclasses.asdict(config))
    checkpoints, _ = open_checkpoints(
        checkpoint_dir, resume, checkpoint_every, keep, "train", run_config
    )
    if checkpoints:
        per_call = checkpoint_every_updates(checkpoint_every, config)
    else:
        chunked = progress or log_dir is not None
        per_call = updates_per_call(config.num_updates, PROGRESS_LINES if chunked else 1)
    if not is_main_process():
        # The same program on every process (so the same chunks), but one voice.
        progress, log_dir = False, None
    trainer = make_train(config, environment)
    key = jax.random.key(seed)
    start = None
    if checkpoints and resume:
        restored = checkpoints.restore(jax.eval_shape(trainer.init, key, hp))
        if restored is not None:
            start = (restored.state, restored.curves)
    if progress is True:
        shape = describe(config, preset) + (f" on {mesh.size} devices" if mesh else "")
        print(f"{variant} on {name}: {shape}; compiling…", file=sys.stderr)
    try:
        program = compile_program(trainer, key, hp, per_call, mesh)
        with reporter(progress, f"{variant} on {name}") as report:
            state, metrics, train_seconds = _run_one(
                program, key, hp, start, report, checkpoints, run_config, log_dir
            )
    finally:
        if checkpoints:
            checkpoints.close()
    return TrainResult(
        metrics=metrics,
        params=state.params,
        config=run_config,
        state=state,
        policy=make_policy(trainer, state),
        compile_seconds=program.compile_seconds,
        train_seconds=train_seconds,
        env=environment,
        resumed_from=int(start[0].update) if start else 0,
    )


def open_checkpoints(
    directory: str | Path | None,
    resume: bool,
    every: int | None,
    keep: int,
    kind: str,
    run_config: dict[str, Any],
) -> tuple[Checkpoints | None, dict[str, Any] | None]:
    """The checkpoints of a `kind` ("train" or "sweep") and the newest one's record, checked
    against this run before anything is compiled."""
    if directory is None:
        if resume or every is not None:
            raise ValueError(
                f"{'resume' if resume else 'checkpoint_every'} needs a checkpoint directory"
            )
        return None, None
    checkpoints = Checkpoints(directory, keep)
    record = checkpoints.latest_record()
    try:
        if record is not None and not resume:
            raise ValueError(
                f"{checkpoints.directory} already holds checkpoints; pass resume=True (--resume) "
                "to continue that run, or choose another directory"
            )
        if record is not None and record.get("kind") != kind:
            raise ConfigMismatch(
                f"{checkpoints.directory} holds the checkpoints of a {record.get('kind')}, "
                f"not of a {kind}"
            )
        if record is not None:
            check_same_run(record["config"], run_config, checkpoints.directory)
    except ValueError:
        checkpoints.close()
        raise
    return checkpoints, record


def checkpoint_every_updates(every: int | None, config: TrainConfig) -> int:
    """Updates between checkpoints (and so per compiled call): `every`, checked, or a
    twentieth of the run."""
    if every is None:
        return updates_per_call(config.num_updates, PROGRESS_LINES)
    if isinstance(every, bool) or not isinstance(every, int) or every < 1:
        raise ValueError(f"checkpoint_every must be a positive number of updates, got {every!r}")
    return min(every, config.num_updates)


def _run_one(
    program: Program,
    key: jax.Array,
    hp: Hyperparameters,
    start: tuple[TrainState, dict[str, np.ndarray]] | None,
    report: Callable[[Progress], None] | None,
    checkpoints: Checkpoints | None,
    run_config: dict[str, Any],
    log_dir: str | Path | None,
) -> tuple[TrainState, dict[str, np.ndarray], float]:
    """Execute `program`, checking, checkpointing and logging after every chunk."""
    trainer = program.trainer
    samples = trainer.config.samples_per_update
    log = MetricLog(log_dir, start[1] if start else None) if log_dir is not None else None
    saved: list[int] = []

    def after_chunk(state: TrainState, metrics: dict[str, np.ndarray]) -> None:
        index = int(state.nonfinite_update)
        if index >= 0:
            where = None
            if checkpoints:
                checkpoints.wait()
                where = (
                    f"The last good checkpoint, at update {saved[-1]}, is in "
                    f"{checkpoints.directory}"
                    if saved
                    else "No checkpoint was written before it"
                )
            raise TrainingDiverged(index + 1, (index + 1) * samples, where)
        if checkpoints:
            update = int(state.update)
            record = {"kind": "train", "config": run_config, "update": update}
            checkpoints.save(update, state, metrics, record, make_policy(trainer, state))
            saved.append(update)
        if log:
            log.write(metrics)

    if start is not None:
        saved.append(int(start[0].update))
    try:
        return execute(program, key, hp, start=start, report=report, after_chunk=after_chunk)
    finally:
        if log:
            log.close()


def _resolve(
    env: Any,
    variant: str,
    alpha: float | None,
    k: float | None,
    delta: float | None,
    epsilon: float,
    total_steps: int | None,
    preset: str,
    overrides: dict[str, Any],
) -> tuple[TrainConfig, Hyperparameters, dict[str, Any]]:
    """Defaults from the task table, then every check, before anything is compiled."""
    if variant not in VARIANTS:
        raise ValueError(f"unknown variant {variant!r}; valid variants: {', '.join(VARIANTS)}")
    optimisation = {
        name: overrides.pop(name) for name in HYPERPARAMETER_DEFAULTS if name in overrides
    }
    config = resolve_config(
        env, total_steps, overrides, also_valid=tuple(HYPERPARAMETER_DEFAULTS), preset=preset
    )
    table2 = TABLE2.get(env) if isinstance(env, str) else None
    if table2 and variant == "fppo-lp" and alpha is None:
        alpha = table2["alpha"]
    if table2 and variant == "fppo-qp" and k is None:
        k = table2["k"]
    hp = hyperparameters(variant, epsilon=epsilon, alpha=alpha, k=k, delta=delta, **optimisation)
    o = hp.objective
    settings: dict[str, Any] = {"variant": variant, "epsilon": _as_float(o.epsilon)}
    settings.update({name: _as_float(getattr(o, name)) for name in VARIANT_DEFAULTS[variant]})
    settings.update({name: _as_float(getattr(hp, name)) for name in HYPERPARAMETER_DEFAULTS})
    return config, hp, settings


def resolve_config(
    env: Any,
    total_steps: int | None,
    overrides: dict[str, Any],
    also_valid: tuple[str, ...] = (),
    preset: str = "paper",
) -> TrainConfig:
    """The checked TrainConfig of `preset` and `overrides`, with the task's step budget by
    default."""
    if isinstance(env, str) and env not in TASKS:
        raise ValueError(f"unknown environment {env!r}; registered: {', '.join(TASKS)}")
    unknown = sorted(set(overrides) - set(CONFIG_FIELDS))
    if unknown:
        raise ValueError(
            f"unknown setting {', '.join(unknown)}; valid: "
            + ", ".join([*CONFIG_FIELDS, *also_valid])
        )
    values = dict(overrides)
    if total_steps is not None:
        values["total_steps"] = total_steps
    elif "total_steps" not in values:
        task = TASKS.get(env) if isinstance(env, str) else None
        values["total_steps"] = task.total_steps if task else TrainConfig.total_steps
    return preset_config(preset, **values)


def _as_float(x: jax.Array) -> float:
    # The shortest decimal that round-trips the float32, so that 1.3 is reported as 1.3.
    return float(str(np.asarray(x)[()]))


def describe(config: TrainConfig, preset: str | None = None) -> str:
    """One run's length and shape, in words."""
    prefix = "" if preset is None else f"preset {preset}, "
    return f"{prefix}{config.num_updates} updates × {describe_update(config)}"


def describe_update(config: TrainConfig) -> str:
    """One update's shape, in words."""
    return (
        f"{config.samples_per_update:,} samples ({config.num_envs} envs × {config.num_steps} "
        f"steps), {config.num_minibatches} minibatches × {config.num_epochs} epochs"
    )


def env_name(env: Any, environment: Environment) -> str:
    return env if isinstance(env, str) else type(getattr(environment, "env", environment)).__name__


def make_policy(trainer: Trainer, state: TrainState) -> Policy:
    """The policy of `state`, on its own (see :class:`~fppo_jax.policy.Policy`)."""
    config = trainer.config
    return Policy(
        params=state.params["policy"],
        obs_stats=state.obs_stats if config.normalize_observations else None,
        action_space=trainer.env.action_space,
        hidden_sizes=config.hidden_sizes,
    )
