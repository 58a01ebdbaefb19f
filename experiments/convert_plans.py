"""Converts studies' plans recorded when the rule's words named its module, once.

A study's ``plan.json`` records its test in words (``test`` and, with a margin,
``equivalence_test``), and a resumed study is held to them. Until the package was laid out in
folders, those words ended with the module that held the rule, ``(fppo_jax.sequential)``; the
module moved (``fppo_jax.stats.sequential``) and the words now name none, so that a move
changes no plan. This removes that ending from every plan under the directories given
(default: experiments/results), leaving everything else as it was, byte for byte, and says
which files it changed. Run once over experiments/results (done; the converted plans are
committed); a study of one's own recorded before the move converts the same way::

    python experiments/convert_plans.py runs/my-study
"""

from __future__ import annotations

import argparse
from pathlib import Path

ENDING = " (fppo_jax.sequential)"


def convert(path: Path) -> bool:
    """Removes the module's name from the rule's words in the plan at `path`; whether it did."""
    text = path.read_text()
    # The words sit in JSON strings, where the ending is written as is (no escapes in it).
    converted = text.replace(ENDING + '"', '"')
    if converted == text:
        return False
    path.write_text(converted)
    return True


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    default = Path(__file__).resolve().parent / "results"
    parser.add_argument("directories", nargs="*", type=Path, default=[default])
    for directory in parser.parse_args().directories:
        for path in sorted(directory.rglob("plan.json")):
            if convert(path):
                print(f"converted {path}")


if __name__ == "__main__":
    main()
