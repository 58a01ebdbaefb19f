"""A study's decision rule behind one interface, :class:`DecisionRule`: given each comparison's
scores so far (seeds in order), each comparison's :class:`~fppo_jax.stats.sequential.Decision`.
A plan records its rule by a stable `id` and `version` (:class:`RuleRecord`), never by words
or a module's path: words are reworded and modules move while the rule stays the same.
:func:`rule_of` gives back the rule a plan records, refusing an id this code does not know or
another version of it.

One rule is here: :class:`SequentialMannWhitney`, the group-sequential Mann–Whitney test with
Holm's procedure and, given a margin, equivalence (:mod:`fppo_jax.stats.sequential`). Another
rule (a fixed design, a permutation test) is a class with the same members, added to
:data:`RULES`; the study, its report and its plan take it unchanged."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import ClassVar, Protocol, TypedDict

import numpy as np

from fppo_jax.errors import InvalidInput
from fppo_jax.stats.sequential import Decision, Design, decide


class RuleRecord(TypedDict):
    """How a plan names its rule: a stable id, and the version of the rule under that id."""

    id: str
    version: int


class DecisionRule(Protocol):
    """What decides a study's comparisons: its `design` (the looks, the level, the margin), its
    words for reports, and :meth:`decide`, a pure function of the scores."""

    id: ClassVar[str]
    version: ClassVar[int]

    @property
    def design(self) -> Design:
        """The seed schedule, the error level and the margin."""
        ...

    @property
    def words(self) -> str:
        """The rule in words, as a report states it."""
        ...

    @property
    def equivalence_words(self) -> str | None:
        """How it decides ``equivalent``, in words (None without a margin)."""
        ...

    def decide(self, scores: Sequence[tuple[np.ndarray, np.ndarray]]) -> list[Decision]:
        """Each comparison's decision from its ``(candidate, baseline)`` scores so far."""
        ...


@dataclasses.dataclass(frozen=True)
class SequentialMannWhitney:
    """The rule of :mod:`fppo_jax.stats.sequential` under `design`."""

    design: Design
    id: ClassVar[str] = "sequential-mann-whitney-holm"
    version: ClassVar[int] = 1

    @property
    def words(self) -> str:
        return (
            "two-sided group-sequential Mann–Whitney test of P(candidate > baseline) = 1/2, "
            "Lan–DeMets O'Brien–Fleming-type alpha-spending over the looks, Holm's procedure "
            "across the comparisons"
        )

    @property
    def equivalence_words(self) -> str | None:
        if self.design.margin is None:
            return None
        return (
            "equivalent when P(candidate > baseline) is within 1/2 ± margin: two one-sided "
            "group-sequential tests (the repeated confidence interval of P, placement standard "
            "error, inside the margin), Lan–DeMets O'Brien–Fleming-type one-sided "
            "alpha-spending, Holm's procedure across the comparisons"
        )

    def decide(self, scores: Sequence[tuple[np.ndarray, np.ndarray]]) -> list[Decision]:
        return decide(scores, self.design)


# Every rule this code decides by, by id.
RULES: dict[str, type[SequentialMannWhitney]] = {SequentialMannWhitney.id: SequentialMannWhitney}


def record_of(rule: DecisionRule) -> RuleRecord:
    """What a plan records of `rule`."""
    return {"id": rule.id, "version": rule.version}


def rule_of(record: RuleRecord, design: Design) -> DecisionRule:
    """The rule a plan names by `record`, under `design`; refused, naming it, where this code
    does not know the id or decides by another version of it."""
    kind = RULES.get(record["id"])
    if kind is None:
        raise InvalidInput(
            f"the plan decides by the rule {record['id']!r}, which this fppo-jax does not know "
            f"(it knows {', '.join(RULES)}): decide it with the fppo-jax that planned it"
        )
    if record["version"] != kind.version:
        raise InvalidInput(
            f"the plan decides by version {record['version']} of {record['id']!r}, and this "
            f"fppo-jax by version {kind.version}: decide it with the fppo-jax that planned it"
        )
    return kind(design)
