"""Converts studies' plans recorded by earlier versions to this one's form, once.

Two conversions, each of the plan's rule, everything else left as it was:
- Until the package was laid out in folders, the rule's words (``test`` and, with a margin,
  ``equivalence_test``) ended with the module that held it, ``(fppo_jax.sequential)``; that
  ending is removed.
- Until rules were named by id, a plan recorded its rule in those words; now it records
  ``rule``, the rule's id and version (``fppo_jax.stats.rules``), in their place
  (``fppo_jax.analysis.study_plan.upgraded``, which a study also applies when it reads an
  earlier plan, so that it goes on under it unconverted).

A converted plan is the one this version writes for the same study, byte for byte. Run once
over experiments/results (done; the converted plans are committed); a study of one's own
recorded before either change converts the same way::

    python experiments/convert_plans.py runs/my-study
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from fppo_jax.analysis.study_plan import upgraded
from fppo_jax.store.files import write_json

ENDING = " (fppo_jax.sequential)"


def convert(path: Path) -> bool:
    """Converts the plan at `path` to this version's form; whether it changed it."""
    text = path.read_text()
    # The words sit in JSON strings, where the ending is written as is (no escapes in it).
    plan = upgraded(json.loads(text.replace(ENDING + '"', '"')))
    if json.dumps(plan, indent=2) + "\n" == text:
        return False
    write_json(path, plan)
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
