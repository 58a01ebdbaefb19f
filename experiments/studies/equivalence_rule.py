"""The error rates and seeds of `fppo-jax study --margin`'s equivalence decision, by simulating
studies on synthetic scores.

    python experiments/studies/equivalence_rule.py  # experiments/results/equivalence_rule.md
    python experiments/studies/equivalence_rule.py --smoke  # 200 studies, into a temporary dir

No training: each simulated study draws every score from a normal distribution with sd 1,
each candidate's mean shifted so that P(candidate > baseline) is ½ + δ, ½ − δ (at the margin:
any `equivalent` is false) or ½ (identical settings), and applies
`fppo_jax.stats.sequential.decide` with margin δ = 0.2 and family-wise level 0.05, for the default
schedule (groups of 5 seeds up to 30) and a longer one (groups of 10 up to 50). At the margin
the table gives the share of studies with any comparison decided `equivalent` (the family-wise
false-equivalence rate); with identical settings, the share of comparisons decided
`equivalent`, the share of studies with any `better` or `worse` (the family-wise error of the
difference test) and the mean seeds a comparison used. Seeded: the same command writes the
same figures.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from fppo_jax.stats.decidable import equivalence_reachable
from fppo_jax.stats.sequential import Design
from fppo_jax.stats.simulation import shift_for, simulate

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # experiments/: shared modules

from common import (
    add_smoke_flags,
    argument_parser,
    header,
    refuse_to_replace,
    results_of,
    write_result,
)

MARGIN, LEVEL = 0.2, 0.05
SCHEDULES = {"5 to 30": (5, 30), "10 to 50": (10, 50)}
FAMILIES = {"1 task × 1 candidate": [1], "2 tasks × 2 candidates": [2, 2]}
PROBABILITIES = (0.5 + MARGIN, 0.5 - MARGIN, 0.5)


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--studies", type=int, default=2000, help="simulated studies per row")
    add_smoke_flags(parser, "200 studies per row")
    args = parser.parse_args()
    studies = 200 if args.smoke else args.studies
    path = results_of(args, "equivalence-rule") / "equivalence_rule.md"
    refuse_to_replace([path], args.force)

    start = time.perf_counter()
    error = (LEVEL * (1 - LEVEL) / studies) ** 0.5
    rows = []
    for schedule, (group_size, max_seeds) in SCHEDULES.items():
        design = Design(group_size, max_seeds, LEVEL, MARGIN)
        for name, family in FAMILIES.items():
            reachable = equivalence_reachable(design, sum(family))
            for seed, probability in enumerate(PROBABILITIES, start=1):
                shift = shift_for(probability)
                found = simulate(design, family, shift=shift, studies=studies, seed=seed)
                cells = [schedule, name, f"{probability:g}", f"{shift:+.3f}"]
                if probability != 0.5:
                    cells += [f"{found['false_equivalence_rate']:.3f}", "–", "–"]
                else:
                    cells += ["–", f"{found['equivalent']:.3f}"]
                    cells += [f"{found['false_decision_rate']:.3f}"]
                cells += [f"{found['seeds']:.1f}", str(reachable)]
                rows.append("| " + " | ".join(cells) + " |")
                print(rows[-1], file=sys.stderr, flush=True)
    wall = time.perf_counter() - start

    lines = [
        *header("The study's equivalence decision: false equivalence and seeds, simulated"),
        f"- {studies} simulated studies per row, {wall:.0f} s in all",
        "",
        f"Design: margin {MARGIN:g} on P(candidate > baseline), family-wise level {LEVEL:g}, "
        "looks after every group of seeds per setting (the schedule). Scores normal with sd 1, "
        "each candidate shifted (in sd) so that P(candidate > baseline) is the row's: "
        f"{0.5 + MARGIN:g} and {0.5 - MARGIN:g} lie on the margin, where any `equivalent` is "
        "false; 0.5 is identical settings. *False equivalent*: the share of studies with any "
        "comparison decided `equivalent`, to stay under the level (plus three Monte Carlo "
        f"standard errors: {LEVEL + 3 * error:.3f}). *Equivalent*: the share of comparisons "
        "decided `equivalent`. *False better or worse*: the share of studies with any "
        "comparison decided `better` or `worse` (identical settings: the family-wise error of "
        "the difference test). *Seeds*: the mean per setting a comparison used. *Reachable "
        "from*: the fewest seeds per setting at which the first level of Holm's procedure "
        "can decide `equivalent` (the look whose narrowest interval fits in the margin).",
        "",
        "| schedule | family | P(candidate > baseline) | shift (sd) | false equivalent | "
        "equivalent | false better or worse | seeds | reachable from |",
        "|---|---|---|---|---|---|---|---|---|",
        *rows,
    ]
    write_result(path, lines)
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
