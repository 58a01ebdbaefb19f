"""Racing as a tune's scheduler: the budget spent in seeds, not in updates. Every run trains
the full budget from scratch (ranks at a part of the budget need not carry to its end); round
r trains each arm's trials still in on the round's fresh tuning seeds, as one window. After it,
per arm, the incumbent (the best mean over the seeds every trial still in shares) stays, and any
other trial is dropped where the paired one-sided signed-rank test on those seeds
(:func:`~fppo_jax.stats.race.signed_rank_p`) shows the incumbent better at the plan's level; a
trial the seeds cannot tell from the incumbent goes on to more seeds. It ends after its rounds,
or when each arm has one trial left. As in F-Race and irace (Birattari et al. 2002; López-Ibáñez
et al. 2016), only contenders get seeds, and the incumbent is measured again on every one.

A drop is no claim about a setting, so the level is not adjusted over the trials: the validation
race (:mod:`fppo_jax.analysis.validation_race`) decides what replaces the default."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from fppo_jax.analysis.halving import seed_values, trial_row
from fppo_jax.analysis.population import Window
from fppo_jax.analysis.tuning_records import ArmRung, RungScores, TrialScore
from fppo_jax.stats.race import signed_rank_p


class Racing:
    """Each arm's `trials` raced over `rounds` rounds of `seeds_per_round` of the tuning
    `seeds` (``rounds · seeds_per_round`` of them, in order), each run `end` updates long, a
    trial dropped at `level` (see the module)."""

    def __init__(
        self,
        arms: Sequence[str],
        trials: int,
        seeds: Sequence[int],
        seeds_per_round: int,
        end: int,
        updates_per_call: int,
        level: float,
    ):
        self.arms, self.trials, self.seeds = list(arms), trials, list(seeds)
        self.seeds_per_round, self.end, self.level = seeds_per_round, end, level
        self._updates_per_call = updates_per_call

    @property
    def rounds(self) -> int:
        return len(self.seeds) // self.seeds_per_round

    @property
    def updates_per_call(self) -> int:
        return self._updates_per_call

    def live(self, recorded: Sequence[RungScores]) -> dict[str, list[int]]:
        """Each arm's trials still in after `recorded`."""
        if not recorded:
            return {arm: list(range(self.trials)) for arm in self.arms}
        return {arm: list(recorded[-1]["arms"][arm]["survivors"]) for arm in self.arms}

    def next_window(self, recorded: Sequence[RungScores]) -> Window | None:
        live = self.live(recorded)
        if len(recorded) >= self.rounds or (recorded and all(len(t) <= 1 for t in live.values())):
            return None
        first = len(recorded) * self.seeds_per_round
        seeds = self.seeds[first : first + self.seeds_per_round]
        runs = tuple((arm, t, seed) for arm in self.arms for t in live[arm] for seed in seeds)
        return Window(runs, 0, self.end)

    def measured(
        self, recorded: Sequence[RungScores], scores: np.ndarray, diverged: np.ndarray
    ) -> dict[str, ArmRung]:
        window = self.next_window(recorded)
        assert window is not None
        measured: dict[str, ArmRung] = {}
        for arm, trials in self.live(recorded).items():
            last = recorded[-1]["arms"][arm]["trials"] if recorded else []
            before = {row["trial"]: row for row in last}
            rows = [trial_row(window, scores, diverged, arm, t, before.get(t)) for t in trials]
            measured[arm] = {"trials": rows, "survivors": self._still_in(rows)}
        return measured

    def _still_in(self, rows: list[TrialScore]) -> list[int]:
        """The incumbent and every trial the shared seeds cannot show worse than it."""
        alive = [row for row in rows if not row["diverged"]]
        if not alive:
            return []
        incumbent = max(alive, key=lambda r: (_mean(r), -r["trial"]))
        best = seed_values(incumbent["seed_scores"])
        return sorted(
            row["trial"]
            for row in alive
            if row is incumbent
            or signed_rank_p(best, seed_values(row["seed_scores"])) >= self.level
        )


def _mean(row: TrialScore) -> float:
    values = seed_values(row["seed_scores"])
    return float(np.mean(np.where(np.isfinite(values), values, -np.inf)))
