"""The validation race that ends every tune, whatever scheduler searched: per arm, the `k`
finalists that the search carried furthest and the arm's default (trial 0) train the full budget
on validation seeds, a stream of their own (disjoint from the tuning seeds and from the test
seeds a study counts from 0), as one window, from scratch. A finalist replaces the default only
where the race's test shows it better (:mod:`fppo_jax.stats.race`: paired by seed, one-sided,
Holm over the finalists at the plan's level); otherwise the arm keeps its default. The setting
chosen is the race's, and its validation score is the tuned score a report gives: a score the
choice was not made on by the search (the search's own scores overstate the chosen, the
winner's curse; the record keeps both, finalist by finalist).

:class:`ValidationRace` wraps the search's scheduler: its windows first, then the race as one
more rung. What the race records of each arm (:class:`~fppo_jax.analysis.tuning_records.
RaceRecord`) sits beside the rung's rows; :func:`race_lines` says it in the report."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from fppo_jax.analysis.halving import ranked, seed_values, trial_row
from fppo_jax.analysis.population import Window
from fppo_jax.analysis.scheduling import Scheduler
from fppo_jax.analysis.tuning_records import (
    ArmResults,
    ArmRung,
    RaceRecord,
    RaceTest,
    RungScores,
    TrialScore,
)
from fppo_jax.stats import statistics
from fppo_jax.stats.race import RaceOutcome, race

# The race's test, as a plan names it: an id and version, never words.
RACE_TEST: RaceTest = {"id": "wilcoxon-signed-rank-holm", "version": 1}


class ValidationRace:
    """`search`, then the race of `finalists` per arm against its default on `seeds` over the
    full run of `end` updates, at family-wise `level` (see the module)."""

    def __init__(
        self,
        search: Scheduler,
        arms: Sequence[str],
        finalists: int,
        seeds: Sequence[int],
        end: int,
        level: float,
    ):
        self.search, self.arms, self.finalists = search, list(arms), finalists
        self.seeds, self.end, self.level = list(seeds), end, level

    @property
    def rounds(self) -> int:
        return self.search.rounds + 1

    @property
    def updates_per_call(self) -> int:
        return self.search.updates_per_call

    def searched(self, recorded: Sequence[RungScores]) -> int | None:
        """How many of `recorded` are the search's rungs, once it is done (None before)."""
        for rungs in range(len(recorded) + 1):
            if self.search.next_window(recorded[:rungs]) is None:
                return rungs
        return None

    def next_window(self, recorded: Sequence[RungScores]) -> Window | None:
        searched = self.searched(recorded)
        if searched is None:
            return self.search.next_window(recorded)
        if len(recorded) > searched:
            return None  # raced
        runs = tuple(
            (arm, trial, seed)
            for arm, trials in self.entrants(recorded).items()
            for trial in trials
            for seed in self.seeds
        )
        return Window(runs, 0, self.end)

    def entrants(self, recorded: Sequence[RungScores]) -> dict[str, list[int]]:
        """Per arm, its default (trial 0) and then its finalists, best first."""
        return {arm: [0, *finalists(recorded, arm, self.finalists)] for arm in self.arms}

    def measured(
        self, recorded: Sequence[RungScores], scores: np.ndarray, diverged: np.ndarray
    ) -> dict[str, ArmRung]:
        searched = self.searched(recorded)
        if searched is None:
            return self.search.measured(recorded, scores, diverged)
        window = self.next_window(recorded)
        assert window is not None
        measured: dict[str, ArmRung] = {}
        for arm, trials in self.entrants(recorded).items():
            rows = [trial_row(window, scores, diverged, arm, trial) for trial in trials]
            record = self._raced(recorded, arm, rows)
            measured[arm] = {"trials": rows, "survivors": [record["chosen"]], "race": record}
        return measured

    def _raced(
        self, recorded: Sequence[RungScores], arm: str, rows: list[TrialScore]
    ) -> RaceRecord:
        """The race of `rows`' finalists (all but the first, the default) against the default."""
        default = _scores(rows[0])
        contenders = [row["trial"] for row in rows[1:]]
        # No finalist (every sampled trial diverged or never scored): the default stays.
        found = (
            race(default, np.array([_scores(row) for row in rows[1:]]), self.level)
            if contenders
            else RaceOutcome((), (), (), None)
        )
        improvement = [_improvement(_scores(row), default) for row in rows[1:]]
        return {
            "test": {**RACE_TEST},
            "level": self.level,
            "finalists": contenders,
            "search_scores": [search_score(recorded, arm, row["trial"]) for row in rows[1:]],
            "default_score": rows[0]["score"],
            "validation_scores": [row["score"] for row in rows[1:]],
            "p": list(found.p),
            "adjusted": list(found.adjusted),
            "probability_of_improvement": improvement,
            "chosen": 0 if found.winner is None else contenders[found.winner],
        }


def race_lines(arms: dict[str, ArmResults], seeds: int) -> list[str]:
    """The report's account of each arm's validation race on `seeds` validation seeds (arms
    without one are left out)."""
    raced = {arm: found["race"] for arm, found in arms.items() if "race" in found}
    if not raced:
        return []
    first = next(iter(raced.values()))
    lines = [
        "",
        f"The validation race, on {seeds} validation seeds "
        f"(one-sided Wilcoxon signed-rank test against the default, paired by seed, Holm over "
        f"the finalists at level {first['level']:g}): a finalist's search score is the one that "
        "carried it, on the tuning seeds; its validation score, on seeds it was not chosen on, "
        "is the honest one.",
        "",
        "| arm | trial | search score | validation score | P(trial > default) [95%] | p | Holm p |",
        "|---|---|---|---|---|---|---|",
    ]
    for arm, record in raced.items():
        lines.append(f"| {arm} | 0 (default) | — | {_number(record['default_score'])} | | | |")
        for j, trial in enumerate(record["finalists"]):
            point, low, high = record["probability_of_improvement"][j]
            shown = "—" if point is None else f"{point:.2f} [{low:.2f}, {high:.2f}]"
            lines.append(
                f"| {arm} | {trial} | {_number(record['search_scores'][j])} | "
                f"{_number(record['validation_scores'][j])} | {shown} | {record['p'][j]:.3g} | "
                f"{record['adjusted'][j]:.3g} |"
            )
    lines.append("")
    lines += [_outcome(arm, record, seeds) for arm, record in raced.items()]
    return lines


def _outcome(arm: str, record: RaceRecord, seeds: int) -> str:
    """`arm`'s race in a sentence: the finalist chosen, or why the default stays, said plainly
    where the race could not tell them apart (a one-sided test shows no finalist worse)."""
    if record["chosen"] != 0:
        return (
            f"- {arm}: trial {record['chosen']} replaces the default, shown better on the "
            "validation seeds."
        )
    if not record["finalists"]:
        return f"- {arm}: the default stays: no sampled trial scored without diverging to race it."
    if all(high is not None and high < 0.5 for *_, high in record["probability_of_improvement"]):
        return (
            f"- {arm}: the default stays: no finalist was shown better than it, and each one's "
            "P(trial > default) interval lies below ½."
        )
    return (
        f"- {arm}: the default stays, undecided: no finalist was shown better than it, nor worse, "
        f"on {seeds} validation seeds; more seeds would be needed to tell them apart."
    )


def _number(x: float | None) -> str:
    return "—" if x is None or not math.isfinite(x) else f"{x:.1f}"


def finalists(recorded: Sequence[RungScores], arm: str, k: int) -> list[int]:
    """`arm`'s `k` sampled trials (not trial 0) that the search carried furthest, by the last
    rung each reached and then by its score there, best first; none that diverged or never
    scored."""
    reached: dict[int, tuple[int, float]] = {}
    for rung, scores in enumerate(recorded):
        for row in ranked(scores["arms"][arm]["trials"]):
            if row["trial"] != 0 and row["score"] is not None:
                reached[row["trial"]] = (rung, row["score"])
    dropped = {
        row["trial"] for s in recorded for row in s["arms"][arm]["trials"] if row["diverged"]
    }
    order = sorted(
        (t for t in reached if t not in dropped), key=lambda t: (-reached[t][0], -reached[t][1], t)
    )
    return order[:k]


def search_score(recorded: Sequence[RungScores], arm: str, trial: int) -> float | None:
    """`arm`'s `trial`'s score at the last rung of the search it reached."""
    found = None
    for scores in recorded:
        for row in scores["arms"][arm]["trials"]:
            if row["trial"] == trial:
                found = row["score"]
    return found


def _scores(row: TrialScore) -> np.ndarray:
    return seed_values(row["seed_scores"])


def _improvement(finalist: np.ndarray, default: np.ndarray) -> list[float | None]:
    """P(finalist > default) with its bootstrap interval, over the runs that scored (None
    where one side has none)."""
    x, y = finalist[np.isfinite(finalist)], default[np.isfinite(default)]
    if not (x.size and y.size):
        return [None, None, None]
    values = statistics.compare(x, y)["probability_of_improvement"]
    return [float(v) if math.isfinite(v) else None for v in values]
