import ast
from pathlib import Path

import pytest

import fppo_jax
from fppo_jax.errors import (
    FppoError,
    InvalidInput,
    MissingFile,
    MissingPackage,
    NotEnoughMemory,
    first_line,
)

PACKAGE = Path(fppo_jax.__file__).parent
# Runs without the package's other modules (a policy deployed on its own), so its errors are the
# built-ins.
STANDALONE = {"numpy_policy.py"}
BUILT_IN_KINDS = {"ValueError", "ImportError", "MemoryError", "FileNotFoundError"}


def _raised_names(path: Path) -> list[tuple[int, str]]:
    raised = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Raise) and isinstance(node.exc, ast.Call):
            if isinstance(node.exc.func, ast.Name):
                raised.append((node.lineno, node.exc.func.id))
    return raised


def test_the_package_raises_its_own_kinds_where_the_command_line_prints_one_line():
    bare = [
        f"{path.relative_to(PACKAGE)}:{line} raises {name}"
        for path in sorted(PACKAGE.rglob("*.py"))
        if path.name not in STANDALONE
        for line, name in _raised_names(path)
        if name in BUILT_IN_KINDS
    ]
    assert bare == []


@pytest.mark.parametrize(
    ("kind", "built_in"),
    [
        (InvalidInput, ValueError),
        (MissingPackage, ImportError),
        (MissingFile, FileNotFoundError),
        (NotEnoughMemory, MemoryError),
    ],
)
def test_each_kind_is_caught_as_its_built_in_and_as_a_project_error(kind, built_in):
    for caught in (built_in, FppoError):
        with pytest.raises(caught):
            raise kind("refused")


def test_first_line_is_the_messages_first_line_at_most_200_characters():
    assert first_line(ValueError("cannot read\nTraceback: ...")) == "cannot read"
    assert first_line(ValueError("\n  padded  \nsecond")) == "padded  "
    assert first_line(ValueError("")) == "no message"
    assert first_line(KeyError()) == "no message"
    assert first_line(OSError("x" * 500)) == "x" * 200
    assert first_line(KeyError("digest")) == "'digest'"
