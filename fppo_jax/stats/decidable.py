"""What a study's design can decide, before any score: the largest z a look's seeds reach
(:func:`largest_z`), the fewest seeds that reach a boundary (:func:`fewest_seeds`), the
narrowest interval of the equivalence test (:func:`narrowest_half_width`) and the first look
that can decide ``equivalent``, said in the plan's lines (:func:`plan_lines`).
"""

from __future__ import annotations

import numpy as np

from fppo_jax.core.checks import positive_int
from fppo_jax.stats.sequential import Design
from fppo_jax.stats.spending import boundaries


def largest_z(seeds: int) -> float:
    """The largest |z| that :func:`mann_whitney_z` reaches with `seeds` scores of each setting:
    every candidate run above every baseline run (or below), U − n²/2 = ±n²/2 over
    σ = n·√((2n + 1)/12), so √(3n² / (2n + 1)); ties only lower it. A look whose boundary is
    above it cannot decide ``better`` or ``worse``."""
    n = positive_int("seeds", seeds)
    return float(np.sqrt(3 * n * n / (2 * n + 1)))


def fewest_seeds(critical: float) -> int | None:
    """The fewest seeds per setting whose :func:`largest_z` reaches `critical`: the smallest n
    with 3n² ≥ c²(2n + 1); None for a boundary no seeds reach (infinite: a look that spends no
    error)."""
    if not np.isfinite(critical):
        return None
    c2 = float(critical) ** 2
    n = max(1, int(np.ceil((c2 + np.sqrt(c2 * c2 + 3 * c2)) / 3)))
    while n > 1 and largest_z(n - 1) >= critical:  # the root rounded up past the edge
        n -= 1
    while largest_z(n) < critical:
        n += 1
    return n


def _reaching(critical: float) -> str:
    """What it would take a look to reach `critical`, in words."""
    needed = fewest_seeds(critical)
    if needed is None:
        return "it spends no error, so no seeds can"
    return f"reaching ±{critical:.2f} takes at least {needed} seeds per setting"


def narrowest_half_width(seeds: int, critical: float) -> float:
    """The narrowest half-width c·se of the equivalence test's interval with `seeds` scores of
    each setting at boundary `critical`: se at its floor √((2n + 1) / (12n²)) (:func:
    `improvement_estimate`). Where it exceeds the margin no scores can decide ``equivalent``."""
    n = positive_int("seeds", seeds)
    return float(critical * np.sqrt((2 * n + 1) / (12 * n * n)))


def equivalence_reachable(design: Design, comparisons: int) -> int | None:
    """The fewest seeds per setting (one of the design's looks) at which ``equivalent`` can be
    decided at the first level of Holm's procedure, α / `comparisons`: the first look whose
    narrowest interval (:func:`narrowest_half_width`) fits within the margin; None if none
    does, or the design has no margin."""
    if design.margin is None:
        return None
    looks = design.looks
    fractions = tuple(n / design.max_seeds for n in looks)
    critical = boundaries(design.level / comparisons, fractions, sides=1)
    fits = [
        n
        for n, c in zip(looks, critical, strict=True)
        if narrowest_half_width(n, c) <= design.margin
    ]
    return fits[0] if fits else None


def plan_lines(design: Design, comparisons: int) -> list[str]:
    """What a study's plan can decide, in a few lines for the command line: each look's
    boundary if no comparison is decided (level α / `comparisons`), with a warning where the
    look's seeds cannot reach it (:func:`largest_z`) that names the fewest seeds per setting
    that could (:func:`fewest_seeds`), and one more where no look can; and, with a margin,
    the fewest seeds at which ``equivalent`` becomes reachable
    (:func:`equivalence_reachable`), or a warning that no look reaches it, with the seeds one
    last look of the same boundary would need."""
    positive_int("comparisons", comparisons)
    looks = design.looks
    fractions = tuple(n / design.max_seeds for n in looks)
    level = design.level / comparisons
    critical = boundaries(level, fractions)
    lines = [
        f"plan: {len(looks)} look{'s' if len(looks) > 1 else ''}; better or worse when |z| "
        f"reaches the look's boundary (level {level:.3g} while no comparison is decided):"
    ]
    for k, (n, c) in enumerate(zip(looks, critical, strict=True)):
        line = f"  look {k + 1}, {n} seeds per setting: ±{c:.2f}"
        if largest_z(n) < c:
            line += (
                f" (warning: cannot decide, |z| is at most {largest_z(n):.2f} with {n} seeds; "
                f"{_reaching(c)})"
            )
        lines.append(line)
    if all(largest_z(n) < c for n, c in zip(looks, critical, strict=True)):
        lines.append(
            "  warning: no look of this design can decide better or worse, whatever the "
            f"scores: its last look, {looks[-1]} seeds per setting, needs "
            f"{fewest_seeds(critical[-1])} to reach ±{critical[-1]:.2f}; plan more seeds "
            "(max_seeds) or fewer looks (a larger group_size)"
        )
    if design.margin is None:
        return lines
    reachable = equivalence_reachable(design, comparisons)
    within = f"equivalent (P(candidate > baseline) within 1/2 ± {design.margin:g})"
    if reachable is not None:
        return [*lines, f"  {within}: reachable from {reachable} seeds per setting"]
    last = boundaries(level, fractions, sides=1)[-1]
    ratio = (design.margin / last) ** 2  # the fewest n with last·√((2n + 1)/(12n²)) ≤ margin
    needed = int(np.ceil((2 + np.sqrt(4 + 48 * ratio)) / (24 * ratio)))
    return [
        *lines,
        f"  warning: no look can decide {within}; at its last boundary it needs about "
        f"{needed} seeds per setting",
    ]
