"""What the experiment scripts share: where results go, the machine they were measured on, the
command that made them, and the rule that a recorded result is never replaced unasked.

Reports rebuilt from what is recorded (``figures.py``, ``verdict.py``, the Markdown summaries of
``table1_mujoco.py`` and ``ablation.py``) are written again freely; what was trained or measured
(curves, run records, benchmark and profile tables) is replaced only with ``--force``.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
from collections.abc import Iterable
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"


def machine() -> str:
    """The processor, its cores, the accelerator JAX sees and the jax version."""
    import jax

    try:
        with open("/proc/cpuinfo") as f:
            names = [line.split(":", 1)[1].strip() for line in f if line.startswith("model name")]
    except OSError:
        names = []
    device = jax.devices()[0]
    accelerator = "no GPU" if device.platform == "cpu" else device.device_kind
    cpu = names[0] if names else platform.processor() or platform.machine()
    return f"{cpu}, {os.cpu_count()} cores, {accelerator}; jax {jax.__version__}"


def command() -> str:
    """The command line that is running, as it is typed from the repository root."""
    return " ".join([f"python experiments/{Path(sys.argv[0]).name}", *sys.argv[1:]])


def add_record_flags(parser: argparse.ArgumentParser, default: Path | None = RESULTS) -> None:
    """``--results DIR`` (where results go) and ``--force`` (replace what is recorded there)."""
    parser.add_argument("--results", type=Path, default=default, help="where results go")
    parser.add_argument(
        "--force", action="store_true", help="replace results already recorded there"
    )


def refuse_to_replace(paths: Iterable[Path], force: bool) -> None:
    """Exit, before any work, if one of `paths` is already recorded and `force` is not set."""
    existing = [path for path in paths if path.exists()]
    if existing and not force:
        more = f" (and {len(existing) - 1} more)" if len(existing) > 1 else ""
        sys.exit(
            f"{existing[0]}{more} is already recorded: pass --force to replace it, or "
            "--results DIR (--output FILE) to record elsewhere and keep both"
        )


def inside_results(path: Path) -> bool:
    """Whether `path` is this repository's recorded results or inside them."""
    path, results = path.resolve(), RESULTS.resolve()
    return path == results or results in path.parents
