"""Remove every output from the notebooks, so that none is committed stale.

    python notebooks/strip_outputs.py

The notebooks are kept without outputs; a test checks it, and another runs each of them top to
bottom (with FPPO_JAX_NOTEBOOK_BUDGET=small) so that none stops working.
"""

from pathlib import Path

import nbformat


def strip(path: Path) -> bool:
    """Strip `path` in place; True if it had outputs."""
    notebook = nbformat.read(path, as_version=4)
    changed = False
    for cell in notebook.cells:
        if cell.cell_type == "code" and (cell.outputs or cell.execution_count is not None):
            cell.outputs, cell.execution_count = [], None
            changed = True
        changed |= cell.metadata.pop("execution", None) is not None
    if changed:
        nbformat.write(notebook, path)
    return changed


if __name__ == "__main__":
    for path in sorted(Path(__file__).parent.glob("*.ipynb")):
        print(f"{path}: {'stripped' if strip(path) else 'already clean'}")
