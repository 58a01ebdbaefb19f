"""What importing loads: the package nothing, training none of the optional or heavy parts
(checkpoints, statistics, plots, the other environment families), ``--help`` no trainer; and
every public name is still there."""

import json
import pkgutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import fppo_jax

ROOT = Path(__file__).resolve().parents[1]
OPTIONAL = ["envpool", "gymnasium", "mujoco_playground", "wandb", "onnx", "onnxruntime"]
TRAINING = ["orbax", "scipy", "matplotlib", "brax", "mujoco", "tensorboardX", *OPTIONAL]
TRAINER = ["flax", "optax", "orbax", "scipy", "matplotlib"]


def loaded(code: str) -> set[str]:
    """The top-level packages in sys.modules after `code`, in a fresh process."""
    report = "import json, sys; print(json.dumps(sorted({m.split('.')[0] for m in sys.modules})))"
    done = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code) + "\n" + report],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    )
    return set(json.loads(done.stdout.splitlines()[-1]))


@pytest.mark.parametrize(
    "code, absent",
    [
        ("import fppo_jax", ["jax", *TRAINING]),
        ("from fppo_jax import train, sweep, TrainResult, load_policy", TRAINING),
        (
            """
            from fppo_jax.cli import main
            try:
                main(["train", "--help"])
            except SystemExit:
                pass
            """,
            TRAINER + OPTIONAL,
        ),
    ],
    ids=["package", "train", "help"],
)
def test_only_what_is_used_is_imported(code, absent):
    assert loaded(code).isdisjoint(absent)


def test_every_public_name_is_importable_and_listed():
    for name in fppo_jax.__all__:
        assert getattr(fppo_jax, name) is not None
    assert set(fppo_jax.__all__) <= set(dir(fppo_jax))
    # A layer is an attribute; no module or folder of the package bears a public name, which
    # importing it would bind in the name's place.
    from fppo_jax import sweep
    from fppo_jax.run.sweeps import expand_grid
    from fppo_jax.stats import statistics

    assert fppo_jax.stats.statistics is statistics
    assert fppo_jax.sweep is sweep is sys.modules["fppo_jax.run.sweeps"].sweep
    assert not {module.name for module in pkgutil.iter_modules(fppo_jax.__path__)} & set(
        fppo_jax.__all__
    )
    assert fppo_jax.expand_grid is expand_grid
    with pytest.raises(AttributeError, match="no_such_name"):
        fppo_jax.no_such_name  # noqa: B018


def test_gymnax_loads_its_drawing_libraries_on_first_use():
    """gymnax imports seaborn and matplotlib for a few render functions: a gymnax environment
    is made without loading them, and a render function that uses them gets the usual
    modules."""
    code = """
        import json, sys
        from fppo_jax import make_env
        make_env("cartpole")
        drawing = ("seaborn", "scipy", "matplotlib")
        deferred = [name for name in drawing if name in sys.modules]
        from gymnax.environments.misc import pong
        palette = pong.sns.color_palette("cubehelix", 3)
        import matplotlib.colors, matplotlib.pyplot, seaborn
        same = [pong.sns.color_palette is seaborn.color_palette, pong.plt is not matplotlib.pyplot,
                pong.plt.subplots is matplotlib.pyplot.subplots,
                pong.colors.ListedColormap is matplotlib.colors.ListedColormap]
        print(json.dumps([deferred, len(palette), same]))
    """
    done = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    )
    assert json.loads(done.stdout.splitlines()[-1]) == [[], 3, [True, True, True, True]]
