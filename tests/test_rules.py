"""fppo_jax.stats.rules: the study's rule behind its interface decides as the sequential module
does, is recorded by id and version, and a plan's rule this code does not decide by is refused
by name."""

import numpy as np
import pytest

from fppo_jax.errors import InvalidInput
from fppo_jax.stats.rules import RULES, SequentialMannWhitney, record_of, rule_of
from fppo_jax.stats.sequential import Design, decide


def test_the_rule_decides_as_the_sequential_module_under_its_design():
    design = Design(group_size=10, max_seeds=20, margin=0.2)
    rng = np.random.default_rng(0)
    scores = [(rng.normal(2, 1, 20), rng.normal(0, 1, 20)), (rng.normal(0, 1, 20),) * 2]
    rule = rule_of(record_of(SequentialMannWhitney(design)), design)
    assert rule.design == design and rule.decide(scores) == decide(scores, design)
    assert [d.decision for d in rule.decide(scores)] == ["better", "equivalent"]


def test_a_plan_records_the_rule_by_id_and_version_and_words_apart():
    rule = SequentialMannWhitney(Design())
    assert record_of(rule) == {"id": "sequential-mann-whitney-holm", "version": 1}
    assert set(RULES) == {rule.id}
    assert "Mann–Whitney" in rule.words and rule.equivalence_words is None
    assert "two one-sided" in (SequentialMannWhitney(Design(margin=0.1)).equivalence_words or "")


def test_a_rule_unknown_or_of_another_version_is_refused_by_name():
    with pytest.raises(InvalidInput, match="rule 'bayes', which this fppo-jax does not know"):
        rule_of({"id": "bayes", "version": 1}, Design())
    with pytest.raises(InvalidInput, match="version 2 of 'sequential-mann-whitney-holm'"):
        rule_of({"id": "sequential-mann-whitney-holm", "version": 2}, Design())
