"""How to install one of the package's optional extras (``pyproject.toml``)."""

from __future__ import annotations


def install_hint(extra: str) -> str:
    """The command that installs `extra`, for an install from the package index and from a
    clone of the repository alike."""
    return f"pip install 'fppo-jax[{extra}]' (from a clone: pip install -e '.[{extra}]')"
