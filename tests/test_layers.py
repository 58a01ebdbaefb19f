"""The package's folders are its layers: a module imports only from its own layer and those
below it (each folder's README.md says what lives there), so the pure, jitted core never
depends on how runs are stored, studied or called from the command line."""

from __future__ import annotations

import ast
from pathlib import Path

import fppo_jax

LAYERS = ["errors", "envs", "core", "stats", "store", "export", "run", "analysis", "cli"]

# The one import that runs upward, done lazily: a surrogate's hyperparameter may not take a
# name of the command line, and only the parser knows them all.
UPWARD = {("core.own_surrogates", "cli.parser")}

PACKAGE = Path(fppo_jax.__file__).parent


def _layer(module: str) -> int:
    return LAYERS.index(module.split(".")[0])


def _imports(path: Path) -> set[str]:
    """The package's modules that `path` imports, anywhere in it, without the package name."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("fppo_jax."):
            found.add(node.module.removeprefix("fppo_jax."))
        elif isinstance(node, ast.Import):
            found.update(
                alias.name.removeprefix("fppo_jax.")
                for alias in node.names
                if alias.name.startswith("fppo_jax.")
            )
    return found


def _modules() -> dict[str, Path]:
    return {
        ".".join(path.relative_to(PACKAGE).with_suffix("").parts): path
        for path in PACKAGE.rglob("*.py")
        if path.parent != PACKAGE  # the package's own __init__ and __main__ sit above the layers
        or path.stem not in ("__init__", "__main__")
    }


def test_every_module_sits_in_a_layer():
    assert {module.split(".")[0] for module in _modules()} == set(LAYERS)


def test_imports_run_downward_only():
    upward = {
        (module, imported)
        for module, path in _modules().items()
        for imported in _imports(path)
        if _layer(imported) > _layer(module)
    }
    assert upward == UPWARD


def test_every_layer_says_what_lives_there_and_what_it_may_import():
    for layer in LAYERS[1:]:
        readme = (PACKAGE / layer / "README.md").read_text()
        below = LAYERS[: LAYERS.index(layer)]
        assert f"may import {', '.join(below)}" in " ".join(readme.split()), layer


TESTS = Path(__file__).resolve().parent


def test_every_module_has_a_test_file_of_its_own():
    """Each module of the package (a folder's ``__init__`` apart) is tested in
    ``tests/test_<module>.py``, so that what tests a module is found by its name: the names are
    unique across the layers, and each file holds a test."""
    stems = [path.stem for path in _modules().values() if path.stem != "__init__"]
    assert len(stems) == len(set(stems)), sorted(s for s in stems if stems.count(s) > 1)
    missing = sorted(
        f"{module}: tests/test_{path.stem}.py"
        for module, path in _modules().items()
        if path.stem != "__init__" and "def test_" not in _text(TESTS / f"test_{path.stem}.py")
    )
    assert not missing, "modules without a test file of their own:\n" + "\n".join(missing)


def _text(path: Path) -> str:
    return path.read_text() if path.is_file() else ""
