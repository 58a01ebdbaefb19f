"""Successive halving (Jamieson and Talwalkar, AISTATS 2016), as a tune spends its budget:
the rungs of a population of trials (:func:`schedule`: how many trials each rung keeps, and the
update it ends at), the rule that ranks a rung's trials (:func:`ranked`), whose best ``1/eta``
go on from where they stopped, and the two as a tune's scheduler (:class:`SuccessiveHalving`)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from fppo_jax.analysis.population import Window
from fppo_jax.analysis.rung_evidence import evidence
from fppo_jax.analysis.tuning_records import ArmRung, RungPlan, RungScores, TrialScore
from fppo_jax.errors import InvalidInput

CALLS_A_RUNG = 10  # compiled calls the first rung is split into, at least, for progress


@dataclasses.dataclass(frozen=True)
class Rungs:
    """A successive-halving schedule: the live `trials` of each arm at each rung, the update
    each rung ends at (the last one the run's end), and the updates per compiled call."""

    trials: tuple[int, ...]
    ends: tuple[int, ...]

    @property
    def updates_per_call(self) -> int:
        """The largest divisor of the first rung's length that is at most a
        :data:`CALLS_A_RUNG`-th of it (1 for a shorter rung): every rung but the last, whose end
        the run's length stops, is then whole calls, and progress is told between them."""
        first = self.ends[0]
        return (
            max(d for d in range(1, first // CALLS_A_RUNG + 1) if first % d == 0)
            if (first >= CALLS_A_RUNG)
            else 1
        )

    def to_json(self, samples_per_update: int) -> list[RungPlan]:
        return [
            {"trials": n, "ends_at_update": end, "env_steps_per_run": end * samples_per_update}
            for n, end in zip(self.trials, self.ends, strict=True)
        ]

    def updates_per_arm(self, seeds: int) -> int:
        """Updates every arm trains over the rungs: its live trials × seeds × each rung's."""
        starts = (0, *self.ends[:-1])
        return seeds * sum(
            n * (end - start) for n, start, end in zip(self.trials, starts, self.ends, strict=True)
        )


def schedule(trials: int, eta: int, num_updates: int) -> Rungs:
    """The rungs of `trials` trials halved by `eta` over a run of `num_updates` updates: as
    many rungs as `eta` divides the trials down to one, rung r (from 0) keeping
    ``trials // eta**r`` of them and ending at update ``first · eta**r`` (the last at the run's
    end), ``first = num_updates // eta**(rungs − 1)``."""
    count = 1
    while eta**count <= trials:
        count += 1
    first = num_updates // eta ** (count - 1)
    if first < 1:
        raise InvalidInput(
            f"a run of {num_updates} updates is too short for {count} rungs of η = {eta} (the "
            f"first rung would be {num_updates}/{eta ** (count - 1)} of an update): give more "
            "total_steps, fewer trials or a smaller eta"
        )
    ends = (*(first * eta**r for r in range(count - 1)), num_updates)
    return Rungs(tuple(max(1, trials // eta**r) for r in range(count)), ends)


def ranked(rows: list[TrialScore]) -> list[TrialScore]:
    """A rung's trials best first, those that diverged left out: by score, then those without
    one (no episode finished), ties by trial number."""
    alive = [row for row in rows if not row["diverged"]]
    return sorted(alive, key=lambda r: (r["score"] is None, -(r["score"] or 0.0), r["trial"]))


class SuccessiveHalving:
    """Successive halving as a :class:`~fppo_jax.analysis.scheduling.Scheduler`: round r trains
    each arm's live trials × `seeds` from the end of round r − 1 (its own runs' states) to
    ``rungs.ends[r]``; after it, each arm keeps its best ``rungs.trials[r + 1]`` trials by
    :func:`ranked`, and after the last round the best one; a rung whose trials tie keeps them
    all (:func:`~fppo_jax.analysis.rung_evidence.tied`), and each records its evidence."""

    def __init__(self, arms: Sequence[str], trials: int, seeds: Sequence[int], rungs: Rungs):
        self.arms, self.trials, self.seeds, self.rungs = list(arms), trials, list(seeds), rungs

    @property
    def rounds(self) -> int:
        return len(self.rungs.trials)

    @property
    def updates_per_call(self) -> int:
        return self.rungs.updates_per_call

    def live(self, recorded: Sequence[RungScores]) -> dict[str, list[int]]:
        """Each arm's trials in the round after `recorded`."""
        if not recorded:
            return {arm: list(range(self.trials)) for arm in self.arms}
        return {arm: list(recorded[-1]["arms"][arm]["survivors"]) for arm in self.arms}

    def next_window(self, recorded: Sequence[RungScores]) -> Window | None:
        rung = len(recorded)
        if rung >= self.rounds:
            return None
        live = self.live(recorded)
        runs = tuple((arm, t, seed) for arm in self.arms for t in live[arm] for seed in self.seeds)
        if rung == 0:
            return Window(runs, 0, self.rungs.ends[0])
        before = self.next_window(recorded[:-1])
        assert before is not None
        where = {run: i for i, run in enumerate(before.runs)}
        continues = tuple(where[run] for run in runs)
        return Window(runs, self.rungs.ends[rung - 1], self.rungs.ends[rung], continues)

    def measured(
        self, recorded: Sequence[RungScores], scores: np.ndarray, diverged: np.ndarray
    ) -> dict[str, ArmRung]:
        window = self.next_window(recorded)
        assert window is not None
        going_on = self.rungs.trials[min(len(recorded) + 1, self.rounds - 1)]
        measured: dict[str, ArmRung] = {}
        for arm, trials in self.live(recorded).items():
            rows = [trial_row(window, scores, diverged, arm, trial) for trial in trials]
            before = recorded[-1]["arms"][arm]["trials"] if recorded else None
            found = evidence(rows, before)
            # A tie cuts none: the trials' numbers, not their scores, would choose.
            kept = ranked(rows) if found["tied"] else ranked(rows)[:going_on]
            survivors = sorted(r["trial"] for r in kept)
            measured[arm] = {"trials": rows, "survivors": survivors, "evidence": found}
        return measured


def trial_row(
    window: Window,
    scores: np.ndarray,
    diverged: np.ndarray,
    arm: str,
    trial: int,
    before: TrialScore | None = None,
) -> TrialScore:
    """`arm`'s `trial`'s row after `window`: its runs' scores there (after `before`'s, for a
    trial that goes on adding seeds), their mean (None where not finite: a run without a score)
    and whether a run diverged."""
    runs = [i for i, (a, t, _) in enumerate(window.runs) if a == arm and t == trial]
    new = [float(v) if math.isfinite(v) else None for v in np.asarray(scores, float)[runs]]
    seed_scores = [*(before["seed_scores"] if before else []), *new]
    mean = float(np.mean(seed_values(seed_scores)))
    return {
        "trial": trial,
        "score": mean if math.isfinite(mean) else None,
        "seed_scores": seed_scores,
        "diverged": bool(np.asarray(diverged)[runs].any()) or bool(before and before["diverged"]),
    }


def seed_values(seed_scores: Sequence[float | None]) -> np.ndarray:
    """A row's seed scores as numbers, NaN for a run without a score."""
    return np.array([math.nan if v is None else v for v in seed_scores], float)
