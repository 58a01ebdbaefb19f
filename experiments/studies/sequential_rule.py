"""The error rates and seeds of `fppo-jax study`'s rule, by simulating studies on synthetic scores.

    python experiments/studies/sequential_rule.py  # experiments/results/sequential_rule.md
    python experiments/studies/sequential_rule.py --smoke  # 200 studies, into a temporary directory

No training: each simulated study draws every score from a normal distribution with sd 1,
each candidate's mean `shift` sd above its task's baseline, and applies
`fppo_jax.stats.sequential.decide` (groups of 5 seeds up to 30, family-wise level 0.05). With no
shift, any decision is a false one: their rate is the family-wise error. With a shift, the
table gives the share of comparisons decided `better` (the power), the mean seeds a comparison
used and the runs a study trained, beside the fixed design (one look, Holm across the same
family) with the fewest seeds that reaches the same power, by bisection over its seeds with the
same simulated scores. Seeded: the same command writes the same figures.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from fppo_jax.stats.sequential import Design
from fppo_jax.stats.simulation import simulate

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: shared modules

from common import (
    add_smoke_flags,
    argument_parser,
    header,
    refuse_to_replace,
    results_of,
    write_result,
)

DESIGN = Design(group_size=5, max_seeds=30, level=0.05)
FAMILIES = {"1 task × 1 candidate": [1], "2 tasks × 2 candidates": [2, 2]}
SHIFTS = (0.0, 0.5, 1.0)
LARGEST_FIXED = 200  # seeds per setting: beyond it the fixed design is reported as "> 200"


def fixed_seeds_for(power: float, family: list[int], shift: float, studies: int) -> int | None:
    """The fewest seeds per setting of a one-look design (Holm across `family`) whose simulated
    power is at least `power`, or None beyond :data:`LARGEST_FIXED`."""

    def reaches(n: int) -> bool:
        fixed = Design(n, n, DESIGN.level)
        return simulate(fixed, family, shift=shift, studies=studies, seed=1)["power"] >= power

    if not reaches(LARGEST_FIXED):
        return None
    low, high = 1, LARGEST_FIXED  # reaches(high); the power grows with the seeds
    while high - low > 1:
        middle = (low + high) // 2
        low, high = (low, middle) if reaches(middle) else (middle, high)
    return high


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--studies", type=int, default=2000, help="simulated studies per row")
    add_smoke_flags(parser, "200 studies per row")
    args = parser.parse_args()
    studies = 200 if args.smoke else args.studies
    path = results_of(args, "sequential-rule") / "sequential_rule.md"
    refuse_to_replace([path], args.force)

    start = time.perf_counter()
    rows = []
    for name, family in FAMILIES.items():
        for shift in SHIFTS:
            found = simulate(DESIGN, family, shift=shift, studies=studies, seed=1)
            error = (DESIGN.level * (1 - DESIGN.level) / studies) ** 0.5
            cells = [name, f"{shift:g}", f"{found['false_decision_rate']:.3f}"]
            if shift == 0:
                cells += [f"≤ {DESIGN.level:g} (+3 SE: {DESIGN.level + 3 * error:.3f})"]
                cells += [f"{found['seeds']:.1f}", f"{found['runs']:.0f}", "–", "–"]
            else:
                fixed = fixed_seeds_for(found["power"], family, shift, studies)
                runs = "–" if fixed is None else f"{fixed * (sum(family) + len(family))}"
                cells += [f"{found['power']:.3f}", f"{found['seeds']:.1f}", f"{found['runs']:.0f}"]
                cells += [f"> {LARGEST_FIXED}" if fixed is None else str(fixed), runs]
            rows.append("| " + " | ".join(cells) + " |")
            print(rows[-1], file=sys.stderr, flush=True)
    wall = time.perf_counter() - start

    lines = [
        *header("The study's rule: family-wise error and seeds, simulated"),
        f"- {studies} simulated studies per row, {wall:.0f} s in all",
        "",
        f"Design: looks after {', '.join(map(str, DESIGN.looks))} seeds per setting, "
        f"family-wise level {DESIGN.level:g}; scores normal with sd 1, each candidate `shift` sd "
        "above its task's baseline. *False decisions*: the share of studies with any comparison "
        "decided against the truth (with no shift, any decision: the family-wise error). "
        "*Power*: the share of comparisons decided `better`, which with no shift is replaced by "
        "the bound the false decisions must stay under (the level plus three Monte Carlo "
        "standard errors). *Seeds*: the mean per setting a comparison used; *runs*: the mean a "
        "study trained (a task's baseline runs while any of its candidates does). *Fixed "
        "design*: the fewest seeds per setting of one look, Holm across the same family, that "
        "reaches the same power, and the runs it trains.",
        "",
        "| family | shift (sd) | false decisions | power | seeds | runs | fixed design: seeds "
        "| its runs |",
        "|---|---|---|---|---|---|---|---|",
        *rows,
    ]
    write_result(path, lines)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
