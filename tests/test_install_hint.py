"""fppo_jax.errors.install_hint: how to install an optional extra, for an extra that exists."""

import re
import tomllib
from pathlib import Path

from fppo_jax.errors import install_hint

ROOT = Path(__file__).resolve().parents[1]


def test_install_hint_names_the_extra_for_the_index_and_for_a_clone():
    assert install_hint("wandb") == (
        "pip install 'fppo-jax[wandb]' (from a clone: pip install -e '.[wandb]')"
    )


def test_every_extra_the_package_names_in_a_hint_is_one_pyproject_defines():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert project["name"] == "fppo-jax"  # the name the hint installs
    defined = set(project["optional-dependencies"])
    named = set()
    for path in (ROOT / "fppo_jax").rglob("*.py"):
        named |= set(re.findall(r"install_hint\(\s*['\"]([^'\"]+)['\"]\s*\)", path.read_text()))
    assert {"wandb", "onnx", "native", "gymnasium", "playground"} <= named
    assert named <= defined, f"hints for extras pyproject.toml lacks: {sorted(named - defined)}"
