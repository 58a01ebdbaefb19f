"""A study's looks: each task's next group of seeds gathered (trained or recorded), the
sequential rule applied to every comparison still undecided, and what each look leaves:
``decisions.json``, each task's merged sweep and the report."""

from __future__ import annotations

import dataclasses
import json
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import TypedDict, cast

import numpy as np

from fppo_jax.analysis.arms import task_folder
from fppo_jax.analysis.preregistration import commit
from fppo_jax.analysis.reuse import Taken, protocol_differences
from fppo_jax.analysis.study_figures import write_figures
from fppo_jax.analysis.study_files import DEFAULTS, StudyResult
from fppo_jax.analysis.study_plan import (
    DECISIONS_FILE,
    REPORT_FILE,
    BesideDefaults,
    DecisionRow,
    Decisions,
    GroupEntry,
    StudyPlan,
    rule_of_plan,
)
from fppo_jax.analysis.study_report import beside_defaults, write_report
from fppo_jax.analysis.study_runs import (
    Source,
    recorded_group,
    refuse_missing_shares,
    run_scores,
    runs_of,
    share_commits,
)
from fppo_jax.analysis.study_sections import SHARES, START, Scores, steps_name
from fppo_jax.analysis.study_shapes import (
    Shape,
    ShapedRuns,
    TaskRuns,
    holding,
    merged,
    shape_folder,
    shape_record,
    shaped_protocol,
)
from fppo_jax.core.shape_space import ChoiceValue
from fppo_jax.core.surrogates import Surrogate
from fppo_jax.errors import InvalidInput
from fppo_jax.run.results import SweepResult
from fppo_jax.stats import statistics
from fppo_jax.stats.rules import DecisionRule
from fppo_jax.stats.sequential import Decision
from fppo_jax.store.files import write_json

# Reported beside the plan's endpoints, never decided on: each run's best return over training
# (the paper's statistic is its like over the seed-mean curve), biased upward.
REPORTED = "max"


def shown_progress(settings: Mapping[str, object]) -> bool:
    """Whether the study prints its plan, each look's groups and each decision on stderr: where
    its sweeps show progress as lines or a bar (``progress=True``), not where a callable takes
    it."""
    shown = settings.get("progress", False)
    return isinstance(shown, bool | np.bool_) and bool(shown)


@dataclasses.dataclass(frozen=True)
class _Group:
    """A task's group of seeds at one look, of the study's settings or (`defaults`) of each
    arm's default beside them: the `variants` still to train in `where` from `source`
    (`result`: the group recorded there already, whole) and the runs `taken` from recorded
    sweeps."""

    task: str
    look: int
    seeds: list[int]
    variants: list[Surrogate]
    where: Path
    result: SweepResult | None
    taken: dict[str, Taken]
    source: Source
    defaults: bool
    shape: Shape = ()

    @property
    def to_train(self) -> bool:
        return bool(self.variants) and self.result is None


def run_looks(
    output: Path,
    plan: StudyPlan,
    tasks: list[str],
    candidates: list[Surrogate],
    baseline: Surrogate,
    groups: int | None,
    source: Source,
) -> StudyResult:
    """The looks: each task's next group while some comparison awaits seeds, then the plan's
    rule (:func:`~fppo_jax.analysis.study_plan.rule_of_plan`).
    With ``source.part``, the first look whose groups are not all recorded has this share of
    them trained, and the call returns there, writing no decision."""
    recorded: dict[str, list[SweepResult]] = {task: [] for task in tasks}
    defaults: dict[str, list[SweepResult]] = {task: [] for task in tasks}  # with_defaults
    trained: list[GroupEntry] = []
    shown = shown_progress(source.settings)
    endpoint, rule = plan["primary_endpoint"], rule_of_plan(plan)
    design = rule.design
    decisions = _decide(recorded, tasks, candidates, baseline, rule, endpoint)
    for look, seeds in enumerate(design.looks):
        waiting = {key for key, d in decisions.items() if d.decision is None}
        if not waiting:
            break
        group_seeds = list(range(design.looks[look - 1] if look else 0, seeds))
        found = [
            _group(output, source, task, look, group_seeds, arms, beside, shape)
            # each arm's default at the same looks, on the same seeds, as its tuned setting
            for beside in ((False, True) if source.defaults else (False,))
            for task in tasks
            # the baseline only while one of its task's candidates waits
            if (variants := [c for c in candidates if (task, c.name) in waiting])
            # arms in run shapes of their own (a tune's choice) train apart, by shape
            for shape, arms in _by_shape(source, task, [*variants, baseline], beside).items()
        ]
        to_train = [group for group in found if group.to_train]
        if source.part is not None and to_train:
            for group in to_train:
                if recorded_group(group.where, group.variants, group.seeds, source.part) is None:
                    if shown:
                        _say(_training_line(group, len(design.looks), source.part))
                    group.source.train(group.task, group.variants, group.seeds, group.where)
            return StudyResult(plan, _rows(decisions, baseline), {}, False)
        for group in to_train if source.part is None else []:
            refuse_missing_shares(group.where)
        looks_trained = len({entry["group"] for entry in trained if "commit" in entry})
        if to_train and groups is not None and looks_trained >= groups:
            break
        for group in found:
            if shown:
                _say(_training_line(group, len(design.looks)))
            if entry := _gather(group, defaults if group.defaults else recorded):
                trained.append(entry)
        before = decisions
        decisions = _decide(recorded, tasks, candidates, baseline, rule, endpoint)
        if shown:
            for (task, name), decision in decisions.items():
                if decision.decision is not None and before[task, name].decision is None:
                    _say(_decision_line(task, name, baseline.name, decision))
        if source.part is None:  # an array task writes no decision: the job after the array does
            _write_decisions(output, decisions, baseline, trained, plan)  # a killed one keeps them
            for where, runs in ((output, recorded), (output / DEFAULTS, defaults)):
                _write_merged(where, runs, found)
    return _finish(output, plan, recorded, defaults, decisions, baseline, trained, source.part)


def _say(line: str) -> None:
    """A line of the study's progress, on stderr."""
    print(f"study: {line}", file=sys.stderr, flush=True)


def _training_line(group: _Group, looks: int, part: tuple[int, int] | None = None) -> str:
    """What a look does on a task: the seeds it trains, of which settings, and those taken."""
    seeds = f"seeds {group.seeds[0]}–{group.seeds[-1]}"
    task = f"{group.task}, defaults" if group.defaults else group.task
    said = []
    if group.to_train:
        share = "" if part is None else f" (part {part[0]} of {part[1]})"
        said.append(f"training {seeds} of {', '.join(v.name for v in group.variants)}{share}")
    elif group.variants:
        said.append(f"{seeds} of {', '.join(v.name for v in group.variants)} recorded already")
    if group.taken:
        said.append(f"{seeds} of {', '.join(group.taken)} taken from recorded sweeps")
    return f"look {group.look + 1} of {looks}, {task}: {'; '.join(said)}"


def _decision_line(task: str, candidate: str, baseline: str, decision: Decision) -> str:
    return (
        f"{task}: {candidate} against {baseline}: {decision.decision} with {decision.seeds} "
        f"seeds ({decision.reason})"
    )


def _write_merged(
    output: Path, recorded: dict[str, list[SweepResult]], groups: list[_Group]
) -> None:
    """Each task's runs so far as one sweep, ``<task>/curves.csv`` and ``sweep.json`` merged
    over its groups (:func:`~fppo_jax.merge`: one ``run`` numbering, where each group's
    restarts), beside the groups, one per run shape where its arms train in several (in the
    shape's folder); not for a task whose runs were all taken from recorded sweeps (it has no
    directory in the study's)."""
    for task, group in {group.task: group for group in groups}.items():
        where = output / task_folder(task)
        if not recorded[task] or not where.is_dir():
            continue
        runs = merged(recorded[task])
        for part in runs.parts if isinstance(runs, ShapedRuns) else (runs,):
            shape = group.source.shape_of(task, str(part.settings[0]["variant"]))
            part.write(where / shape_folder(shape))


def _group(
    output: Path,
    source: Source,
    task: str,
    look: int,
    seeds: list[int],
    variants: list[Surrogate],
    defaults: bool = False,
    shape: Shape = (),
) -> _Group:
    """`task`'s group at `look` (with `defaults`, of each arm's default, in ``defaults/``) of
    `variants` in run shape `shape`: those whose runs `source` takes from recorded sweeps, and
    the others, to train in the study's own directory unless recorded there."""
    if defaults:
        source, output = cast(Source, source.defaults), output / DEFAULTS
    taken = {v.name: t for v in variants if (t := source.take(task, v, seeds))}
    variants = [v for v in variants if v.name not in taken]
    where = output / task_folder(task) / shape_folder(shape) / f"group-{look + 1}"
    result = recorded_group(where, variants, seeds) if variants else None
    protocol = shaped_protocol(source.expected[task][0], shape)
    differences = protocol_differences(result.config, protocol) if result else []
    if differences:
        raise InvalidInput(
            f"{where} was trained under another protocol than this call would train "
            f"({'; '.join(differences)}): a study's groups share one protocol. Go on on a "
            "machine that trains as this one did (a plan's backend auto is chosen by the machine)"
        )
    return _Group(task, look, seeds, variants, where, result, taken, source, defaults, shape)


def _by_shape(
    source: Source, task: str, variants: list[Surrogate], defaults: bool
) -> dict[Shape, list[Surrogate]]:
    """`variants` by the run shape each trains on `task` (each arm's default: the task's)."""
    found: dict[Shape, list[Surrogate]] = {}
    for variant in variants:
        found.setdefault(() if defaults else source.shape_of(task, variant.name), []).append(
            variant
        )
    return found


class _Said(TypedDict, total=False):
    """What ``decisions.json`` says of some groups only (:class:`GroupEntry`'s keys that not
    every entry has), spread each in its place."""

    defaults: bool
    shape: dict[str, ChoiceValue]
    commit: str
    shares: list[str]
    reused: dict[str, list[str]]


def _gather(group: _Group, recorded: dict[str, list[SweepResult]]) -> GroupEntry | None:
    """`group`'s runs added to `recorded`, trained first where they are not recorded; what
    ``decisions.json`` says of the group (None when it was recorded by an earlier call)."""
    said: _Said = {}
    result = group.result
    if group.to_train:
        result = group.source.train(group.task, group.variants, group.seeds, group.where)
        said["commit"] = commit()
    elif shares := share_commits(group.where):
        said["shares"] = shares
    if result is not None:
        recorded[group.task].append(result)
    recorded[group.task] += [t.result for t in group.taken.values()]
    if group.taken:
        said["reused"] = {name: [str(s) for s in t.sources] for name, t in group.taken.items()}
    if not said:
        return None
    of: _Said = {"defaults": True} if group.defaults else {}
    if group.shape:
        of["shape"] = shape_record(group.shape)
    return {"task": group.task, "group": group.look + 1, **of, "seeds": group.seeds, **said}


def _finish(
    output: Path,
    plan: StudyPlan,
    recorded: dict[str, list[SweepResult]],
    defaults: dict[str, list[SweepResult]],
    decisions: dict[tuple[str, str], Decision],
    baseline: Surrogate,
    trained: list[GroupEntry],
    part: tuple[int, int] | None,
) -> StudyResult:
    """The study as it stands; unless this call trained a `part`, its decisions, report and
    figures written, with the comparisons of each arm's default beside them where the plan
    trains them."""
    results = {task: merged(parts) for task, parts in recorded.items() if parts}
    at_defaults = {task: merged(parts) for task, parts in defaults.items() if parts}
    if part is not None:
        rows = _rows(decisions, baseline)
        return StudyResult(plan, rows, results, all(row["final"] for row in rows), at_defaults)
    scores = {task: _task_scores(result, plan) for task, result in results.items()}
    variants, endpoint = (*plan["candidates"], plan["baseline"]), plan["primary_endpoint"]
    beside = None
    if plan.get("with_defaults"):
        default_scores = {
            task: {v: run_scores(result, v, endpoint) for v in variants}
            for task, result in at_defaults.items()
        }
        beside = beside_defaults(plan, scores, default_scores)
    rows = _write_decisions(output, decisions, baseline, trained, plan, beside)
    finished = all(row["final"] for row in rows)
    write_report(output / REPORT_FILE, plan, rows, scores, finished, beside)
    write_figures(output, plan, rows, results, scores)
    return StudyResult(plan, rows, results, finished, at_defaults)


def _task_scores(result: TaskRuns, plan: StudyPlan) -> Scores:
    """What the report shows of a task's runs: each variant's scores by endpoint, and its env
    steps to each share of the baseline's final IQM (``steps to 50%``; none where that IQM is
    not positive, where a share of it is no lower bar)."""
    variants = (*plan["candidates"], plan["baseline"])
    shown = ("final", plan["primary_endpoint"], *plan["secondary_endpoints"], REPORTED)
    scores = {v: {e: run_scores(result, v, e) for e in dict.fromkeys(shown)} for v in variants}
    for variant in variants:  # where each run starts: the untrained policy's first return
        curves = holding(result, variant).metrics["average_return"][runs_of(result, variant)]
        scores[variant][START] = np.array([_first_finite(row) for row in curves])
    final = scores[plan["baseline"]]["final"]
    target = float(statistics.iqm(final[np.isfinite(final)]))
    if not target > 0:
        return scores
    for variant in variants:
        runs, metrics = runs_of(result, variant), holding(result, variant).metrics
        curves, steps = metrics["average_return"][runs], metrics["env_steps"][runs]
        for share in SHARES:
            reached = statistics.steps_to_threshold(curves, steps, share * target)
            scores[variant][steps_name(share)] = reached
    return scores


def _first_finite(curve: np.ndarray) -> float:
    finite = curve[np.isfinite(curve)]
    return float(finite[0]) if finite.size else np.nan


def _decide(
    recorded: dict[str, list[SweepResult]],
    tasks: list[str],
    candidates: list[Surrogate],
    baseline: Surrogate,
    rule: DecisionRule,
    endpoint: str,
) -> dict[tuple[str, str], Decision]:
    """The rule on every comparison's scores so far (seeds in order, group after group)."""
    keys = [(task, c.name) for task in tasks for c in candidates]
    scores = []
    for task, candidate in keys:
        pair = []
        for variant in (candidate, baseline.name):
            parts = [
                run_scores(group, variant, endpoint)
                for group in recorded[task]
                if variant in [s["variant"] for s in group.settings]
            ]
            pair.append(np.concatenate(parts) if parts else np.zeros(0))
        scores.append(tuple(pair))
    # each of `scores` is a (candidate, baseline) pair
    return dict(
        zip(keys, rule.decide(cast("list[tuple[np.ndarray, np.ndarray]]", scores)), strict=True)
    )


def _rows(decisions: dict[tuple[str, str], Decision], baseline: Surrogate) -> list[DecisionRow]:
    return [
        _row(task, candidate, baseline.name, decision)
        for (task, candidate), decision in decisions.items()
    ]


def _row(task: str, candidate: str, baseline: str, decision: Decision) -> DecisionRow:
    row: DecisionRow = {
        "task": task,
        "candidate": candidate,
        "baseline": baseline,
        "decision": decision.decision or "undecided",
        "final": decision.decision is not None,
        "seeds": decision.seeds,
        "z": decision.z if np.isfinite(decision.z) else None,
        "boundary": decision.boundary if np.isfinite(decision.boundary) else None,
        "reason": decision.reason,
    }
    if decision.interval is not None:  # with a margin: the repeated CI of P it was held to
        row["interval"] = list(decision.interval)
    return row


class _Recorded(TypedDict, total=False):
    """The keys of :class:`Decisions` that only some studies record, spread each in its
    place."""

    margin: float
    beside_defaults: BesideDefaults


def _write_decisions(
    output: Path,
    decisions: dict[tuple[str, str], Decision],
    baseline: Surrogate,
    trained: list[GroupEntry],
    plan: StudyPlan,
    beside: BesideDefaults | None = None,
) -> list[DecisionRow]:
    """``decisions.json``: the plan's margin where it has one, a row per comparison
    (returned), what each arm's default measured `beside` them (untested, where given), and
    every group trained with the commit it ran at, or with the recorded sweeps its runs were
    taken from, earlier calls' groups kept."""
    path = output / DECISIONS_FILE
    earlier = json.loads(path.read_text()).get("groups", []) if path.exists() else []
    by_group: dict[tuple[str, int, bool, str], GroupEntry] = {_key(g): g for g in earlier}
    for entry in trained:  # a group trained earlier keeps its commit when runs are taken now
        key = _key(entry)
        before = by_group.get(key)
        by_group[key] = entry if before is None else {**before, **entry}
    groups = list(by_group.values())
    rows = _rows(decisions, baseline)
    margin: _Recorded = {"margin": plan["margin"]} if "margin" in plan else {}
    measured: _Recorded = {} if beside is None else {"beside_defaults": beside}
    record: Decisions = {
        "finished": all(row["final"] for row in rows),
        **margin,
        "comparisons": rows,
        **measured,
        "groups": sorted(
            groups, key=lambda g: (g["group"], g.get("defaults", False), g["task"], _key(g)[3])
        ),
    }
    write_json(path, record)
    return rows


def _key(group: GroupEntry) -> tuple[str, int, bool, str]:
    """A group's place in ``decisions.json``: its task, look, kind and run shape."""
    shape = json.dumps(group.get("shape", {}), sort_keys=True)
    return group["task"], group["group"], group.get("defaults", False), shape
