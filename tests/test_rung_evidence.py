"""fppo_jax.analysis.rung_evidence: a tie is seen, trials apart beyond their seeds' noise give a
small p, alike ones a large one, and ranks that carry from the rung before a ρ near 1."""

from fppo_jax.analysis.rung_evidence import evidence, tied


def row(trial, seed_scores, diverged=False):
    scores = [s for s in seed_scores if s is not None]
    score = sum(scores) / len(scores) if scores and len(scores) == len(seed_scores) else None
    return {"trial": trial, "score": score, "seed_scores": seed_scores, "diverged": diverged}


def test_a_rung_whose_trials_score_alike_is_tied():
    assert tied([row(0, [-200.0, -200.0]), row(1, [-200.0, -200.0]), row(2, [5.0], True)])
    assert not tied([row(0, [1.0, 2.0]), row(1, [1.0, 3.0])])
    assert not tied([row(0, [1.0, 2.0])])  # one trial: nothing to cut
    found = evidence([row(0, [-200.0, -200.0]), row(1, [-200.0, -200.0])], None)
    assert found == {"tied": True, "variance_ratio": None, "p": None, "rank_correlation": None}


def test_trials_apart_beyond_their_noise_give_a_small_p_and_alike_ones_a_large_one():
    apart = [row(t, [10.0 * t, 10.0 * t + 1, 10.0 * t - 1]) for t in range(4)]
    alike = [row(t, [1.0 + 0.1 * t, -1.0, 0.5]) for t in range(4)]
    found, noise = evidence(apart, None), evidence(alike, None)
    assert found["p"] < 1e-6 < 0.5 < noise["p"] and found["variance_ratio"] > 100
    assert not found["tied"] and found["rank_correlation"] is None


def test_ranks_that_carry_from_the_rung_before():
    before = [row(t, [float(t), float(t)]) for t in range(4)]
    same = [row(t, [float(t) + 5, float(t) + 5]) for t in range(4)]
    turned = [row(t, [float(-t), float(-t)]) for t in range(4)]
    assert evidence(same, before)["rank_correlation"] == 1.0
    assert evidence(turned, before)["rank_correlation"] == -1.0
    assert evidence(same[:2], before)["rank_correlation"] is None  # two pairs: no ρ
