"""MuJoCo tasks on MJX: an adapter for Brax environments, and Swimmer built on MJX itself.

Both keep gym's episode limit in their state and report it as truncation, separately from
the environment's own termination, so that the trainer bootstraps the one and not the other.
Brax and MJX are imported on first use: the classic tasks never pay for them.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import io
import warnings
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, cast

import jax
import jax.numpy as jnp
import mujoco

from fppo_jax.envs.core import Box, Step, Timed, key_shape, limited_step
from fppo_jax.errors import InvalidInput


def _import_quietly() -> None:
    """Import Brax and MJX without their import-time chatter.

    MJX prints that its optional Warp backend is missing, and Brax warns that its own
    pipelines are unmaintained; neither concerns MJX environments, and both would otherwise
    interleave with a run's progress lines.
    """
    chatter = io.StringIO()
    with (
        contextlib.redirect_stdout(chatter),
        contextlib.redirect_stderr(chatter),
        warnings.catch_warnings(),
    ):
        warnings.simplefilter("ignore")
        import brax.envs
        import brax.io.mjcf  # noqa: F401
        from mujoco import mjx  # noqa: F401


def is_brax_env(env: Any) -> bool:
    """Whether `env` is a Brax ``Env`` (checked without importing Brax if it is not loaded)."""
    module = type(env).__module__
    if not module.startswith("brax"):
        return False
    _import_quietly()
    from brax.envs.base import Env

    return isinstance(env, Env)


def _action_box(ctrl_range: Any, action_size: int) -> Box:
    """The actuators' control range, or [-1, 1] where the model leaves it unlimited."""
    low = [-1.0] * action_size
    high = [1.0] * action_size
    for i, (lo, hi) in enumerate(ctrl_range[:action_size]):
        if lo < hi:
            low[i], high[i] = float(lo), float(hi)
    return Box(tuple(low), tuple(high))


@dataclasses.dataclass(frozen=True, eq=False)
class BraxEnvironment:
    """A Brax ``Env`` (any backend; the registered tasks use ``mjx``) with an episode limit.

    Brax's ``done`` is the environment's termination (a fallen Hopper, say); reaching
    `episode_length` steps is truncation.
    """

    env: Any
    episode_length: int = 1000

    @property
    def backend(self) -> str:
        """What steps it, as records name it: "mjx", or Brax's own pipeline ("generalized")."""
        return str(getattr(self.env, "backend", "brax"))

    @functools.cached_property
    def observation_size(self) -> int:
        # Brax's own `observation_size` runs a reset op by op: 20 s for an MJX model on a CPU.
        state = jax.eval_shape(self.env.reset, key_shape())
        return int(state.obs.shape[-1])

    @property
    def action_space(self) -> Box:
        return _action_box(self.mj_model.actuator_ctrlrange, int(self.env.action_size))

    @property
    def mj_model(self) -> mujoco.MjModel:
        return self.env.sys.mj_model

    @property
    def dt(self) -> float:
        return float(self.env.dt)

    def qpos(self, state: Timed) -> jax.Array:
        """Generalised positions, for rendering."""
        return cast(jax.Array, state.inner.pipeline_state.q)

    def reset(self, key: jax.Array) -> tuple[Timed, jax.Array]:
        state = self.env.reset(key)
        return Timed(state, jnp.zeros((), jnp.int32)), state.obs.astype(jnp.float32)

    def step(self, key: jax.Array, state: Timed, action: jax.Array) -> tuple[Timed, Step]:
        inner = self.env.step(state.inner, action)
        return limited_step(state, inner, inner.obs, inner.reward, inner.done, self.episode_length)


def brax_environment(name: str, episode_length: int = 1000, **kwargs: Any) -> BraxEnvironment:
    """Brax's environment `name` on the MJX backend."""
    _import_quietly()
    from brax import envs

    if name not in envs._envs:
        raise InvalidInput(f"Brax has no environment {name!r}; it offers: " + ", ".join(envs._envs))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        env = envs.get_environment(name, backend="mjx", **kwargs)
    return BraxEnvironment(env, episode_length)


def swimmer_model() -> mujoco.MjModel:
    """gym's Swimmer model (as shipped with Brax): three capsules in a viscous fluid."""
    _import_quietly()
    from etils import epath

    path = epath.resource_path("brax") / "envs/assets/swimmer.xml"
    return mujoco.MjModel.from_xml_path(str(path))


@dataclasses.dataclass(frozen=True, eq=False)
class Swimmer:
    """gym's Swimmer (v2–v4 dynamics and reward) stepped by MJX.

    Brax's own Swimmer runs only on its ``generalized`` pipeline; MJX runs the MuJoCo model
    directly, fluid forces included. Reward: forward velocity of the front tip minus
    ``ctrl_cost_weight`` · ‖a‖²; observation: joint angles (positions excluded) and all
    velocities; no termination, truncation at `episode_length`.
    """

    mj_model: mujoco.MjModel = dataclasses.field(default_factory=swimmer_model)
    episode_length: int = 1000
    frame_skip: int = 4
    backend = "mjx"
    ctrl_cost_weight: float = 1e-4
    reset_noise_scale: float = 0.1

    def __post_init__(self) -> None:
        _import_quietly()
        from mujoco import mjx

        object.__setattr__(self, "_model", mjx.put_model(self.mj_model))

    if TYPE_CHECKING:  # set by __post_init__, and no field

        @property
        def _model(self) -> Any: ...  # mujoco.mjx.Model

    @property
    def observation_size(self) -> int:
        return int(self.mj_model.nq - 2 + self.mj_model.nv)

    @property
    def action_space(self) -> Box:
        return _action_box(self.mj_model.actuator_ctrlrange, int(self.mj_model.nu))

    @property
    def dt(self) -> float:
        return float(self.mj_model.opt.timestep) * self.frame_skip

    def qpos(self, state: Timed) -> jax.Array:
        return cast(jax.Array, state.inner.qpos)

    def reset(self, key: jax.Array) -> tuple[Timed, jax.Array]:
        from mujoco import mjx

        qpos_key, qvel_key = jax.random.split(key)
        m, scale = self.mj_model, self.reset_noise_scale
        noise: Callable[[jax.Array, int], jax.Array] = lambda key, n: jax.random.uniform(  # noqa: E731
            key, (n,), minval=-scale, maxval=scale
        )
        qpos = jnp.asarray(m.qpos0) + noise(qpos_key, m.nq)
        qvel = noise(qvel_key, m.nv)
        data = mjx.make_data(self._model).replace(qpos=qpos, qvel=qvel)
        return Timed(data, jnp.zeros((), jnp.int32)), self._observation(data)

    def step(self, key: jax.Array, state: Timed, action: jax.Array) -> tuple[Timed, Step]:
        from mujoco import mjx

        before = state.inner.qpos[0]
        data = state.inner.replace(ctrl=action)
        data = jax.lax.fori_loop(0, self.frame_skip, lambda _, d: mjx.step(self._model, d), data)
        velocity = (data.qpos[0] - before) / self.dt
        reward = velocity - self.ctrl_cost_weight * jnp.sum(jnp.square(action))
        steps = state.steps + 1
        return Timed(data, steps), Step(
            obs=self._observation(data),
            reward=reward.astype(jnp.float32),
            terminated=jnp.zeros((), bool),
            truncated=steps >= self.episode_length,
        )

    def _observation(self, data: Any) -> jax.Array:
        return jnp.concatenate([data.qpos[2:], data.qvel]).astype(jnp.float32)
