"""Pictures of a policy acting on a MuJoCo task: an image strip (PNG), an animation (GIF) or
a video (MP4, encoded by the ffmpeg that imageio-ffmpeg brings).

The episode runs in JAX (MJX); the frames are drawn by MuJoCo's own renderer from the
recorded joint positions, which needs an OpenGL context. Without a display that is EGL or
OSMesa, chosen with ``MUJOCO_GL`` before MuJoCo is first imported (importing fppo_jax first
sets ``egl`` on a Linux machine with no display, unless the variable is set).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from fppo_jax.envs import Environment
from fppo_jax.errors import FppoError, InvalidInput
from fppo_jax.store.files import writable_directory


class RenderingUnavailable(FppoError, RuntimeError):
    """MuJoCo could not create an OpenGL context on this machine."""


def check_render_path(path: str | Path) -> None:
    """Raise InvalidInput unless `path` names a format that :func:`save_frames` writes, in a
    directory that can be written (made if missing)."""
    if Path(path).suffix not in (".png", ".gif", ".mp4"):
        raise InvalidInput(
            "render to a .png (image strip), a .gif (animation) or an .mp4 (video), not "
            f"{Path(path).name}"
        )
    writable_directory(Path(path).parent)


def check_renderable(env: str) -> None:
    """Raise InvalidInput, before any training, for a task MuJoCo cannot draw: the classic tasks
    and gymnax's environments, which have no MuJoCo model."""
    from fppo_jax.envs import MUJOCO_TASKS, TASKS

    if (env in TASKS and env not in MUJOCO_TASKS) or env.startswith("gymnax/"):
        raise InvalidInput(
            f"{env} is a classic (gymnax) task, which MuJoCo cannot render; --render takes a "
            f"MuJoCo task ({', '.join(MUJOCO_TASKS)}, or brax/, playground/ and native/ ids)"
        )


def episode_positions(
    env: Environment, policy: Callable[[jax.Array], jax.Array], key: jax.Array, max_steps: int
) -> np.ndarray:
    """Joint positions at the start and after each step of one episode, until it ends or
    `max_steps`; `policy` maps one observation to one action."""
    if not hasattr(env, "qpos"):
        raise TypeError(f"{type(env).__name__} is not a MuJoCo environment: nothing to render")
    reset_key, steps_key = jax.random.split(key)

    @jax.jit
    def run() -> tuple[jax.Array, jax.Array]:
        state, obs = env.reset(reset_key)

        def step(carry: tuple[Any, ...], key: jax.Array) -> tuple[tuple[Any, ...], tuple[Any, ...]]:
            state, obs, ended = carry
            state, out = env.step(key, state, policy(obs))
            return (state, out.obs, ended | out.terminated | out.truncated), (
                env.qpos(state),
                ended,
            )

        carry = (state, obs, jnp.zeros((), bool))
        _, (qpos, ended) = jax.lax.scan(step, carry, jax.random.split(steps_key, max_steps))
        return jnp.concatenate([env.qpos(state)[None], qpos]), ended

    qpos, ended = run()
    length = int(np.argmax(np.asarray(ended))) if bool(np.any(ended)) else max_steps
    return np.asarray(qpos[: length + 1])


def render_frames(
    model: mujoco.MjModel, qpos: np.ndarray, width: int = 320, height: int = 240
) -> np.ndarray:
    """One RGB frame per row of `qpos`, seen by a camera that follows the first body."""
    try:
        renderer = mujoco.Renderer(model, height, width)
    except Exception as error:
        raise RenderingUnavailable(
            f"MuJoCo could not create an OpenGL context ({error}). Without a display, set "
            "MUJOCO_GL=egl (GPU or Mesa EGL) or MUJOCO_GL=osmesa (software) before Python "
            "starts."
        ) from error
    data = mujoco.MjData(model)
    camera = mujoco.MjvCamera()
    camera.type = mujoco.mjtCamera.mjCAMERA_TRACKING
    camera.trackbodyid = 1
    camera.distance = 3.0 * _body_extent(model, data)
    camera.elevation = -30.0
    camera.azimuth = 90.0
    frames = []
    with renderer:
        for q in qpos:
            data.qpos[:] = q
            mujoco.mj_forward(model, data)
            renderer.update_scene(data, camera)
            frames.append(renderer.render())
    return np.stack(frames)


def _body_extent(model: mujoco.MjModel, data: mujoco.MjData) -> float:
    """How far the robot's geoms reach from its first body, at the model's rest pose (the
    model's own extent counts the floor)."""
    mujoco.mj_forward(model, data)
    own = model.geom_bodyid > 0
    reach = np.linalg.norm(data.geom_xpos[own] - data.xpos[1], axis=1) + model.geom_rbound[own]
    return max(float(reach.max(initial=0.0)), 0.25)


def save_frames(frames: np.ndarray, path: str | Path, dt: float, strip_length: int = 8) -> Path:
    """`.gif` and `.mp4`: every frame, played at the environment's speed; `.png`:
    `strip_length` frames spread evenly over the episode, side by side."""
    from PIL import Image

    check_render_path(path)
    path = Path(path)
    if path.suffix == ".mp4":
        import imageio.v2 as imageio

        imageio.mimwrite(path, list(frames), fps=1 / dt)
    elif path.suffix == ".gif":
        images = [Image.fromarray(frame) for frame in frames]
        duration = max(round(1000 * dt), 20)  # GIF players round below 20 ms up
        images[0].save(path, save_all=True, append_images=images[1:], duration=duration, loop=0)
    else:
        index = np.linspace(0, len(frames) - 1, min(strip_length, len(frames))).round()
        Image.fromarray(np.concatenate(frames[index.astype(int)], axis=1)).save(path)
    return path


def drawable(env: Environment, task: str) -> Environment:
    """`env`, or for a task run in native MuJoCo (whose state lives in envpool) the same task on
    MJX, whose model replays the episode: the observations are the same vectors on both, except
    Ant's (the policy refuses those, saying so)."""
    if getattr(env, "backend", None) != "native":
        return env
    from fppo_jax.envs import make_env

    return make_env(task, "mjx")


def render_policy(
    env: Environment,
    policy: Callable[[jax.Array], jax.Array],
    path: str | Path,
    *,
    seed: int = 0,
    max_steps: int = 1000,
    width: int = 320,
    height: int = 240,
) -> Path:
    """Run `policy` for one episode of the MuJoCo task `env` and save it to `path` (`.png`
    strip, `.gif` or `.mp4`). Raises :class:`RenderingUnavailable` where no OpenGL context can
    be made; the suffix is checked before anything runs."""
    check_render_path(path)
    model: Any = getattr(env, "mj_model", None)
    if model is None:
        raise TypeError(f"{type(env).__name__} is not a MuJoCo environment: nothing to render")
    qpos = episode_positions(env, policy, jax.random.key(seed), max_steps)
    frames = render_frames(model, qpos, width, height)
    return save_frames(frames, path, float(getattr(env, "dt", 0.05)))
