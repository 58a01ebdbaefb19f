"""How a tune spends its budget, checked before any plan and recorded in it: the search's
scheduler (successive halving over updates, or racing over seeds), the tuning seeds, the score
each trial is ranked on (the study's evaluation endpoint by default), and the validation race
that ends every tune (its finalists, its seeds, its level). :meth:`TuneDesign.scheduler` gives a
task's scheduler; :meth:`TuneDesign.plan_fields` what ``tune.json`` records of the design.

Three streams of seeds never meet: tests count from 0 (a study's), tuning seeds from
:data:`TUNING_SEED_START`, validation seeds from :data:`VALIDATION_SEED_START`."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from fppo_jax.analysis.halving import Rungs, SuccessiveHalving, schedule
from fppo_jax.analysis.racing import Racing
from fppo_jax.analysis.scheduling import Scheduler
from fppo_jax.analysis.tuning_records import TaskBudget
from fppo_jax.analysis.validation_race import RACE_TEST, ValidationRace
from fppo_jax.core.checks import MAX_SEEDS, check_seeds, positive_int
from fppo_jax.errors import InvalidInput
from fppo_jax.run.execution import updates_per_call
from fppo_jax.run.prepare import Prepared
from fppo_jax.stats.race import smallest_p
from fppo_jax.stats.sequential import check_level

TUNING_SEED_START = 1_000_000
VALIDATION_SEED_START = 2_000_000
TEST_SEEDS_BELOW = MAX_SEEDS  # a study's test seeds count from 0, at most MAX_SEEDS of them

SCHEDULERS = ("halving", "racing")
SCORES = ("eval", "train")

SCORE_WORDS = {
    "eval": "a run's deterministic policy's mean return over {episodes} evaluation episodes at "
    "the end of the rung (the study's eval endpoint)",
    "train": "a run's training return at the end of the rung (the mean of its last 100 episodes)",
}
SCORE_RULE = (
    "; a trial's score is the mean over its tuning seeds; a trial with a run that finished no "
    "episode ranks below every trial with a score (ties by trial number), and one with a run "
    "that diverged stops"
)
SELECTION = (
    "per task and arm: the {finalists} sampled trials the search carried furthest (by the last "
    "rung each reached, then its score there) and the default race on the validation seeds; a "
    "finalist replaces the default only where the one-sided Wilcoxon signed-rank test, paired "
    "by seed, Holm over the finalists at level {level}, shows it better; then the best mean "
    "among those that did"
)

ROUND_CALLS = 10  # compiled calls a racing round is split into, at most, for progress


@dataclasses.dataclass(frozen=True)
class TuneDesign:
    """A tune's design (see the module): `scheduler` over `trials` per arm with `seeds` (halving:
    each trial's; racing: ``rounds × per_round``, each round's in turn), halving's `eta`, the
    `score` and its `eval_episodes`, and the race of `finalists` on `validation` seeds at
    `level`."""

    scheduler: str
    trials: int
    seeds: list[int]
    eta: int
    per_round: int
    score: str
    eval_episodes: int
    finalists: int
    validation: list[int]
    level: float

    def scheduler_for(self, arms: Sequence[str], prepared: Prepared) -> Scheduler:
        """The task's scheduler: the search, then the validation race."""
        end = prepared.config.num_updates
        search: Scheduler
        if self.scheduler == "halving":
            search = SuccessiveHalving(arms, self.trials, self.seeds, self.rungs(end))
        else:
            per_call = updates_per_call(end, ROUND_CALLS)
            search = Racing(
                arms, self.trials, self.seeds, self.per_round, end, per_call, self.level
            )
        return ValidationRace(search, arms, self.finalists, self.validation, end, self.level)

    def rungs(self, end: int) -> Rungs:
        """Successive halving's rungs over a run of `end` updates."""
        return schedule(self.trials, self.eta, end)

    def budget_of(self, prepared: Prepared) -> TaskBudget:
        """What the plan records of a task's budget per arm."""
        samples, end = prepared.config.samples_per_update, prepared.config.num_updates
        race = (self.finalists + 1) * len(self.validation) * end
        budget: TaskBudget = {"env_steps_per_arm": 0, "env_steps_per_full_run": end * samples}
        if self.scheduler == "halving":
            rungs = self.rungs(end)
            updates = rungs.updates_per_arm(len(self.seeds)) + race
            budget["rungs"] = rungs.to_json(samples)
        else:
            updates = self.trials * len(self.seeds) * end + race
        budget["env_steps_per_arm"] = updates * samples
        budget["full_runs_per_arm"] = updates / end
        return budget

    def plan_fields(self) -> dict[str, object]:
        """What ``tune.json`` records of the design, beside the budget per task."""
        searched: dict[str, object] = {"name": self.scheduler}
        if self.scheduler == "halving":
            searched["eta"] = self.eta
        else:
            searched |= {"seeds_per_round": self.per_round, "level": self.level}
        return {
            "search": searched,
            "score": SCORE_WORDS[self.score].format(episodes=self.eval_episodes) + SCORE_RULE,
            "validation": {
                "finalists": self.finalists,
                "seeds": self.validation,
                "level": self.level,
                "test": {**RACE_TEST},
            },
            "selection": SELECTION.format(finalists=self.finalists, level=self.level),
        }


def design(
    scheduler: str,
    trials: int,
    seeds: int | Sequence[int],
    eta: int,
    budget: int | None,
    score: str,
    eval_episodes: int,
    finalists: int,
    validation_seeds: int | Sequence[int],
    level: float,
) -> TuneDesign:
    """The design of a tune's arguments, each checked and named where refused (see
    :func:`~fppo_jax.tune`)."""
    if scheduler not in SCHEDULERS:
        raise InvalidInput(f"scheduler must be one of {', '.join(SCHEDULERS)}, got {scheduler!r}")
    if score not in SCORES:
        raise InvalidInput(f"score must be one of {', '.join(SCORES)}, got {score!r}")
    trials, episodes = positive_int("trials", trials), positive_int("eval_episodes", eval_episodes)
    level = check_level(level)
    finalists = positive_int("finalists (the race's, k)", finalists)
    if finalists >= trials:
        raise InvalidInput(
            f"finalists ({finalists}) must be fewer than the trials ({trials}): trial 0, the "
            "default, races them"
        )
    validation = check_seeds(validation_seeds, first=VALIDATION_SEED_START)
    if smallest_p(len(validation)) >= level / finalists:
        raise InvalidInput(
            f"a race of {finalists} finalists on {len(validation)} validation seeds can never "
            f"replace the default at level {level:g} (its smallest p, 2^-{len(validation)}, is "
            f"not below {level:g}/{finalists}): give more validation_seeds or fewer finalists"
        )
    if scheduler == "halving":
        tuning = check_seeds(seeds, first=TUNING_SEED_START)
        per_round = len(tuning)
        if per_round < 2:
            raise InvalidInput(
                "successive halving ranks each trial on the mean of its seeds: give at least 2 "
                f"tuning seeds per trial, got {per_round}"
            )
    else:
        per_round = positive_int("seeds (per round)", seeds) if isinstance(seeds, int) else 0
        if not per_round:
            raise InvalidInput("racing takes seeds as a count per round, drawn from the stream")
        tuning = _racing_seeds(trials, per_round, finalists, len(validation), budget)
    overlap = sorted(set(tuning) & set(validation))
    if overlap:
        raise InvalidInput(f"validation seeds {overlap} are also tuning seeds: keep them apart")
    tests = sorted(seed for seed in {*tuning, *validation} if seed < TEST_SEEDS_BELOW)
    if tests:
        raise InvalidInput(
            f"seeds {tests[:5]}{' …' if len(tests) > 5 else ''} are a study's test seeds (it "
            f"counts from 0): tune and validate on seeds from {TEST_SEEDS_BELOW:,} on"
        )
    halving_eta = _eta(eta) if scheduler == "halving" else 0
    return TuneDesign(
        scheduler,
        trials,
        tuning,
        halving_eta,
        per_round,
        score,
        episodes,
        finalists,
        validation,
        level,
    )


def _racing_seeds(
    trials: int, per_round: int, finalists: int, validation: int, budget: int | None
) -> list[int]:
    """The tuning seeds of as many racing rounds as `budget` full runs per arm holds beside the
    race's."""
    if budget is None:
        raise InvalidInput("racing spends a budget: give budget (full runs per arm and task)")
    race = (finalists + 1) * validation
    rounds = (positive_int("budget", budget) - race) // (trials * per_round)
    if rounds < 1:
        raise InvalidInput(
            f"a budget of {budget} full runs per arm cannot hold one round of {trials} trials × "
            f"{per_round} seeds ({trials * per_round} runs) beside the validation race's {race}: "
            f"give at least {race + trials * per_round}"
        )
    return list(range(TUNING_SEED_START, TUNING_SEED_START + rounds * per_round))


def _eta(eta: object) -> int:
    if isinstance(eta, bool) or not isinstance(eta, int | np.integer) or eta < 2:
        raise InvalidInput(f"eta (the halving rate) must be an integer of at least 2, got {eta!r}")
    return int(eta)
