"""The persistent compilation cache: programs JAX compiled are kept on disk, so that a run
compiled once starts without compiling again (most of a short run's wall time is compiling).

``train``, ``sweep`` and the command line turn it on (:func:`enable`) before anything compiles,
in ``$FPPO_JAX_CACHE_DIR/jax-<version>-jaxlib-<version>/``; ``FPPO_JAX_CACHE_DIR`` defaults to
``fppo-jax`` in the user's cache directory (``$XDG_CACHE_HOME``, else ``~/.cache``), and an
empty value or ``off`` turns the cache off. A switch of the process, not of a run: JAX keeps
one cache for everything a process compiles.

- Never stale: JAX's key of an entry holds the program, the compiler's options, the devices
  and JAX's version; a directory per version pair also lets old entries be deleted by hand.
- Safe to share between processes (two test workers, a job array): with a size limit, JAX
  reads and writes each entry under a file lock (``filelock``), never a half-written one, and
  evicts the least recently used entries past the limit.
- A cache directory set for JAX itself (``jax_compilation_cache_dir``, or the environment's
  ``JAX_COMPILATION_CACHE_DIR``) is the user's: it is kept as it is, neither moved nor turned
  off, and its thresholds are left alone.
"""

from __future__ import annotations

import os
import warnings
from collections.abc import Mapping
from pathlib import Path

import jax
import jaxlib
from jax.experimental.compilation_cache import compilation_cache

ENVIRONMENT_VARIABLE = "FPPO_JAX_CACHE_DIR"
OFF = ("", "off")
# Bounded, so that JAX locks each entry it reads or writes (see above) and old versions'
# entries do not pile up: room for thousands of programs (the README's first run keeps two,
# half a megabyte).
MAX_SIZE = 2 * 1024**3
# JAX's default keeps only programs compiled in a second or more: a run's initialisation takes
# about that on a fast CPU, and the small runs of tests and notebooks less.
MIN_COMPILE_SECONDS = 0.1

_ours: str | None = None  # the directory this module gave JAX, if any


def directory(environ: Mapping[str, str] = os.environ) -> Path | None:
    """Where compiled programs are cached (None: off), from `environ`'s ``FPPO_JAX_CACHE_DIR``
    or the user's cache directory, in a subdirectory of this JAX's and jaxlib's versions."""
    root: str | Path | None  # the variable as given, else the default directory
    root = environ.get(ENVIRONMENT_VARIABLE)
    if root is None:
        root = Path(environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "fppo-jax"
    elif root.strip().lower() in OFF:
        return None
    return Path(root).expanduser() / f"jax-{jax.__version__}-jaxlib-{jaxlib.__version__}"  # type: ignore[attr-defined]  # jaxlib does not re-export it


def enable() -> Path | None:
    """Point JAX's persistent compilation cache at :func:`directory` (or turn it off, if this
    module had turned it on), unless the user set one for JAX; returns the directory JAX caches
    in now, if any. Cheap to call again: only a change of ``FPPO_JAX_CACHE_DIR`` does anything."""
    global _ours
    current: str | None = jax.config.jax_compilation_cache_dir  # type: ignore[attr-defined]  # options are attributes set at run time
    if current is not None and current != _ours:
        return Path(current)  # the user's
    wanted = directory()
    if wanted is not None:
        try:
            wanted.mkdir(parents=True, exist_ok=True)
        except OSError as error:
            warnings.warn(f"compiled programs are not cached: {error}", stacklevel=2)
            wanted = None
    path = None if wanted is None else os.fspath(wanted)
    if path == current:
        return wanted
    if current is not None:
        compilation_cache.reset_cache()  # JAX opens its cache once; this one is another
    jax.config.update("jax_compilation_cache_max_size", MAX_SIZE)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", MIN_COMPILE_SECONDS)
    jax.config.update("jax_compilation_cache_dir", path)
    _ours = path
    return wanted
