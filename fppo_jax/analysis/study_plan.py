"""A study's plan: what ``plan.json`` preregisters before any run (the comparisons, the
endpoints, the test in words, the seed schedule, the settings and the commit), and the check
that a study, or a tune, goes on only under the plan it started with."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path
from typing import Any, cast

from fppo_jax.core.objectives import identities
from fppo_jax.core.surrogates import Surrogate
from fppo_jax.errors import InvalidInput
from fppo_jax.stats import statistics
from fppo_jax.stats.sequential import Design
from fppo_jax.stats.spending import boundaries
from fppo_jax.store.files import json_value, write_json

ENDPOINTS = statistics.STUDY_ENDPOINTS  # decided on; those not chosen are reported beside it


# The rule in words, which a plan records and a resumed study is held to; they name no module,
# whose place may change while the rule does not (experiments/convert_plans.py converted the
# plans recorded when they named one).
TEST = (
    "two-sided group-sequential Mann–Whitney test of P(candidate > baseline) = 1/2, "
    "Lan–DeMets O'Brien–Fleming-type alpha-spending over the looks, Holm's procedure across "
    "the comparisons"
)


EQUIVALENCE_TEST = (
    "equivalent when P(candidate > baseline) is within 1/2 ± margin: two one-sided "
    "group-sequential tests (the repeated confidence interval of P, placement standard error, "
    "inside the margin), Lan–DeMets O'Brien–Fleming-type one-sided alpha-spending, Holm's "
    "procedure across the comparisons"
)


PLAN_FILE, DECISIONS_FILE, REPORT_FILE = "plan.json", "decisions.json", "report.md"


def commit() -> str:
    """The commit of the code that runs (``git rev-parse HEAD`` in the package's directory), or
    ``unknown`` outside a git checkout."""
    try:
        done = subprocess.run(
            ["git", "rev-parse", "HEAD"],
            cwd=Path(__file__).resolve().parent,
            capture_output=True,
            text=True,
            check=True,
            timeout=30,
        )
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return done.stdout.strip() or "unknown"


def make_plan(
    tasks: list[str],
    candidates: list[Surrogate],
    baseline: Surrogate,
    design: Design,
    endpoint: str,
    settings: dict[str, Any],
    reuse: list[str],
) -> dict[str, Any]:
    """What ``plan.json`` records: the preregistration, decided before any run."""
    return cast(
        dict[str, Any],
        json_value(
            {
                "tasks": tasks,
                "baseline": baseline.name,
                "candidates": [c.name for c in candidates],
                "comparisons": [
                    {"task": task, "candidate": c.name, "baseline": baseline.name}
                    for task in tasks
                    for c in candidates
                ],
                "primary_endpoint": endpoint,
                "secondary_endpoints": [
                    e
                    for e in ENDPOINTS
                    if e != endpoint and (e != "eval" or "eval_every" in settings)
                ],
                "test": TEST,
                "level": design.level,
                **_equivalence_plan(design),
                "group_size": design.group_size,
                "max_seeds": design.max_seeds,
                "looks": list(design.looks),
                "boundaries_if_none_decided": list(
                    boundaries(design.level / (len(tasks) * len(candidates)), _fractions(design))
                ),
                "settings": settings,
                **({"reuse": reuse} if reuse else {}),
                **identities([*candidates, baseline]),
                "commit": commit(),
            }
        ),
    )


def _equivalence_plan(design: Design) -> dict[str, Any]:
    """What the plan records of the equivalence test: nothing without a margin (a plan
    recorded before margins existed is one without), else the margin and the test."""
    if design.margin is None:
        return {}
    return {"margin": design.margin, "equivalence_test": EQUIVALENCE_TEST}


def _fractions(design: Design) -> tuple[float, ...]:
    return tuple(n / design.max_seeds for n in design.looks)


def check_plan(
    output: Path,
    plan: dict[str, Any],
    what: str = "a study",
    name: str = PLAN_FILE,
    recorded_only: frozenset[str] = frozenset({"commit"}),
) -> dict[str, Any]:
    """Write `plan` as `name` in `output`, or check it against the one there: `what` (a study,
    a tune) goes on only under the plan it started with, the fields in `recorded_only` aside
    (the commit: a group records its own). Returns the plan as recorded, with the commit it was
    made at."""
    path = output / name
    if not path.exists():
        write_json(path, plan)
        return plan
    try:
        recorded = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as error:
        raise InvalidInput(f"cannot read the plan {path}: {error}") from None
    for field in dict.fromkeys([*recorded, *plan]):
        was, now = recorded.get(field), plan.get(field)
        if field in recorded_only or was == now:
            continue
        if isinstance(was, dict) and isinstance(now, dict):
            keys = [
                k
                for k in dict.fromkeys([*was, *now])
                if was.get(k) != now.get(k) and f"{field}.{k}" not in recorded_only
            ]
            if not keys:
                continue
            field, was, now = f"{field}.{keys[0]}", was.get(keys[0]), now.get(keys[0])
        raise InvalidInput(
            f"{output} holds {what} planned with {field} = {_shown(was)}, not {_shown(now)}: "
            f"{what} goes on only under its plan (start another in a new directory)"
        )
    return cast(dict[str, Any], recorded)


def _shown(value: Any) -> str:
    return "none" if value is None else json.dumps(value)
