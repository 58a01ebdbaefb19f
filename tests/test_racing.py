"""fppo_jax.analysis.racing: each round trains only the contenders, on the round's fresh seeds,
from scratch to the full budget; a trial is dropped only where its seeds show it worse than the
incumbent, and the race ends after its rounds or when one trial per arm is left."""

import numpy as np

from fppo_jax.analysis.racing import Racing

SEEDS = list(range(1_000_000, 1_000_008))


def _racing(level=0.05):
    return Racing(["ppo"], 3, SEEDS, 2, end=8, updates_per_call=2, level=level)


def _round(racing, recorded, score_of):
    window = racing.next_window(recorded)
    scores = np.array([score_of(trial, seed) for _, trial, seed in window.runs])
    return {"arms": racing.measured(recorded, scores, np.zeros(len(scores), bool))}


def test_contenders_alone_get_the_next_seeds_from_scratch():
    racing, recorded = _racing(), []
    window = racing.next_window(recorded)
    assert window.runs == tuple(("ppo", t, s) for t in range(3) for s in SEEDS[:2])
    assert (window.start, window.end, window.continues) == (0, 8, None)
    # Trial 2 far below the others on every seed; trials 0 and 1 alike.
    clearly = {0: 10.0, 1: 10.0, 2: 0.0}
    for _ in range(2):
        recorded.append(_round(racing, recorded, lambda t, s: clearly[t] + (s % 3) * 0.1 * t))
    assert recorded[-1]["arms"]["ppo"]["survivors"] == [0, 1, 2]  # 4 seeds: p ≥ 2^-4 > 0.05
    recorded.append(_round(racing, recorded, lambda t, s: clearly[t] + (s % 3) * 0.1 * t))
    rows = recorded[-1]["arms"]["ppo"]
    assert [len(r["seed_scores"]) for r in rows["trials"]] == [6, 6, 6]
    assert rows["survivors"] == [0, 1]  # 6 seeds: p = 2^-6 < 0.05, trial 2 dropped
    window = racing.next_window(recorded)
    assert {t for _, t, _ in window.runs} == {0, 1}
    assert {s for *_, s in window.runs} == set(SEEDS[6:8])


def test_the_race_ends_after_its_rounds_or_with_one_trial_left():
    racing, recorded = _racing(level=0.5), []
    for _ in range(4):  # alike on every seed: none is shown worse
        recorded.append(_round(racing, recorded, lambda t, s: 1.0))
    assert racing.next_window(recorded) is None and racing.rounds == 4
    one = Racing(["ppo"], 2, SEEDS, 2, end=8, updates_per_call=2, level=0.5)
    first = [_round(one, [], lambda t, s: float(10 * t))]
    assert first[0]["arms"]["ppo"]["survivors"] == [1]  # p = 0.25 < 0.5
    assert one.next_window(first) is None
