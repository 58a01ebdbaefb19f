"""What a study's design can decide before any run (fppo_jax.stats.decidable): the largest z a
look reaches, the fewest seeds that reach a boundary, and where equivalence becomes reachable."""

import numpy as np
import pytest

from fppo_jax.stats.decidable import (
    equivalence_reachable,
    fewest_seeds,
    largest_z,
    narrowest_half_width,
    plan_lines,
)
from fppo_jax.stats.sequential import Design, mann_whitney_z
from fppo_jax.stats.spending import boundaries


def test_what_each_look_can_decide_is_stated_before_any_run():
    assert largest_z(5) == pytest.approx(np.sqrt(75 / 11))  # 2.61: all of one above the other
    x, y = np.arange(5.0), np.arange(5.0) + 10
    assert abs(mann_whitney_z(x, y)) == pytest.approx(largest_z(5))
    design = Design(group_size=5, max_seeds=30, margin=0.2)
    lines = plan_lines(design, 1)
    assert lines[1] == (
        "  look 1, 5 seeds per setting: ±5.37 (warning: cannot decide, |z| is at most 2.61 with "
        "5 seeds; reaching ±5.37 takes at least 20 seeds per setting)"
    )
    assert largest_z(19) < 5.37 <= largest_z(20) and fewest_seeds(5.37) == 20
    assert fewest_seeds(float("inf")) is None
    assert lines[2] == "  look 2, 10 seeds per setting: ±3.71" and len(lines) == 8
    # Equivalence needs the look's narrowest interval, at P = 1/2 and se at its floor, within
    # the margin: not at 20 seeds, at 25.
    critical = boundaries(0.05, tuple(n / 30 for n in design.looks), sides=1)
    assert narrowest_half_width(20, critical[3]) > 0.2 >= narrowest_half_width(25, critical[4])
    assert equivalence_reachable(design, 1) == 25
    assert lines[-1] == (
        "  equivalent (P(candidate > baseline) within 1/2 ± 0.2): reachable from 25 seeds per "
        "setting"
    )
    # Too narrow a margin for the design: a warning with the seeds a last look would need.
    narrow = plan_lines(Design(group_size=5, max_seeds=30, margin=0.05), 4)
    assert narrow[-1].startswith("  warning: no look can decide equivalent (P(candidate")
    needed = int(narrow[-1].split("needs about ")[1].split()[0])
    last = boundaries(0.0125, tuple(n / 30 for n in design.looks), sides=1)[-1]
    assert narrowest_half_width(needed, last) <= 0.05 < narrowest_half_width(needed - 1, last)
    assert plan_lines(Design(5, 30), 1)[-1].startswith("  look 6, 30 seeds")  # no margin
    # No look can decide: said once more, with the seeds the last look's boundary needs.
    never = plan_lines(Design(group_size=1, max_seeds=2), 1)
    assert never[2].endswith("with 2 seeds; reaching ±1.97 takes at least 4 seeds per setting)")
    assert never[-1] == (
        "  warning: no look of this design can decide better or worse, whatever the scores: its "
        "last look, 2 seeds per setting, needs 4 to reach ±1.97; plan more seeds (max_seeds) or "
        "fewer looks (a larger group_size)"
    )
    assert not any("no look" in line for line in plan_lines(Design(2, 4), 2))  # look 2 can
