"""Runs recorded elsewhere that a study takes instead of training them again: a pool of recorded
sweeps (every ``sweep.json`` under the directories given), searched for one setting's runs at
given seeds.

A recorded run is taken for the study's own only when its sweep ran the same task under the
same protocol (:meth:`~fppo_jax.store.record.RunRecord.protocol`: the environment, its
backend, the preset, the budget and the run's shape), its setting is the one the study
trains (the variant and every hyperparameter it sets), and, for a surrogate of one's own, the
function is the same (its digest). What this cannot see is the training code that made the
runs: a pool is only as good as that code, which the regression pins (``tests/test_regression.py``)
say is unchanged or not. So the study's plan names the pool, and its ``decisions.json`` every
run taken from it, with the sweep it came from.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from fppo_jax.core.config import Setting
from fppo_jax.errors import MissingFile
from fppo_jax.run.merge import merge
from fppo_jax.run.results import SweepResult
from fppo_jax.store.record import RunRecord


@dataclasses.dataclass(frozen=True)
class Taken:
    """One setting's runs taken from a pool: merged into one sweep of that setting alone, and
    the recorded sweeps they came from."""

    result: SweepResult
    sources: list[Path]


@dataclasses.dataclass(frozen=True)
class Pool:
    """Recorded sweeps, each with the directory it was read from."""

    sweeps: list[tuple[Path, SweepResult]]

    @classmethod
    def read(cls, directories: Sequence[str | Path]) -> Pool:
        """Every sweep recorded under `directories` (each ``sweep.json`` and its curves, their
        digests checked as :meth:`SweepResult.read` checks them)."""
        missing = [str(d) for d in directories if not Path(d).is_dir()]
        if missing:
            raise MissingFile(f"no directory of recorded sweeps to reuse at {', '.join(missing)}")
        found = sorted({p.parent for d in directories for p in Path(d).rglob("sweep.json")})
        return cls([(where, SweepResult.read(where)) for where in found])

    def take(
        self,
        protocol: RunRecord,
        setting: Setting,
        identity: Mapping[str, object] | None,
        seeds: Sequence[int],
    ) -> Taken | None:
        """`setting`'s runs at every one of `seeds`, from the sweeps of `protocol`
        (:meth:`RunRecord.protocol`) that ran `setting` with the surrogate `identity`
        (None: a built-in's); a seed found in several sweeps is taken from the first. None
        unless every seed is found: a group is reused whole or trained."""
        chosen: dict[int, tuple[Path, SweepResult, int]] = {}
        for where, recorded in self.sweeps:
            record = _record(recorded)
            if record.protocol() != protocol or setting not in recorded.settings:
                continue
            if record.surrogates.get(str(setting["variant"])) != identity:
                continue
            index = recorded.settings.index(setting)
            for run, entry in enumerate(recorded.runs):
                if entry["setting"] == index and entry["seed"] in seeds:
                    chosen.setdefault(entry["seed"], (where, recorded, run))
        if set(chosen) != set(seeds):
            return None
        by_sweep: dict[Path, tuple[SweepResult, list[int]]] = {}
        for seed in sorted(seeds):
            where, recorded, run = chosen[seed]
            by_sweep.setdefault(where, (recorded, []))[1].append(run)
        parts = [runs_alone(recorded, runs) for recorded, runs in by_sweep.values()]
        return Taken(merge(parts), list(by_sweep))


def protocol_differences(config: Mapping[str, object], protocol: RunRecord) -> list[str]:
    """Where a recorded sweep's `config` and `protocol` differ, field by field, each as
    ``name: <recorded> there, <protocol's> in this call``."""
    recorded = RunRecord.from_json(config, "a recorded sweep's record").protocol()
    return recorded.differences(protocol, "there", "in this call")


def _record(recorded: SweepResult) -> RunRecord:
    return RunRecord.from_json(recorded.config, "a recorded sweep's record")


def runs_alone(recorded: SweepResult, runs: list[int]) -> SweepResult:
    """The sweep of `recorded`'s `runs` alone, all of one setting."""
    setting = recorded.settings[recorded.runs[runs[0]]["setting"]]
    seeds = [recorded.runs[run]["seed"] for run in runs]
    record = _record(recorded)
    variant = str(setting["variant"])
    own = record.surrogates.get(variant)
    surrogates = {variant: own} if own else {}
    record = dataclasses.replace(record, grid=None, seeds=tuple(seeds), surrogates=surrogates)
    return SweepResult(
        settings=[setting],
        seeds=seeds,
        runs=[{"setting": 0, "seed": seed} for seed in seeds],
        metrics={name: values[runs] for name, values in recorded.metrics.items()},
        diverged=np.asarray(recorded.diverged)[runs],
        config=record.to_json(),
        compile_seconds=0.0,
        train_seconds=0.0,
    )
