"""The documentation site (mkdocs.yml, docs/hooks.py): it builds strictly, so that a link to a
page, file or anchor that is not there fails here; its API reference holds every public name;
the notebooks and the results pages are in it. And the README's set-up commands are what CI
runs."""

from __future__ import annotations

import importlib.util
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

import fppo_jax

ROOT = Path(__file__).resolve().parent.parent
NEEDED = ("mkdocs", "material", "mkdocstrings", "mkdocstrings_handlers.python", "mkdocs_jupyter")
MISSING = [name for name in NEEDED if importlib.util.find_spec(name.split(".")[0]) is None]
needs_docs = pytest.mark.skipif(
    bool(MISSING),
    reason=f"the docs extra is not installed ({', '.join(MISSING)}): pip install -e '.[docs]'",
)


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    """The site, built with ``mkdocs build --strict`` into a new temporary folder."""
    out = tmp_path_factory.mktemp("site")
    done = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"},
    )
    assert done.returncode == 0, done.stdout + done.stderr
    return out


@needs_docs
def test_the_site_builds_strictly_with_the_readme_as_its_home(site):
    home = (site / "index.html").read_text()
    assert "Does FPPO beat PPO?" in home
    assert (site / "experiments" / "results" / "figures" / "headline.png").is_file()
    for page in sorted((ROOT / "docs").glob("*.md")):
        name = "index" if page.stem == "README" else f"{page.stem}/index"
        assert (site / "docs" / f"{name}.html").is_file(), page.name


@needs_docs
def test_the_api_reference_holds_every_public_name(site):
    page = (site / "docs" / "api" / "index.html").read_text()
    headings = {  # each heading's name, before the labels (dataclass …) beside it
        re.sub(r"<[^>]+>", " ", heading).split()[0]
        for heading in re.findall(r"<h2[^>]*>(.*?)</h2>", page, re.DOTALL)
    }
    assert {f"fppo_jax.{name}" for name in fppo_jax.__all__} <= headings
    assert "fppo_jax.train" in headings and ":func:" not in page  # a role shown as code


@needs_docs
def test_the_notebooks_and_the_results_are_in_the_site(site):
    for notebook in sorted((ROOT / "notebooks").glob("*.ipynb")):
        assert (site / "notebooks" / notebook.stem / "index.html").is_file(), notebook.name
    quickstart = (site / "notebooks" / "quickstart" / "index.html").read_text()
    assert "fppo_jax" in quickstart and "jp-Cell" in quickstart  # rendered, cell by cell
    results = site / "experiments" / "results"
    for report in ("tuned", "study", "spo-dpo", "redecided", "dose_response", "baseline-shape"):
        assert (results / report / "index.html").is_file(), report
    assert (results / "index.html").is_file()  # the index of every recorded result


def test_a_link_leads_where_the_repository_s_page_leads_it(monkeypatch):
    monkeypatch.syspath_prepend(str(ROOT / "docs"))
    pytest.importorskip(
        "mkdocs", reason="the docs extra is not installed: pip install -e '.[docs]'"
    )
    hooks = __import__("hooks")
    docs, tuned = ROOT / "docs" / "results.md", ROOT / "experiments" / "results" / "tuned.md"
    assert (
        hooks.resolved(docs, "../experiments/results/tuned.md") == "../experiments/results/tuned.md"
    )
    assert hooks.resolved(docs, "../experiments/") == "../experiments/README.md"  # a folder
    assert hooks.resolved(docs, "nowhere.md") is None  # the build then fails on it
    # A record's link relative to experiments/, as its script wrote it, leads to the file.
    assert hooks.resolved(tuned, "plans/tuned.json") == "../plans/tuned.json"
    assert hooks.resolved(docs, "plans/tuned.json") is None  # a page of docs/ gets no such help


def test_the_readme_s_test_command_is_what_ci_runs():
    readme = (ROOT / "README.md").read_text()
    ci = (ROOT / ".ci" / "run").read_text().strip().splitlines()[-1]
    commands = re.findall(r"```bash\n(.*?)\n```", readme, re.DOTALL)
    assert ci in commands
    first = next(c for c in commands if "fppo-jax train" in c)
    assert shlex.split(first)[:4] == ["python", "-m", "pip", "install"]
    assert len(readme.splitlines()) <= 200
