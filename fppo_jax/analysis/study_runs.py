"""Where a study's runs come from: each look's group of seeds trained as one sweep, or taken
from sweeps recorded elsewhere (:mod:`fppo_jax.analysis.reuse`), the shares of a split look
recorded and joined, and each run's score on an endpoint."""

from __future__ import annotations

import dataclasses
import json
import shutil
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, TypedDict

import numpy as np

from fppo_jax.analysis.preregistration import commit
from fppo_jax.analysis.reuse import Pool, Taken
from fppo_jax.analysis.study_plan import TunedChoice
from fppo_jax.analysis.study_shapes import Shape as RunShape
from fppo_jax.analysis.study_shapes import TaskRuns, holding, shape_of, shaped_protocol
from fppo_jax.core.config import Setting
from fppo_jax.core.objectives import hyperparameter_names, identities, takers
from fppo_jax.core.resolution import resolve_hyperparameters, sweepable
from fppo_jax.core.shape_space import config_values, configured, split_setting
from fppo_jax.core.surrogates import Surrogate
from fppo_jax.core.variants import BUILTINS
from fppo_jax.errors import InvalidInput
from fppo_jax.run.merge import merge
from fppo_jax.run.options import Snapshot
from fppo_jax.run.plan import part_runs
from fppo_jax.run.prepare import prepare
from fppo_jax.run.results import SweepResult
from fppo_jax.run.stop_signals import stop_if_signalled
from fppo_jax.run.sweeps import expand_grid, sweep
from fppo_jax.stats import statistics
from fppo_jax.store.files import write_json
from fppo_jax.store.record import RunRecord

# What the study sets itself for every group's sweep.
OWN_SETTINGS = ("log_dir", "checkpoint_dir", "resume", "checkpoint_every", "keep", "callback")


# A grid as :func:`~fppo_jax.sweep` takes it: each axis's values (the variants themselves, not
# their names), or a list of settings.
Grid = Mapping[str, object] | Sequence[Mapping[str, object]]


class Shape(TypedDict):
    """The run shape that every sweep of a study shares, as :func:`~fppo_jax.sweep` takes it."""

    total_steps: int | None
    preset: str
    backend: str


class GroupShape(Shape):
    """A study's :class:`Shape` and the runs per compiled call of each group's sweep."""

    chunk: int | None


@dataclasses.dataclass(frozen=True)
class Source:
    """Where a study's groups of runs come from: recorded sweeps in the `pool` of reused
    directories, where they match the `expected` protocol and setting, else trained (with the
    study's `settings`, the sweeps' other keyword arguments, and `shape`; by this call, only
    its `part` of each group)."""

    settings: dict[str, object]
    shape: GroupShape
    specific: set[str]  # the hyperparameters that only some variants take
    part: tuple[int, int] | None
    expected: dict[str, tuple[RunRecord, dict[str, Setting]]]  # by task, then variant
    identity: Mapping[str, Mapping[str, object]]  # each surrogate of one's own's, by name
    pool: Pool | None
    tuned: TunedChoice | None  # a tune's chosen settings, by task and variant
    # with_defaults: the source of each arm's default setting, trained beside its tuned one
    defaults: Source | None = None

    @classmethod
    def of(
        cls,
        tasks: list[str],
        everyone: list[Surrogate],
        settings: dict[str, object],
        shape: Shape,
        chunk: int | None,
        part: tuple[int, int] | None,
        reuse: list[str],
        tuned: TunedChoice | None = None,
    ) -> Source:
        """The study's source of runs, every setting of every task checked and the recorded
        sweeps of `reuse` read, all before the plan is written: a mistyped directory or a
        setting refused leaves no plan behind."""
        return cls(
            settings,
            {**shape, "chunk": chunk},
            set(hyperparameter_names([*BUILTINS.values(), *everyone])),
            part,
            {
                task: _checked_settings(
                    task,
                    everyone,
                    settings,
                    shape,
                    None if tuned is None else tuned["settings"][task],
                )
                for task in tasks
            },
            identities(everyone).get("surrogates", {}),
            Pool.read(reuse) if reuse else None,
            tuned,
        )

    def train(
        self, task: str, variants: list[Surrogate], seeds: list[int], where: Path
    ) -> SweepResult:
        by_name = {s.name: s for s in variants}
        fixed = {
            name: value
            for name, value in self.settings.items()
            if name not in self.specific or takers(name, by_name)
        }
        grid: Grid = {"variant": variants}
        shape = self.shape_of(task, variants[0].name)  # the group's arms share theirs
        if self.tuned is not None:
            chosen = self.tuned["settings"][task]
            grid = [{"variant": v, **split_setting(chosen[v.name])[0]} for v in variants]
        # A stop signal stops the study before the group, or after the chunk in flight but
        # the group's last (the group, recorded when it ends, then trains again from its start).
        said = (
            f"at {task}'s {where.name} (seeds {seeds[0]}–{seeds[-1]}), the groups before it "
            "recorded; the same command goes on from there"
        )
        stop_if_signalled(said)
        last = shaped_protocol(self.expected[task][0], shape).config.num_updates

        def stop(snapshot: Snapshot) -> None:
            if snapshot.update < last:
                stop_if_signalled(said)

        fixed |= config_values(dict(shape))
        return sweep_group(
            task, grid, seeds, where, part=self.part, callback=stop, **self.shape, **fixed
        )

    def shape_of(self, task: str, variant: str) -> RunShape:
        """The run shape `variant` trains on `task` where its tuned setting's differs from the
        task's (empty: the task's)."""
        chosen = shape_of(None if self.tuned is None else self.tuned["settings"][task][variant])
        config = self.expected[task][0].config
        return tuple((name, v) for name, v in chosen if v != configured(config, name))

    def at_defaults(self, everyone: list[Surrogate]) -> Source:
        """The like of this source for each arm's default setting: the settings a study without
        a tune trains (no hyperparameter given), so that such a study's recorded runs are
        taken from the pool."""
        expected = {
            task: (
                protocol,
                {str(s["variant"]): s for s in expand_grid({"variant": everyone}, task)},
            )
            for task, (protocol, _) in self.expected.items()
        }
        return dataclasses.replace(self, expected=expected, tuned=None)

    def take(self, task: str, variant: Surrogate, seeds: list[int]) -> Taken | None:
        """`variant`'s runs on `task` at `seeds` from the recorded sweeps, if they hold them
        all under the study's protocol and setting (and evaluated, where the study evaluates:
        how often and over how many episodes, a sweep's record does not say)."""
        if self.pool is None or self.shape_of(task, variant.name):
            return None  # an arm in a shape of its own trains its runs
        protocol, setting_of = self.expected[task]
        name = variant.name
        taken = self.pool.take(protocol, setting_of[name], self.identity.get(name), seeds)
        if taken is not None and self.settings.get("eval_every") is not None:
            return taken if "eval_return" in taken.result.metrics else None
        return taken


def _checked_settings(
    task: str,
    everyone: list[Surrogate],
    settings: dict[str, object],
    shape: Shape,
    tuned: dict[str, Setting] | None = None,
) -> tuple[RunRecord, dict[str, Setting]]:
    """Every setting of `task` checked before the plan is written, as a sweep checks them; and
    what a recorded run must match to be reused: the protocol, and each variant's setting (its
    `tuned` one, where a tune chose it)."""
    run = prepare(task, dict(settings), sweepable(everyone), **shape)
    several = [k for k, v in run.hyperparameters.items() if isinstance(v, list | tuple)]
    if several:
        raise InvalidInput(
            f"a study compares one setting per variant: give {', '.join(several)} one value "
            "each (to compare values, sweep them: fppo_jax.sweep)"
        )
    by_name = {s.name: s for s in everyone}
    if tuned is None:
        grid = expand_grid({"variant": everyone, **run.hyperparameters}, task)
    else:
        for chosen in {shape_of(setting) for setting in tuned.values()} - {()}:
            # each run shape a tune chose, checked to make a run of the study's budget
            prepare(task, {**settings, **config_values(dict(chosen))}, (), **shape)
        picked = [{"variant": s, **split_setting(tuned[s.name])[0]} for s in everyone]
        grid = expand_grid(picked, task)
    for setting in grid:
        values = {k: v for k, v in setting.items() if k != "variant"}
        resolve_hyperparameters(by_name[str(setting["variant"])], None, **values)
    return run.record(), {str(s["variant"]): s for s in grid}


# A share writes no decision (array tasks train side by side): the join records its commit.
SHARE_FILE = "share.json"


def sweep_group(
    task: str,
    grid: Grid,
    seeds: list[int],
    where: Path,
    part: tuple[int, int] | None = None,
    **settings: Any,
) -> SweepResult:
    """One group: the settings of `grid` × `seeds` on `task` as one sweep that records itself
    in `where` (or its `part`, in ``where/part-<K>``), read back from there (as a resumed study
    reads it).
    One cut short (a killed study) is trained again; a group whose shares array tasks began is
    not trained whole over them."""
    if part is None:
        refuse_missing_shares(where)
    else:
        where = where / f"part-{part[0]}"
    if where.exists():
        shutil.rmtree(where)
    sweep(task, grid, seeds, log_dir=where, part=part, **settings)
    if part is not None:
        write_json(where / SHARE_FILE, {"commit": commit()})
    return SweepResult.read(where)


def share_commits(where: Path) -> list[str]:
    """The commit each share of the group in `where` trained at, in part order (``""`` for a
    share that recorded none); empty for a group that did not train in shares."""
    shares = sorted(
        (p.parent for p in where.glob("part-*/sweep.json")),
        key=lambda share: int(share.name.removeprefix("part-")),
    )
    return [
        json.loads(path.read_text())["commit"] if (path := share / SHARE_FILE).exists() else ""
        for share in shares
    ]


def recorded_group(
    where: Path, variants: list[Surrogate], seeds: list[int], part: tuple[int, int] | None = None
) -> SweepResult | None:
    """The group in `where` if it holds every run of `variants` × `seeds`, whole or joined from
    the shares that array tasks recorded in ``part-<K>/``; with `part`, that share alone, if it
    holds all its runs. None if it holds none or some of them. A group of other runs is
    refused: the plan did not make it."""
    runs = len(variants) * len(seeds)
    if part is not None:
        where = where / f"part-{part[0]}"
    found = [SweepResult.read(where)] if (where / "sweep.json").exists() else []
    shares = sorted(where.glob("part-*/sweep.json"))
    if shares:
        try:
            found.append(merge([SweepResult.read(share.parent) for share in shares]))
        except InvalidInput:  # some shares are still to come
            pass
    for result in found:  # a group trained whole and cut short may have been finished in shares
        names = [str(s["variant"]) for s in result.settings]
        if names != [v.name for v in variants] or result.config["seeds"] != seeds:
            raise InvalidInput(
                f"{where} holds a group of {', '.join(names)} on seeds {result.config['seeds']}, "
                f"where the study's plan needs {', '.join(v.name for v in variants)} on {seeds}"
            )
        expected = runs
        if part is not None:  # the share of the group's runs, by the groups they trained in
            size = result.config.get("runs_per_call")
            if not isinstance(size, int) or size < 1:
                continue
            start, stop = part_runs(part, runs, size)
            expected = stop - start
        if len(result.runs) == expected:
            return result
    return None


def refuse_missing_shares(where: Path) -> None:
    """Raise if the group in `where`, not recorded whole, holds some of the shares that array
    tasks train (``part-<K>/``), naming what joining them says is missing: trained whole over
    them, or decided without them, the shares would be lost."""
    shares = sorted(where.glob("part-*/sweep.json"))
    if not shares:
        return
    try:
        merge([SweepResult.read(share.parent) for share in shares])
    except InvalidInput as error:
        raise InvalidInput(
            f"{where} holds shares of its runs trained by array tasks (--part), and not all of "
            f"them: {error}. Run the missing ones with --part K/N, then this again"
        ) from None


def runs_of(result: TaskRuns, variant: str) -> list[int]:
    """`variant`'s runs in `result` (indices in the sweep that holds them,
    :func:`~fppo_jax.analysis.study_shapes.holding`), in seed order."""
    result = holding(result, variant)
    index = [s["variant"] for s in result.settings].index(variant)
    runs = [i for i, run in enumerate(result.runs) if run["setting"] == index]
    return sorted(runs, key=lambda i: result.runs[i]["seed"])


def run_scores(result: TaskRuns, variant: str, endpoint: str) -> np.ndarray:
    """`variant`'s score per run in `result`, in seed order; a run that diverged or finished no
    episode (or, for ``eval``, no evaluation) scores −inf, below every other (a run that
    failed)."""
    result = holding(result, variant)
    runs = runs_of(result, variant)
    metric = "eval_return" if endpoint == "eval" else "average_return"
    if metric not in result.metrics:
        raise InvalidInput(
            f"the eval endpoint needs every run's evaluations, and {variant}'s runs on "
            f"{result.config['env']} have none: runs taken from recorded sweeps (reuse) that "
            "were not evaluated cannot be scored on it"
        )
    scores = statistics.endpoint(result.metrics[metric][runs], endpoint)
    failed = (np.asarray(result.diverged)[runs] > 0) | ~np.isfinite(scores)
    return np.where(failed, -np.inf, scores)
