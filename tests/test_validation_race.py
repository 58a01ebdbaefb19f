"""fppo_jax.analysis.validation_race: after the search, the finalists it carried furthest and
the default train the full budget on the validation seeds; where every finalist is the default
in disguise the default stays, where one is clearly better it is chosen; the record keeps each
finalist's search score beside its validation score."""

import numpy as np

from fppo_jax.analysis.population import Window
from fppo_jax.analysis.validation_race import ValidationRace, finalists, race_lines

VALIDATION = list(range(2_000_000, 2_000_008))


def row(trial, score, diverged=False):
    return {"trial": trial, "score": score, "seed_scores": [score], "diverged": diverged}


# The search: two rungs, the second of trials 2 and 3; trial 1 diverged.
SEARCHED = [
    {
        "arms": {
            "ppo": {
                "trials": [row(0, 5.0), row(1, None, True), row(2, 9.0), row(3, 8.0), row(4, 7.0)],
                "survivors": [2, 3],
            }
        }
    },
    {"arms": {"ppo": {"trials": [row(2, 20.0), row(3, 30.0)], "survivors": [3]}}},
]


class TwoRungs:
    """A search that has run once it has two rungs."""

    rounds, updates_per_call = 2, 1

    def next_window(self, recorded):
        return None if len(recorded) >= 2 else Window((("ppo", 0, 1),), 0, 8)

    def measured(self, recorded, scores, diverged):
        raise AssertionError("the search is over")


def _race():
    return ValidationRace(TwoRungs(), ["ppo"], 3, VALIDATION, end=8, level=0.05)


def test_the_finalists_are_those_carried_furthest_then_the_best_there():
    assert finalists(SEARCHED, "ppo", 3) == [3, 2, 4]  # not 0 (the default), not 1 (diverged)
    window = _race().next_window(SEARCHED)
    assert window.runs == tuple(("ppo", t, s) for t in (0, 3, 2, 4) for s in VALIDATION)
    assert (window.start, window.end, window.continues) == (0, 8, None)
    assert _race().rounds == 3 and _race().next_window([*SEARCHED, {"arms": {}}]) is None


def _measured(score_of):
    race = _race()
    window = race.next_window(SEARCHED)
    scores = np.array([score_of(trial, seed) for _, trial, seed in window.runs])
    return race.measured(SEARCHED, scores, np.zeros(len(scores), bool))["ppo"]


def test_finalists_that_are_the_default_in_disguise_leave_the_default():
    found = _measured(lambda trial, seed: float(seed % 5))  # every trial alike, seed by seed
    assert found["survivors"] == [0] and found["race"]["chosen"] == 0
    assert found["race"]["p"] == [1.0, 1.0, 1.0]
    # Not shown better, and no worse: the report says so plainly, and what would tell them apart.
    assert race_lines({"ppo": found}, len(VALIDATION))[-1] == (
        "- ppo: the default stays, undecided: no finalist was shown better than it, nor worse, "
        "on 8 validation seeds; more seeds would be needed to tell them apart."
    )


def test_finalists_all_below_the_default_leave_it_and_are_not_called_undecided():
    found = _measured(lambda trial, seed: float(seed % 5) - (0.0 if trial == 0 else 3.0))
    assert found["race"]["chosen"] == 0
    assert race_lines({"ppo": found}, len(VALIDATION))[-1] == (
        "- ppo: the default stays: no finalist was shown better than it, and each one's "
        "P(trial > default) interval lies below ½."
    )


def test_a_finalist_clearly_better_is_chosen_and_its_search_score_kept_beside():
    found = _measured(lambda trial, seed: float(seed % 5) + (3.0 if trial == 2 else 0.0))
    record = found["race"]
    assert found["survivors"] == [2] and record["chosen"] == 2
    assert record["finalists"] == [3, 2, 4] and record["search_scores"] == [30.0, 20.0, 7.0]
    assert record["adjusted"][1] < 0.05 <= min(record["adjusted"][0], record["adjusted"][2])
    assert record["probability_of_improvement"][1][0] > 0.5
    lines = race_lines({"ppo": {"race": record}}, len(VALIDATION))
    assert "| ppo | 2 | 20.0 |" in "\n".join(lines)
    assert "- ppo: trial 2 replaces the default" in lines[-1]


def test_an_arm_without_a_finalist_keeps_its_default():
    searched = [{"arms": {"ppo": {"trials": [row(0, 5.0), row(1, None)], "survivors": [0]}}}]
    race = ValidationRace(TwoRungs(), ["ppo"], 1, VALIDATION, end=8, level=0.05)
    window = race.next_window([*searched, *searched])
    assert {t for _, t, _ in window.runs} == {0}
    scores = np.arange(len(window.runs), dtype=float)
    found = race.measured([*searched, *searched], scores, np.zeros(len(scores), bool))["ppo"]
    assert found["survivors"] == [0] and found["race"]["finalists"] == []
    assert race_lines({"ppo": found}, len(VALIDATION))[-1] == (
        "- ppo: the default stays: no sampled trial scored without diverging to race it."
    )
