"""Pictures of a policy (fppo_jax.export.render): the image strip, the animation and the video it
writes from frames, what it refuses before any training, and an episode of a saved policy
rendered from the command line (with -m slow)."""

import jax
import numpy as np
import pytest

import fppo_jax
from fppo_jax import make_env
from fppo_jax.cli import main
from fppo_jax.errors import InvalidInput
from fppo_jax.export.render import (
    check_render_path,
    check_renderable,
    episode_positions,
    save_frames,
)


def test_frames_are_saved_as_an_mp4_played_at_the_environments_speed(tmp_path):
    frames = np.random.default_rng(0).integers(0, 256, (26, 240, 320, 3), dtype=np.uint8)
    video = save_frames(frames, tmp_path / "episode.mp4", dt=0.04)
    assert b"ftyp" in video.read_bytes()[:32]  # an MP4 container
    from imageio_ffmpeg import count_frames_and_secs

    assert count_frames_and_secs(video) == (26, pytest.approx(1.04, abs=0.05))


# Four MuJoCo programs compile: training, the deterministic and the stochastic evaluation, and
# the rendered episode.
@pytest.mark.slow
def test_eval_renders_an_episode_of_a_saved_policy_as_mp4(tmp_path, capsys):
    result = fppo_jax.train(
        "reacher",
        "ppo",
        backend="mjx",
        total_steps=64,
        num_envs=2,
        num_steps=32,
        num_minibatches=1,
        num_epochs=1,
    )
    result.save(tmp_path / "policy")
    video = tmp_path / "episode.mp4"
    flags = ["eval", "--checkpoint", str(tmp_path / "policy"), "--episodes", "1"]
    code = main([*flags, "--render", str(video)])
    if code == 2:
        error = capsys.readouterr().err
        assert "not rendered" in error and "MUJOCO_GL" in error
        pytest.skip(f"no OpenGL context on this machine: {error}")
    assert code == 0 and f"wrote {video}" in capsys.readouterr().out
    assert b"ftyp" in video.read_bytes()[:32]
    from imageio_ffmpeg import count_frames_and_secs

    # The start and 50 steps of 20 ms.
    assert count_frames_and_secs(video) == (51, pytest.approx(1.02, abs=0.05))


def test_a_png_is_a_strip_of_frames_spread_over_the_episode_and_a_gif_holds_every_frame(tmp_path):
    from PIL import Image

    # Frame i is filled with the value 10·i: which frames the strip took can be read back.
    frames = np.stack([np.full((6, 4, 3), 10 * i, np.uint8) for i in range(15)])
    strip = np.asarray(Image.open(save_frames(frames, tmp_path / "episode.png", dt=0.02)))
    assert strip.shape == (6, 4 * 8, 3)  # eight frames side by side
    taken = strip[0, ::4, 0] // 10
    assert taken.tolist() == [0, 2, 4, 6, 8, 10, 12, 14]  # the first, the last, evenly between
    short = np.asarray(Image.open(save_frames(frames[:3], tmp_path / "short.png", dt=0.02)))
    assert short.shape == (6, 4 * 3, 3)  # an episode shorter than the strip: every frame
    animation = Image.open(save_frames(frames, tmp_path / "episode.gif", dt=0.005))
    assert animation.n_frames == 15 and animation.info["duration"] == 20  # 5 ms shown as 20


def test_what_cannot_be_drawn_is_refused_before_any_training(tmp_path):
    with pytest.raises(InvalidInput, match=r"render to a \.png .* not episode\.webm"):
        check_render_path(tmp_path / "episode.webm")
    check_render_path(tmp_path / "made" / "episode.gif")  # its directory is made
    assert (tmp_path / "made").is_dir()
    for task in ("cartpole", "gymnax/Pendulum-v1"):
        with pytest.raises(InvalidInput, match="MuJoCo cannot render; --render takes a MuJoCo"):
            check_renderable(task)
    check_renderable("hopper")
    with pytest.raises(TypeError, match="is not a MuJoCo environment: nothing to render"):
        episode_positions(make_env("cartpole"), lambda obs: 0, jax.random.key(0), max_steps=4)
