"""The decision rule of a study that adds seeds until it can answer: a group-sequential
Mann–Whitney test with Lan–DeMets α-spending, Holm's procedure across comparisons.

A study (:mod:`fppo_jax.study`) compares candidates with a baseline, each comparison on one
task, and trains seeds in groups of ``group_size`` up to ``max_seeds``; after each group (a
*look*) this rule decides each comparison — ``better``, ``worse`` — or asks for more seeds.
It is a pure function of the scores so far and the :class:`Design`.

**The statistic.** At look k a comparison holds n_k = min(k·group_size, max_seeds) scores of
each setting, seeds 0 … n_k − 1. Its Mann–Whitney statistic U_k counts the pairs (candidate
run, baseline run) where the candidate scores higher, ties counting ½ (U_k / n_k² is the
probability of improvement of :mod:`fppo_jax.statistics`), standardised under the null
hypothesis that neither setting tends to score higher:

    Z_k = (U_k − n_k²/2) / σ_k,   σ_k² = n_k²/12 · (2n_k + 1 − Σ(t³ − t) / (2n_k(2n_k − 1)))

(t: the sizes of groups of tied scores). As n grows the sequence Z_1, Z_2, … behaves as a
Brownian motion observed at the information fractions t_k = n_k / max_seeds: each Z_k is
standard normal and corr(Z_j, Z_k) = √(t_j / t_k) (the U-statistic's projection on its
runs is a sum over seeds).

**The boundaries.** Each comparison, tested at level a, crosses at the first look where
|Z_k| ≥ c_k(a): ``better`` if Z_k > 0, ``worse`` if Z_k < 0. The critical values spend a over
the looks by Lan and DeMets' (1983) O'Brien–Fleming-type function

    a*(t) = 4 − 4Φ(Φ⁻¹(1 − a/4) / √t)

(each side spends a/2 by the one-sided function 2 − 2Φ(Φ⁻¹(1 − a/4) / √t)), so that
P(cross by look k) = a*(t_k) under the null hypothesis: c_1 = Φ⁻¹(1 − a*(t_1)/2),
and each later c_k solves P(|Z_j| < c_j for j < k, |Z_k| ≥ c_k) = a*(t_k) − a*(t_{k−1}) by
numerical integration over the Brownian motion's values at the earlier looks (Armitage,
McPherson and Rowe 1969; Jennison and Turnbull 2000, ch. 19). Early looks spend almost
nothing (c_1 ≈ 4.9 of five looks at a = 0.05), so only a difference that few seeds already
show beyond doubt stops a comparison early, and the last look's boundary is close to the
fixed design's (2.03 against 1.96).

**The family.** m comparisons share α by Holm's (1979) procedure in its sequential form
(Maurer and Bretz 2013; Ye et al. 2013): each comparison not yet decided is tested at
α / (the number not yet decided); when one is decided its share passes to the others, which
are then tested again at their larger level on every look so far. Whatever the dependence
between the comparisons (candidates share their task's baseline runs), the chance that any
comparison is decided ``better`` or ``worse`` where its two settings score alike is at most α.
A comparison that reaches ``max_seeds`` without crossing is ``undecided``.

Why this rule: it gives each comparison its own stopping time (a decided one stops costing
seeds while the others go on) with an error bound that holds for any number of comparisons
and any dependence between them, using the rank statistic the project's comparisons already
report, whose level does not depend on how returns are distributed (heavy tails, a few
failed runs). AdaStop (Mathieu et al. 2024, TMLR) controls the same family-wise error with
permutation tests, which are exact in small samples but cost a resampling per look and a
boundary the study cannot state before its data; the spending function here is fixed in the
plan. The normal approximation makes small groups conservative rather than liberal: with 5
runs a side |Z| cannot exceed 2.6, so the first look of a long design cannot decide.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Sequence

import numpy as np

from fppo_jax.config import MAX_SEEDS, positive_int
from fppo_jax.errors import InvalidInput

# Points per look of the boundaries' integration grid, odd for Simpson's rule: enough for the
# published boundaries to four decimals (tests/test_sequential.py).
GRID_POINTS = 801
# Far more looks than a study plans, and few enough that their boundaries take seconds.
MAX_LOOKS = 200


@dataclasses.dataclass(frozen=True)
class Design:
    """A study's seed schedule and error level: looks after every `group_size` seeds (per
    setting) up to `max_seeds`, two-sided family-wise error `level` (α)."""

    group_size: int = 5
    max_seeds: int = 30
    level: float = 0.05

    def __post_init__(self) -> None:
        positive_int("group_size", self.group_size)
        if positive_int("max_seeds", self.max_seeds) > MAX_SEEDS:
            raise InvalidInput(f"max_seeds must be at most {MAX_SEEDS:,}, got {self.max_seeds:,}")
        if -(-self.max_seeds // self.group_size) > MAX_LOOKS:
            raise InvalidInput(
                f"max_seeds / group_size gives more than {MAX_LOOKS} looks: take larger groups"
            )
        if self.group_size > self.max_seeds:
            raise InvalidInput(
                f"group_size ({self.group_size}) is larger than max_seeds ({self.max_seeds})"
            )
        number = isinstance(self.level, float | int | np.floating)
        if isinstance(self.level, bool) or not (number and 0 < self.level < 1):
            raise InvalidInput(f"the error level must be in (0, 1), got {self.level!r}")

    @property
    def looks(self) -> tuple[int, ...]:
        """Seeds per setting at each look: every group, the last one cut at `max_seeds`."""
        sizes = range(self.group_size, self.max_seeds + self.group_size, self.group_size)
        return tuple(min(n, self.max_seeds) for n in sizes)


@dataclasses.dataclass(frozen=True)
class Decision:
    """One comparison's state: `decision` (``better``, ``worse``, ``undecided``), or ``None``
    while it awaits seeds; the `seeds` per setting its decision used (or it holds so far); its
    latest statistic `z` and the boundary it was held against; and why it stopped, in words."""

    decision: str | None
    seeds: int
    z: float
    boundary: float
    reason: str


def spent(alpha: float, fraction: float) -> float:
    """Lan–DeMets' O'Brien–Fleming-type spending: the two-sided error spent by information
    fraction `fraction`, each side spending α/2 as 2 − 2Φ(Φ⁻¹(1 − α/4) / √t)."""
    from scipy import special

    return float(4 * special.ndtr(-special.ndtri(1 - alpha / 4) / np.sqrt(fraction)))


def _excess_crossing(
    bound: float, points: np.ndarray, weighted: np.ndarray, step: float, spend: float
) -> float:
    """The probability that a path not yet stopped, at `points` with density × weights
    `weighted`, crosses ±`bound` after an increment of sd `step`, less `spend`."""
    from scipy import special

    outside = special.ndtr((points - bound) / step) + special.ndtr((-bound - points) / step)
    return float(weighted @ outside) - spend


@functools.lru_cache(maxsize=256)
def boundaries(alpha: float, fractions: tuple[float, ...]) -> tuple[float, ...]:
    """The two-sided critical values c_k on the Z scale at the information `fractions` (0 < t_1
    < … ≤ 1) that spend `alpha` by :func:`spent`: P(first |Z_k| ≥ c_k at look k) =
    a*(t_k) − a*(t_{k−1}) under the null hypothesis, by Simpson's rule over the values
    S = Z√t of the paths that have not crossed."""
    from scipy import optimize

    if not fractions or any(b <= a for a, b in zip((0.0, *fractions), fractions, strict=False)):
        raise InvalidInput(f"information fractions must increase from above 0, got {fractions}")
    if fractions[-1] > 1:
        raise InvalidInput(f"information fractions must be at most 1, got {fractions}")
    critical: list[float] = []
    # The density of the paths that have not crossed, at the previous look, on its grid and
    # times Simpson's weights; before the first look every path is at 0.
    points, weighted = np.zeros(1), np.ones(1)
    previous, before = 0.0, 0.0
    for fraction in fractions:
        spend = spent(alpha, fraction) - before
        step = np.sqrt(fraction - previous)

        if spend <= 0:  # nothing left to spend at this look: it cannot decide
            bound = np.inf
        else:
            problem = (points, weighted, step, spend)
            bound = optimize.brentq(_excess_crossing, 1e-9, 40.0, args=problem, xtol=1e-12)
        critical.append(float(bound / np.sqrt(fraction)))
        edge = min(bound, 12.0 * np.sqrt(fraction))  # beyond 12 sd no path is left to count
        grid = np.linspace(-edge, edge, GRID_POINTS)
        simpson = np.full(GRID_POINTS, 2.0)
        simpson[1::2], simpson[[0, -1]] = 4.0, 1.0
        simpson *= (grid[1] - grid[0]) / 3
        gaussian = np.exp(-0.5 * ((grid[:, None] - points[None, :]) / step) ** 2)
        density = gaussian @ weighted / (step * np.sqrt(2 * np.pi))
        points, weighted = grid, simpson * density
        previous, before = fraction, spent(alpha, fraction)
    return tuple(critical)


def repeated_confidence(design: Design, comparisons: int, seeds: int) -> float:
    """The confidence level of the repeated confidence interval at the look that holds `seeds`
    seeds of each setting (Jennison and Turnbull 1989; 2000, ch. 9): 2Φ(c_k) − 1, for the
    boundary c_k of level α/m, m = `comparisons`. Intervals at these levels hold every
    comparison's true value at every look at once with probability at least 1 − α (as far as
    the normal approximation holds), so the one at the look where a comparison stopped stays
    valid whatever the rule made of it: adjusted for stopping early and for the number of
    comparisons. Bonferroni's α/m makes them wider than Holm's decisions need, so one may hold
    ½ where its comparison was decided. 1.0 at a look that spends no error (no interval)."""
    from scipy import special

    looks = design.looks
    if seeds not in looks:
        raise InvalidInput(f"{seeds} seeds is not one of the design's looks {looks}")
    fractions = tuple(n / design.max_seeds for n in looks)
    critical = boundaries(design.level / comparisons, fractions)[looks.index(seeds)]
    return float(2 * special.ndtr(critical) - 1)


def mann_whitney_z(candidate: np.ndarray, baseline: np.ndarray) -> float:
    """The standardised Mann–Whitney statistic of `candidate`'s scores over `baseline`'s, with
    the tie correction; 0 when every score is tied (no evidence either way). A score of −inf
    (a failed run) ranks below every other and ties with another failed run."""
    x, y = np.asarray(candidate, float), np.asarray(baseline, float)
    n, m = x.size, y.size
    # Compared, not subtracted: −inf − (−inf) is NaN, but −inf == −inf is a tie.
    u = np.sum(x[:, None] > y[None, :]) + 0.5 * np.sum(x[:, None] == y[None, :])
    _, ties = np.unique(np.concatenate([x, y]), return_counts=True)
    total = n + m
    variance = n * m / 12 * (total + 1 - np.sum(ties**3 - ties) / (total * (total - 1)))
    return 0.0 if variance <= 0 else float((u - n * m / 2) / np.sqrt(variance))


def decide(scores: Sequence[tuple[np.ndarray, np.ndarray]], design: Design) -> list[Decision]:
    """Each comparison's :class:`Decision` from `scores`, one ``(candidate, baseline)`` pair of
    per-seed scores (seeds 0, 1, … in order) per comparison, by the rule of this module.

    Looks are replayed in order: at each look the comparisons not yet decided that hold its
    seeds are tested at Holm's level on every look so far, and one decided keeps its decision
    and the seeds of the look it was decided at, whatever seeds came after. So the answer on
    scores recorded group by group is the answer given after each group, and a study stopped
    and resumed decides as one that never stopped. A score of −inf stands for a failed run
    (diverged, or no episode finished), ranked below every other; NaN or +inf is refused.
    """
    pairs = _checked(scores)
    fractions = tuple(n / design.max_seeds for n in design.looks)
    # z[i][k]: comparison i's statistic at look k, for the looks its scores reach.
    z = [
        [mann_whitney_z(c[:n], b[:n]) for n in design.looks if n <= min(c.size, b.size)]
        for c, b in pairs
    ]
    decided = _replayed(z, design, fractions)
    critical = boundaries(design.level / max(1, len(pairs) - len(decided)), fractions)
    return [
        decided[i] if i in decided else _not_decided(z[i], min(c.size, b.size), design, critical)
        for i, (c, b) in enumerate(pairs)
    ]


def _checked(
    scores: Sequence[tuple[np.ndarray, np.ndarray]],
) -> list[tuple[np.ndarray, np.ndarray]]:
    pairs = []
    for index, (candidate, baseline) in enumerate(scores):
        pair = np.asarray(candidate, float), np.asarray(baseline, float)
        if any((np.isnan(s) | (s == np.inf)).any() for s in pair):
            raise InvalidInput(
                f"comparison {index} has a score of NaN or +inf: the rule ranks numbers, and "
                "−inf for a failed run"
            )
        pairs.append(pair)
    return pairs


def _replayed(
    z: list[list[float]], design: Design, fractions: tuple[float, ...]
) -> dict[int, Decision]:
    """The comparisons decided, by index, replaying the looks in order with Holm's levels."""
    looks = design.looks
    decided: dict[int, Decision] = {}
    for look in range(len(looks)):
        while True:
            open_ = [i for i in range(len(z)) if i not in decided and len(z[i]) > look]
            if not open_:
                break
            level = design.level / (len(z) - len(decided))
            critical = boundaries(level, fractions)
            crossed = [
                (i, k) for i in open_ for k in range(look + 1) if abs(z[i][k]) >= critical[k]
            ]
            if not crossed:
                break
            for i, k in crossed:  # Holm: every one that crosses at this level is decided
                if i not in decided:
                    direction = "better" if z[i][k] > 0 else "worse"
                    decided[i] = Decision(
                        direction,
                        looks[look],
                        z[i][k],
                        critical[k],
                        f"z = {z[i][k]:.2f} crossed ±{critical[k]:.2f} at look {k + 1} "
                        f"({looks[k]} seeds, level {level:.3g})",
                    )
    return decided


def _not_decided(
    z: list[float], seeds: int, design: Design, critical: tuple[float, ...]
) -> Decision:
    """A comparison the rule has not decided, with `seeds` of scores: undecided at the maximum
    of seeds, else awaiting the next look's."""
    looks, done = design.looks, len(z)
    latest = z[-1] if done else float("nan")
    boundary = critical[done - 1] if done else float("nan")
    if done == len(looks):
        return Decision(
            "undecided",
            looks[-1],
            latest,
            boundary,
            f"reached the maximum of {looks[-1]} seeds: z = {latest:.2f} stayed "
            f"within ±{boundary:.2f}",
        )
    wanted = f"look {done + 1} needs {looks[done]} seeds"
    return Decision(None, seeds, latest, boundary, f"awaits seeds: {wanted}")


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
    score normal with sd 1, each candidate's mean `shift` above its baseline's.

    Returns ``false_decision_rate``: the share of studies with any comparison decided against
    the truth (with ``shift=0`` any decision, the family-wise error; else any ``worse``);
    ``power``: the share of comparisons decided ``better``; ``seeds``: the mean seeds per
    setting a comparison used; ``runs``: the mean runs a study trained (a task's baseline runs
    as long as any of its candidates). Seeded, so it repeats."""
    if shift < 0:
        raise InvalidInput(f"shift must be at least 0, got {shift}")
    rng = np.random.default_rng(seed)
    n = design.max_seeds
    false, better, seeds, runs = 0, 0, 0, 0
    comparisons = sum(candidates_per_task)
    wrong = ("worse",) if shift > 0 else ("better", "worse")
    for _ in range(studies):
        scores = []
        for count in candidates_per_task:
            baseline = rng.standard_normal(n)
            scores += [(rng.standard_normal(n) + shift, baseline) for _ in range(count)]
        decisions = decide(scores, design)
        false += any(d.decision in wrong for d in decisions)
        better += sum(d.decision == "better" for d in decisions)
        used = [d.seeds for d in decisions]
        seeds += sum(used)
        start = 0
        for count in candidates_per_task:
            runs += sum(used[start : start + count]) + max(used[start : start + count])
            start += count
    return {
        "false_decision_rate": false / studies,
        "power": better / (studies * comparisons),
        "seeds": seeds / (studies * comparisons),
        "runs": runs / studies,
    }
