"""The documentation site's hooks (mkdocs.yml's ``hooks``): the site mirrors the repository.

Each page sits at its path in the repository: the README is the home page, ``docs/`` the guide,
``notebooks/`` the notebooks, and every file of the repository that these link to, followed link
by link (the recorded results, their figures, the plans), so a relative link that works on the
repository's pages works on the site, and the strict build fails on one that leads nowhere. A
link to a folder goes to the folder's README.md, as the repository's page of a folder shows it.
The API reference (``docs/api.md``) is written here from ``fppo_jax.__all__``, so that it holds
every public name; mkdocstrings renders each from its docstring.
"""

from __future__ import annotations

import logging
import os
import posixpath
import re
import sys
from collections.abc import Iterator
from pathlib import Path
from urllib.parse import unquote

from mkdocs.config.defaults import MkDocsConfig
from mkdocs.plugins import event_priority
from mkdocs.structure.files import File, Files
from mkdocs.structure.pages import Page

ROOT = Path(__file__).resolve().parent.parent
EXPERIMENTS = ROOT / "experiments"
HOME = "README.md"
API = "docs/api.md"
# What the site starts from; every file these link to is followed.
PAGES = (HOME, "docs/*.md", "docs/images/*", "notebooks/*.ipynb")
log = logging.getLogger("mkdocs.hooks.repository")
LINK = re.compile(r"\]\((?P<target>[^)\s]+)\)")
FENCE = re.compile(r"^(```|~~~).*?^\1", re.MULTILINE | re.DOTALL)
# A role of Sphinx's Python domain before a docstring's reference, as mkdocstrings renders it.
ROLE = re.compile(r":(?:class|func|meth|attr|mod|data|exc|obj):(<code>)~?")


def resolved(page: Path, target: str) -> str | None:
    """Where a relative link `target` of the page `page` leads on the site, as a link relative
    to the page; None where it leads nowhere in the repository (the build then says so). A link
    to a folder leads to the folder's README.md. A recorded result under experiments/ may name a
    file relative to experiments/ (``plans/tuned.json``), as the script that wrote it saw it:
    where the link leads nowhere from the page itself, it leads there."""
    path = unquote(target)
    found = (page.parent / path).resolve()
    if not found.exists() and page.is_relative_to(EXPERIMENTS):
        if (EXPERIMENTS / path).exists():
            found = (EXPERIMENTS / path).resolve()
            path = os.path.relpath(found, page.parent)
    if found.is_dir():
        found, path = found / "README.md", posixpath.join(path.rstrip("/"), "README.md")
    return path if found.is_file() and found.is_relative_to(ROOT) else None


def _relative(target: str) -> bool:
    return bool(target) and "://" not in target and not target.startswith(("#", "mailto:"))


def _links(page: Path) -> Iterator[Path]:
    """The files of the repository that the Markdown file `page` links to, outside its code
    blocks."""
    for match in LINK.finditer(FENCE.sub("", page.read_text())):
        target = match["target"].split("#")[0]
        if _relative(target) and (path := resolved(page, target)) is not None:
            yield (page.parent / path).resolve()


def repository_files() -> list[Path]:
    """The files the site holds: the pages it starts from and all they link to."""
    found: dict[Path, None] = {}
    waiting = [path for pattern in PAGES for path in sorted(ROOT.glob(pattern))]
    while waiting:
        path = waiting.pop()
        if path in found or path == Path(__file__).resolve():
            continue
        found[path] = None
        if path.suffix == ".md":
            waiting.extend(_links(path))
    return sorted(found)


def defined_in(name: str) -> str:
    """The module that defines the public name `name` of ``fppo_jax`` (the package imports each
    on first use, which a reader of the source cannot follow)."""
    import fppo_jax

    value = getattr(fppo_jax, name)
    module = getattr(value, "__module__", None)
    if (
        isinstance(module, str)
        and module.startswith("fppo_jax.")
        and hasattr(value, "__qualname__")
    ):
        return module
    holders = [
        m
        for m, module_object in list(sys.modules.items())
        if m.startswith("fppo_jax.") and vars(module_object).get(name) is value
    ]
    return min(holders, key=lambda m: (m.count("."), m))


def api_page() -> str:
    """The API reference: every name of ``fppo_jax.__all__``, each rendered by mkdocstrings
    from its docstring where it is defined, headed by its public name."""
    import fppo_jax

    lines = [
        "# API reference",
        "",
        "Every public name of `fppo_jax` (its `__all__`), from its docstring. How they fit "
        "together: [the Python API](python-api.md).",
        "",
    ]
    for name in sorted(fppo_jax.__all__, key=str.lower):
        lines += [
            f"::: {defined_in(name)}.{name}",
            "    options:",
            f'      heading: "fppo_jax.{name}"',
            f'      toc_label: "{name}"',
            "",
        ]
    return "\n".join(lines)


@event_priority(100)  # before the notebooks' plugin, which takes the notebooks from this list
def on_files(files: Files, config: MkDocsConfig) -> Files:
    docs = Path(config.docs_dir).resolve()
    theme = [
        f for f in files if f.abs_src_path is None or not Path(f.abs_src_path).is_relative_to(docs)
    ]
    site = Files(theme)
    for path in repository_files():
        uri = path.relative_to(ROOT).as_posix()
        site.append(File(uri, str(ROOT), config.site_dir, config.use_directory_urls))
    site.append(File.generated(config, API, content=api_page()))
    return site


def on_page_markdown(markdown: str, page: Page, config: MkDocsConfig, files: Files) -> str:
    """Each relative link as :func:`resolved` leads it: a folder to its README.md, a record's
    link relative to experiments/ to its file."""
    source = ROOT / page.file.src_uri

    def lead(match: re.Match[str]) -> str:
        target, hash_, anchor = match["target"].partition("#")
        if not _relative(target) or (path := resolved(source, target)) is None:
            return match.group(0)
        if path != unquote(target):
            log.info("%s: the link %s leads to %s", page.file.src_uri, target, path)
        return f"]({path}{hash_}{anchor})"

    return LINK.sub(lead, markdown)


def on_page_content(html: str, page: Page, config: MkDocsConfig, files: Files) -> str:
    """A docstring's Sphinx role (``:class:`~fppo_jax.Policy```) shown as the code it names."""
    return ROLE.sub(r"\1", html)
