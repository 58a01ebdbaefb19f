"""The dose-response's controls, for ``dose_response.py``: α = 1 (FPPO-LP) and k = 0 (FPPO-QP)
are PPO's objective, so each control's run is checked against the same seed's PPO run of its
sweep, bit for bit on every recorded metric, and the seed study's recorded PPO runs are set
beside them; with how the plan's runs were compiled (the parts they ran in) and where in the
sweeps each dose's setting is.
"""

from __future__ import annotations

import numpy as np

from fppo_jax import SweepResult
from fppo_jax.core.resolution import SYMBOLS

# Why a control can part from PPO's run (tests/test_variants.py shows the gradients).
PARTED = (
    "A control equals PPO's objective in real arithmetic, not always in float32: where r lies "
    "within rounding of 1 ± ε, rA and (1 ± ε)A can round to the same number, and PPO's "
    "min(rA, clip(r, 1 − ε, 1 + ε)A) is then a tie, whose gradient JAX splits between the two "
    "terms (½A), while at α = 1 and k = 0 the pulled term is r itself and the gradient A. One "
    "such sample sets the parameters apart in their last bits, and the runs part from there."
)


def doses(plan: dict) -> dict[str, tuple[str, list[float]]]:
    """Each dosed variant's hyperparameter and its doses: ``{"fppo-lp": ("alpha", [1.0, …])}``."""
    return {
        variant: next((k, v) for k, v in spec.items() if isinstance(v, list))
        for variant, spec in plan["doses"].items()
        if isinstance(spec, dict)
    }


def setting_index(result: SweepResult, variant: str, name: str | None, dose: float | None) -> int:
    """The index of `variant`'s setting at `dose` of its hyperparameter `name` (PPO: no dose)."""
    for index, setting in enumerate(result.settings):
        if setting["variant"] == variant and (name is None or setting.get(name) == dose):
            return index
    raise KeyError(f"{variant} {name}={dose}")


def seed_ranges(parts: list[SweepResult]) -> list[str]:
    """Each part's seeds, in order: ``["0–1", "2–3", "6"]``."""
    ranges = []
    for part in parts:
        seeds = sorted({run["seed"] for run in part.runs})
        low, high = seeds[0], seeds[-1]
        ranges.append(f"{low}" if low == high else f"{low}–{high}")
    return sorted(ranges, key=lambda r: int(r.split("–")[0]))


def compiled_parts(plan: dict, parts: dict[str, list[SweepResult]]) -> str:
    """How the runs were compiled: the plan's one sweep per task, or the parts they ran in."""
    per_task = "; ".join(
        f"{task}, {len(of_task)} part{'s' if len(of_task) > 1 else ''} "
        f"(seeds {', '.join(seed_ranges(of_task))})"
        for task, of_task in parts.items()
    )
    return (
        f'How the runs were compiled: the plan says "{plan["seeds"]}"; they ran instead in '
        "parts, "
        f"each a sweep of the task's settings at its own seeds, compiled and run on its own: "
        f"{per_task}. A seed's settings are always in one part, so each control is checked "
        "against the PPO run of its own program; runs of different parts come from programs "
        "of different batch sizes, which may round differently, as the seed study's PPO does "
        "against the sweep's (below)."
    )


def by_seed(result: SweepResult, index: int) -> dict[int, int]:
    """Setting `index`'s runs by seed: ``{seed: run}``."""
    return {run["seed"]: i for i, run in enumerate(result.runs) if run["setting"] == index}


def first_difference(result: SweepResult, a: int, b: int) -> int | None:
    """The first update (from 1) at which runs `a` and `b` differ on a recorded metric; None
    if they never do."""
    updates = [
        int(np.argmax(differ)) + 1
        for values in result.metrics.values()
        if (differ := ~np.isclose(values[a], values[b], rtol=0, atol=0, equal_nan=True)).any()
    ]
    return min(updates, default=None)


def controls(result: SweepResult, study: SweepResult | None, plan: dict) -> list[str]:
    """A line per control: in how many seeds it trains as the sweep's PPO run, bit for bit on
    every recorded metric, and how the seed study's recorded PPO runs compare."""
    ppo = by_seed(result, setting_index(result, "ppo", None, None))
    lines = []
    for variant, (name, values) in doses(plan).items():
        control = by_seed(result, setting_index(result, variant, name, values[0]))
        parted = {seed: first_difference(result, run, ppo[seed]) for seed, run in control.items()}
        same = [seed for seed, update in parted.items() if update is None]
        apart = [f"seed {s} from update {u}" for s, u in sorted(parted.items()) if u is not None]
        lines.append(
            f"- {variant} at {SYMBOLS.get(name, name)} = {values[0]:g}: identical to the sweep's "
            f"PPO run on every recorded metric in {len(same)} of {len(control)} seeds"
            + (f"; apart: {', '.join(apart)}" if apart else "")
        )
    if study is None:
        lines.append("- the seed study has no recorded PPO runs of this task to set beside them")
    else:
        recorded_ppo = by_seed(study, setting_index(study, "ppo", None, None))
        seeds = sorted(set(ppo) & set(recorded_ppo))
        same = [
            s
            for s in seeds
            if np.array_equal(
                study.metrics["average_return"][recorded_ppo[s]],
                result.metrics["average_return"][ppo[s]],
                equal_nan=True,
            )
        ]
        lines.append(
            f"- the sweep's PPO against the seed study's recorded PPO runs (another compiled "
            f"program): the same learning curve in {len(same)} of {len(seeds)} seeds"
        )
    return lines


def controls_lines(
    plan: dict, checks: dict[str, list[str]], parts: dict[str, list[SweepResult]]
) -> list[str]:
    """The report's section on the controls: how the runs were compiled (`parts`, by task),
    each task's checks (:func:`controls`), and why a control can part from PPO where one did."""
    lines = ["## The controls", "", compiled_parts(plan, parts), ""]
    for task, lines_of_task in checks.items():
        lines += [f"{task}:", "", *lines_of_task, ""]
    if any("; apart: " in line for task_lines in checks.values() for line in task_lines):
        lines += [PARTED, ""]
    return lines
