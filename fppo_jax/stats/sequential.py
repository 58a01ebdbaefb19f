"""The decision rule of a study that adds seeds until it can answer: a group-sequential
Mann–Whitney test with Lan–DeMets α-spending, Holm's procedure across comparisons, and, given
a margin, a group-sequential equivalence test of the probability of improvement.

A study (:mod:`fppo_jax.analysis.studies`) compares candidates with a baseline, each comparison on
one task, and trains seeds in groups of ``group_size`` up to ``max_seeds``; after each group (a
*look*) this rule decides each comparison — ``better``, ``worse``, with a margin
``equivalent`` — or asks for more seeds.
It is a pure function of the scores so far and the :class:`Design`.

**The statistic.** At look k a comparison holds n_k = min(k·group_size, max_seeds) scores of
each setting, seeds 0 … n_k − 1. Its Mann–Whitney statistic U_k counts the pairs (candidate
run, baseline run) where the candidate scores higher, ties counting ½ (U_k / n_k² is the
probability of improvement of :mod:`fppo_jax.stats.statistics`), standardised under the null
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

**Equivalence** (with a margin δ in the design; without one, none of this applies and the rule
is the above). A comparison is decided ``equivalent`` when P(candidate > baseline), θ, is shown
to lie within ½ ± δ: by two one-sided tests (Schuirmann 1987) of θ ≤ ½ − δ and of θ ≥ ½ + δ,
each group-sequential at level a, which together are the repeated confidence interval
θ̂_k ± c′_k(a)·se_k lying within [½ − δ, ½ + δ] (Jennison and Turnbull 1993, Biometrics 49:
31–43; 2000, ch. 6 and 9: stopping when a repeated confidence interval at level 1 − 2a fits in
the equivalence region has error at most a). Here θ̂_k = U_k / n_k², se_k is
:func:`improvement_estimate`'s (a placement estimate of its sd, asymptotically the one of
Wellek's (2010, ch. 6) Mann–Whitney equivalence test, floored at its value
when the settings score alike), and c′_k(a) the one-sided boundaries spending a by the
O'Brien–Fleming-type function (:func:`boundaries` with ``sides=1``). Where θ ≥ ½ + δ, deciding
``equivalent`` at some look needs θ̂_k + c′_k·se_k ≤ ½ + δ ≤ θ, so (θ − θ̂_k)/se_k ≥ c′_k: the
one-sided group-sequential test crossing, probability at most a (likewise below), as far as
the standardised θ̂_k behave as the Brownian motion above; a se_k above the true sd (the floor)
only makes crossing rarer. Across comparisons the same sequential Holm procedure holds for
this second family of hypotheses: a = α / (the comparisons not yet decided ``equivalent``),
and one decided passes its share to the others. So the chance that any comparison whose θ is
at or beyond the margin is decided ``equivalent`` is at most α, and the chance of a wrong
``better`` or ``worse`` stays at most α as above: a comparison closed as ``equivalent`` still
counts among those not decided either way, so no share passes on from it (a ``better`` or
``worse`` one likewise counts among those not decided equivalent). The two kinds of error
concern different comparisons (θ = ½ against |θ − ½| ≥ δ), so a family holding both kinds can
make one or the other with chance up to 2α. At each look ``better`` and ``worse`` are tested
first; a comparison shown both different from ½ and within the margin is reported by its
direction.

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
from collections.abc import Sequence

import numpy as np

from fppo_jax.core.checks import MAX_SEEDS, check_fraction, positive_int
from fppo_jax.errors import InvalidInput
from fppo_jax.stats.spending import boundaries

# Far more looks than a study plans, and few enough that their boundaries take seconds.
MAX_LOOKS = 200


@dataclasses.dataclass(frozen=True)
class Design:
    """A study's seed schedule and error level: looks after every `group_size` seeds (per
    setting) up to `max_seeds`, two-sided family-wise error `level` (α); and the equivalence
    `margin` δ on the probability of improvement, or None (no ``equivalent`` decision)."""

    group_size: int = 5
    max_seeds: int = 30
    level: float = 0.05
    margin: float | None = None

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
        check_level(self.level)
        if self.margin is not None:
            check_margin(self.margin)
            if self.level >= 0.5:
                raise InvalidInput(
                    f"an equivalence margin needs an error level below 0.5 (each of its two "
                    f"one-sided tests is at the level), got {self.level!r}"
                )

    @property
    def looks(self) -> tuple[int, ...]:
        """Seeds per setting at each look: every group, the last one cut at `max_seeds`."""
        sizes = range(self.group_size, self.max_seeds + self.group_size, self.group_size)
        return tuple(min(n, self.max_seeds) for n in sizes)


@dataclasses.dataclass(frozen=True)
class Decision:
    """One comparison's state: `decision` (``better``, ``worse``, ``equivalent``,
    ``undecided``), or ``None`` while it awaits seeds; the `seeds` per setting its decision used
    (or it holds so far); its latest statistic `z` and the boundary it was held against (for
    ``equivalent``, the smaller of the two one-sided statistics and their boundary); why it
    stopped, in words; and, where the design has a margin, the repeated confidence `interval`
    of the probability of improvement that the equivalence test holds against ½ ± δ, at the
    look of `seeds` (None before any look)."""

    decision: str | None
    seeds: int
    z: float
    boundary: float
    reason: str
    interval: tuple[float, float] | None = None


def check_level(level: object) -> float:
    """`level` if it is a study's two-sided family-wise error level α, in (0, 1)."""
    return check_fraction("the error level", level)


def check_margin(margin: object) -> float:
    """`margin` if it is an equivalence margin δ on the probability of improvement, in (0, ½)."""
    return check_fraction(
        "the equivalence margin (a distance from 1/2 of P(candidate > baseline))", margin, 0.5
    )


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


def improvement_estimate(candidate: np.ndarray, baseline: np.ndarray) -> tuple[float, float]:
    """The probability of improvement θ̂ = U / (n·m) of `candidate`'s n scores over
    `baseline`'s m, and the standard error the equivalence test gives it:

        se² = max(S²_V / n + S²_W / m,  (n + m + 1) / (12·n·m))

    where V_i = the share of baseline runs candidate run i beats (ties ½), W_j = the share of
    candidate runs that beat baseline run j, and S² their sample variances. The first term is
    the placement estimate of Var(θ̂) (Sen 1967; DeLong, DeLong and Clarke-Pearson 1988),
    consistent whatever the two distributions (asymptotically the variance estimate of
    Wellek's, 2010, ch. 6, Mann–Whitney equivalence test). The second is Var(θ̂) when the
    settings score alike with no ties: the variance of :func:`mann_whitney_z`'s U without its
    tie correction, over (n·m)². The floor keeps the estimate from collapsing in small samples
    (to 0 where every score ties) and errs on the side of a wider interval: under a shift of
    location the true variance is below it. −inf (a failed run) ranks below every other and
    ties with another failed run."""
    x, y = np.asarray(candidate, float), np.asarray(baseline, float)
    n, m = x.size, y.size
    wins = (x[:, None] > y[None, :]) + 0.5 * (x[:, None] == y[None, :])
    theta = float(wins.mean())
    floor = (n + m + 1) / (12 * n * m)
    placement = 0.0
    if n > 1 and m > 1:
        placement = float(np.var(wins.mean(axis=1), ddof=1) / n)
        placement += float(np.var(wins.mean(axis=0), ddof=1) / m)
    return theta, float(np.sqrt(max(placement, floor)))


def equivalence_z(theta: float, error: float, margin: float) -> float:
    """The smaller of the two one-sided statistics of the equivalence test (Schuirmann 1987):
    (θ̂ − (½ − δ)) / se against θ ≤ ½ − δ and ((½ + δ) − θ̂) / se against θ ≥ ½ + δ. At a
    boundary c, min ≥ c is the interval θ̂ ± c·se lying within [½ − δ, ½ + δ]."""
    return min(theta - (0.5 - margin), (0.5 + margin) - theta) / error


@dataclasses.dataclass(frozen=True)
class _Look:
    """A comparison's statistics at one look: the Mann–Whitney `z`, the probability of
    improvement `theta` and its standard error `error` (:func:`improvement_estimate`)."""

    z: float
    theta: float
    error: float


def decide(scores: Sequence[tuple[np.ndarray, np.ndarray]], design: Design) -> list[Decision]:
    """Each comparison's :class:`Decision` from `scores`, one ``(candidate, baseline)`` pair of
    per-seed scores (seeds 0, 1, … in order) per comparison, by the rule of this module.

    Looks are replayed in order: at each look the comparisons not yet decided that hold its
    seeds are tested at Holm's level on every look so far — for ``better`` or ``worse`` first,
    then, with a margin, those still open for ``equivalent`` — and one decided keeps its
    decision and the seeds of the look it was decided at, whatever seeds came after. So the
    answer on scores recorded group by group is the answer given after each group, and a study
    stopped and resumed decides as one that never stopped. A score of −inf stands for a failed
    run (diverged, or no episode finished), ranked below every other; NaN or +inf is refused.
    """
    pairs = _checked(scores)
    fractions = tuple(n / design.max_seeds for n in design.looks)
    # stats[i][k]: comparison i's statistics at look k, for the looks its scores reach.
    stats = [
        [
            _Look(mann_whitney_z(c[:n], b[:n]), *improvement_estimate(c[:n], b[:n]))
            for n in design.looks
            if n <= min(c.size, b.size)
        ]
        for c, b in pairs
    ]
    decided = _replayed(stats, design, fractions)
    return [
        decided[i]
        if i in decided
        else _not_decided(stats[i], min(c.size, b.size), design, decided, len(pairs))
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
    stats: list[list[_Look]], design: Design, fractions: tuple[float, ...]
) -> dict[int, Decision]:
    """The comparisons decided, by index, replaying the looks in order with Holm's levels:
    at each look ``better`` and ``worse`` (two-sided, level α / the comparisons not decided
    either way), then ``equivalent`` (two one-sided tests, each at level α / the comparisons
    not decided equivalent) among those still open."""
    looks, margin = design.looks, design.margin
    decided: dict[int, Decision] = {}
    for look in range(len(looks)):
        while True:  # better or worse, Holm's levels recycled until none crosses
            open_ = [i for i in range(len(stats)) if i not in decided and len(stats[i]) > look]
            if not open_:
                break
            directional = sum(d.decision in ("better", "worse") for d in decided.values())
            level = design.level / (len(stats) - directional)
            critical = boundaries(level, fractions)
            crossed = [
                (i, k) for i in open_ for k in range(look + 1) if abs(stats[i][k].z) >= critical[k]
            ]
            if not crossed:
                break
            for i, k in crossed:  # Holm: every one that crosses at this level is decided
                if i not in decided:
                    z = stats[i][k].z
                    decided[i] = Decision(
                        "better" if z > 0 else "worse",
                        looks[look],
                        z,
                        critical[k],
                        f"z = {z:.2f} crossed ±{critical[k]:.2f} at look {k + 1} "
                        f"({looks[k]} seeds, level {level:.3g})",
                        _interval(stats[i][look], look, design, decided, len(stats)),
                    )
        while margin is not None:  # equivalent, likewise
            open_ = [i for i in range(len(stats)) if i not in decided and len(stats[i]) > look]
            if not open_:
                break
            level = _equivalence_level(design, decided, len(stats))
            critical = boundaries(level, fractions, sides=1)
            within = [
                (i, k)
                for i in open_
                for k in range(look + 1)
                if _equivalence(stats[i][k], margin) >= critical[k]
            ]
            if not within:
                break
            for i, k in within:
                if i not in decided:
                    at = stats[i][k]
                    low, high = _bounds(at, critical[k])
                    decided[i] = Decision(
                        "equivalent",
                        looks[look],
                        _equivalence(at, margin),
                        critical[k],
                        f"P = {at.theta:.2f}, its repeated CI [{low:.2f}, {high:.2f}] "
                        f"(±{critical[k]:.2f} se) within 1/2 ± {margin:g} at look {k + 1} "
                        f"({looks[k]} seeds, level {level:.3g} a side)",
                        (low, high),
                    )
    return decided


def _equivalence(at: _Look, margin: float) -> float:
    return equivalence_z(at.theta, at.error, margin)


def _equivalence_level(design: Design, decided: dict[int, Decision], comparisons: int) -> float:
    """Holm's level of each one-sided test of equivalence: α over the comparisons not decided
    ``equivalent``."""
    done = sum(d.decision == "equivalent" for d in decided.values())
    return design.level / (comparisons - done)


def _interval(
    at: _Look, look: int, design: Design, decided: dict[int, Decision], comparisons: int
) -> tuple[float, float] | None:
    """The repeated confidence interval of the probability of improvement that the
    equivalence test holds against the margin at look index `look` (None without a margin):
    θ̂ ± c·se, c that look's one-sided boundary at the equivalence level."""
    if design.margin is None:
        return None
    fractions = tuple(n / design.max_seeds for n in design.looks)
    level = _equivalence_level(design, decided, comparisons)
    critical = boundaries(level, fractions, sides=1)[look]
    return _bounds(at, critical)


def _bounds(at: _Look, critical: float) -> tuple[float, float]:
    """θ̂ ± `critical`·se, cut to [0, 1], where a probability lies."""
    return max(0.0, at.theta - critical * at.error), min(1.0, at.theta + critical * at.error)


def _not_decided(
    stats: list[_Look],
    seeds: int,
    design: Design,
    decided: dict[int, Decision],
    comparisons: int,
) -> Decision:
    """A comparison the rule has not decided, with `seeds` of scores: undecided at the maximum
    of seeds, else awaiting the next look's."""
    looks, done = design.looks, len(stats)
    fractions = tuple(n / design.max_seeds for n in looks)
    directional = sum(d.decision in ("better", "worse") for d in decided.values())
    critical = boundaries(design.level / (comparisons - directional), fractions)
    latest = stats[-1].z if done else float("nan")
    boundary = critical[done - 1] if done else float("nan")
    interval = _interval(stats[-1], done - 1, design, decided, comparisons) if done else None
    if done == len(looks):
        outside = (
            ""
            if interval is None
            else f", and P's repeated CI [{interval[0]:.2f}, {interval[1]:.2f}] is not within "
            f"1/2 ± {design.margin:g}"
        )
        return Decision(
            "undecided",
            looks[-1],
            latest,
            boundary,
            f"reached the maximum of {looks[-1]} seeds: z = {latest:.2f} stayed "
            f"within ±{boundary:.2f}{outside}",
            interval,
        )
    wanted = f"look {done + 1} needs {looks[done]} seeds"
    return Decision(None, seeds, latest, boundary, f"awaits seeds: {wanted}", interval)
