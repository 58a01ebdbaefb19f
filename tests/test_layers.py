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
    """The package's modules that `path` imports, anywhere in it (at the top, in a function,
    under ``TYPE_CHECKING``), without the package name: ``from fppo_jax.analysis import
    studies`` imports ``analysis.studies``, ``from fppo_jax.envs import make_env`` the folder
    ``envs`` (its ``__init__``)."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("fppo_jax."):
            folder = node.module.removeprefix("fppo_jax.")
            for alias in node.names:
                module = f"{folder}.{alias.name}"
                found.add(
                    module
                    if (PACKAGE / Path(*module.split("."))).with_suffix(".py").is_file()
                    else folder
                )
        elif isinstance(node, ast.Import):
            found.update(
                alias.name.removeprefix("fppo_jax.")
                for alias in node.names
                if alias.name.startswith("fppo_jax.")
            )
    return found


def _modules() -> dict[str, Path]:
    """The package's modules by name (a folder's ``__init__`` by the folder's)."""
    return {
        ".".join(path.relative_to(PACKAGE).with_suffix("").parts).removesuffix(".__init__"): path
        for path in PACKAGE.rglob("*.py")
        if path.parent != PACKAGE  # the package's own __init__ and __main__ sit above the layers
        or path.stem not in ("__init__", "__main__")
    }


def _circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The import circles of `graph` (module → the modules it imports): its strongly connected
    components of more than one module, or of one that imports itself (Tarjan's algorithm)."""
    order: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    circles = []

    def visit(module: str) -> None:
        order[module] = low[module] = len(order)
        stack.append(module)
        for imported in sorted(graph[module]):
            if imported not in order:
                visit(imported)
                low[module] = min(low[module], low[imported])
            elif imported in stack:
                low[module] = min(low[module], order[imported])
        if low[module] == order[module]:
            component = stack[stack.index(module) :]
            del stack[stack.index(module) :]
            if len(component) > 1 or module in graph[module]:
                circles.append(sorted(component))

    for module in sorted(graph):
        if module not in order:
            visit(module)
    return circles


def _graph() -> dict[str, set[str]]:
    modules = _modules()
    return {module: _imports(path) & set(modules) for module, path in modules.items()}


def test_every_module_sits_in_a_layer():
    assert {module.split(".")[0] for module in _modules()} == set(LAYERS)


def test_no_module_imports_itself_through_others():
    """No import circle, whatever form its imports take: a circle held together by a deferred or
    ``TYPE_CHECKING`` import is one that moving an import to the top breaks."""
    assert _circles(_graph()) == []


def test_an_import_circle_of_any_form_is_found():
    graph = _graph()
    graph["analysis.tune_files"] = graph["analysis.tune_files"] | {"analysis.study_tuned"}
    assert any({"analysis.study_tuned", "analysis.tune_files"} <= set(c) for c in _circles(graph))
    assert _circles({"a": {"a"}, "b": set()}) == [["a"]]


def test_a_module_imported_from_its_folder_is_seen(tmp_path):
    path = tmp_path / "example.py"
    path.write_text(
        "from fppo_jax.analysis import studies\n"
        "from fppo_jax.envs import make_env\n"
        "def later():\n    import fppo_jax.run.plan\n"
        "from typing import TYPE_CHECKING\n"
        "if TYPE_CHECKING:\n    from fppo_jax.analysis.tuning import tune\n"
    )
    assert _imports(path) == {"analysis.studies", "envs", "run.plan", "analysis.tuning"}


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
