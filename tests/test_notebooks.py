import re
import shutil
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

ROOT = Path(__file__).parent.parent
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))


def test_the_seven_notebooks_are_there():
    names = {path.stem for path in NOTEBOOKS}
    assert names == {
        "quickstart",
        "objectives",
        "sweeps",
        "escape_speed",
        "own_surrogate",
        "study",
        "tuned",
    }


def test_the_jupyter_commands_the_docs_name_are_installed():
    # With the dev extra, as the tests are: each `jupyter SUB` is a `jupyter-SUB` program.
    docs = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
    named = {sub for doc in docs for sub in re.findall(r"`jupyter ([a-z]+)", doc.read_text())}
    assert named, "the docs name no command that runs a notebook"
    assert not [sub for sub in named if shutil.which(f"jupyter-{sub}") is None]


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda path: path.stem)
def test_notebook_is_committed_without_outputs(path):
    cells = nbformat.read(path, as_version=4).cells
    stale = [i for i, c in enumerate(cells) if c.cell_type == "code" and c.outputs]
    counts = [i for i, c in enumerate(cells) if c.cell_type == "code" and c.execution_count]
    assert not stale and not counts, (
        f"cells {stale or counts} of {path.name} have outputs: "
        "run python notebooks/strip_outputs.py"
    )


# A notebook that takes most of a minute or more runs with -m slow: the quickstart trains on MJX
# and renders, the sweeps and escape-speed ones train dozens of runs. What they call is tested
# on its own in the default run (test_plots.py, test_sweeps.py, test_trainer.py).
SLOW = {"quickstart", "sweeps", "escape_speed"}
RUNNABLE = [
    pytest.param(path, marks=pytest.mark.slow) if path.stem in SLOW else path for path in NOTEBOOKS
]


@pytest.mark.parametrize("path", RUNNABLE, ids=lambda path: path.stem)
def test_notebook_runs_top_to_bottom_with_a_small_budget(path, tmp_path, monkeypatch):
    monkeypatch.setenv("FPPO_JAX_NOTEBOOK_BUDGET", "small")
    notebook = nbformat.read(path, as_version=4)
    client = NotebookClient(
        notebook,
        # On a loaded machine a figure's output can arrive after nbclient's default 4 s wait
        # for it, and be lost.
        iopub_timeout=60,
        kernel_name="python3",
        resources={"metadata": {"path": str(tmp_path)}},
    )
    client.execute()  # raises CellExecutionError, with the cell and its traceback, on an error
    outputs = [o for c in notebook.cells if c.cell_type == "code" for o in c.outputs]
    assert not [o for o in outputs if o.output_type == "error"]
    # Every figure was drawn.
    figures = sum(o.output_type == "display_data" and "image/png" in o.data for o in outputs)
    plotted = sum("plt.show()" in c.source for c in notebook.cells if c.cell_type == "code")
    assert figures >= plotted
