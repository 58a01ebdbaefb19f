"""The sequential rule's operating characteristics (:func:`simulate`): its error rates, power
and seeds on synthetic normal scores, with no training, at a shift of the candidates' scores
(:func:`shift_for`)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from fppo_jax.stats.sequential import Design, decide


def shift_for(probability: float) -> float:
    """The shift in sd of two normal distributions of equal sd at which P(candidate >
    baseline) is `probability`: √2·Φ⁻¹(p), since the difference of two draws has sd √2."""
    from scipy import special

    return float(np.sqrt(2) * special.ndtri(probability))


def simulate(
    design: Design,
    candidates_per_task: Sequence[int],
    *,
    shift: float = 0.0,
    studies: int = 2000,
    seed: int = 0,
) -> dict[str, float]:
    """The rule's operating characteristics, by simulating `studies` studies on synthetic
    scores, no training: on each task a baseline and `candidates_per_task[i]` candidates, every
    score normal with sd 1, each candidate's mean `shift` above its baseline's (below, if
    negative), so that P(candidate > baseline) = Φ(shift / √2) (:func:`shift_for`).

    Returns ``false_decision_rate``: the share of studies with any comparison decided ``better``
    or ``worse`` against the truth (with ``shift=0`` any such decision, the family-wise error;
    else any in the wrong direction); ``power``: the share of comparisons decided ``better``;
    ``equivalent``: the share decided ``equivalent`` (0 without a margin);
    ``false_equivalence_rate``: the share of studies with any comparison decided ``equivalent``
    where P(candidate > baseline) is at or beyond the margin (|P − ½| ≥ δ, to 1e-9; else 0);
    ``seeds``: the mean seeds per setting a comparison used; ``runs``: the mean runs a study
    trained (a task's baseline runs as long as any of its candidates). Seeded, so it
    repeats."""
    from scipy import special

    rng = np.random.default_rng(seed)
    n = design.max_seeds
    false, better, equivalent, false_equivalent, seeds, runs = 0, 0, 0, 0, 0, 0
    comparisons = sum(candidates_per_task)
    wrong = ("worse",) if shift > 0 else ("better",) if shift < 0 else ("better", "worse")
    distance = abs(float(special.ndtr(shift / np.sqrt(2))) - 0.5)
    beyond = design.margin is not None and distance >= design.margin - 1e-9
    for _ in range(studies):
        scores = []
        for count in candidates_per_task:
            baseline = rng.standard_normal(n)
            scores += [(rng.standard_normal(n) + shift, baseline) for _ in range(count)]
        decisions = decide(scores, design)
        false += any(d.decision in wrong for d in decisions)
        better += sum(d.decision == "better" for d in decisions)
        said = sum(d.decision == "equivalent" for d in decisions)
        equivalent += said
        false_equivalent += beyond and said > 0
        used = [d.seeds for d in decisions]
        seeds += sum(used)
        start = 0
        for count in candidates_per_task:
            runs += sum(used[start : start + count]) + max(used[start : start + count])
            start += count
    return {
        "false_decision_rate": false / studies,
        "power": better / (studies * comparisons),
        "equivalent": equivalent / (studies * comparisons),
        "false_equivalence_rate": false_equivalent / studies,
        "seeds": seeds / (studies * comparisons),
        "runs": runs / studies,
    }
