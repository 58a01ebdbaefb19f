"""How a tune spends its budget, behind one interface: a :class:`Scheduler` says, from what the
rounds so far measured, which runs train next (arm, trial and seed each), from which update to
which, and from which earlier run's state each goes on (:class:`~fppo_jax.analysis.population.
Window`); and, once a round is measured, what it records of each arm's trials and which of them
are still in. The loop that trains the windows, records the rounds, joins an array's shares and
tells Optuna (:mod:`fppo_jax.analysis.tuning_rungs`) knows no scheduler: successive halving
(:class:`~fppo_jax.analysis.halving.SuccessiveHalving`) is one; a race over seeds, or
population-based training (a window whose runs go on from other runs' states, at settings of
their own), is a class with the same members.

A scheduler is a pure function of the rounds recorded: the same records give the same next
window, so a tune stopped anywhere goes on from its records, bit for bit."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import numpy as np

from fppo_jax.analysis.population import Window
from fppo_jax.analysis.tuning_records import ArmRung, RungScores


class Scheduler(Protocol):
    """What a tune's loop asks of a way to spend its budget (see the module)."""

    @property
    def rounds(self) -> int:
        """The most rounds it trains."""
        ...

    @property
    def updates_per_call(self) -> int:
        """Updates per compiled call: every window's start and end, but the run's last, fall on
        a whole number of calls."""
        ...

    def next_window(self, recorded: Sequence[RungScores]) -> Window | None:
        """What trains after the rounds `recorded` (None: the tune of this task is done)."""
        ...

    def measured(
        self, recorded: Sequence[RungScores], scores: np.ndarray, diverged: np.ndarray
    ) -> dict[str, ArmRung]:
        """The record of the round after `recorded`, from its runs' `scores` (the tune's score
        at the window's end, NaN where there is none) and whether each `diverged`: per arm, its
        trials' rows and the trials still in."""
        ...
