""":func:`merge`: a sweep's parts, trained apart (other seeds, or a split sweep's parts),
joined into one :class:`~fppo_jax.run.results.SweepResult` once shown to be parts of one sweep."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np

from fppo_jax.core.config import Setting
from fppo_jax.core.surrogates import SurrogateIdentity
from fppo_jax.errors import InvalidInput
from fppo_jax.run.results import SweepResult, labels
from fppo_jax.store.record import RunRecord
from fppo_jax.store.sweep_files import SweepRun


def merge(parts: Sequence[SweepResult]) -> SweepResult:
    """One sweep of the runs of `parts`, sweeps of the same task and protocol that ran other
    seeds or other settings: what ``table``, ``compare`` and ``plot`` read as if one process had
    run them all. The merged grid holds each axis's values from every part. An ``InvalidInput``
    names the configuration field on which two parts differ and a (setting, seed) run that two
    parts both hold; for the shares of one sweep (``sweep(..., part=(K, N))``), which share one
    grid, it also names the runs, and the parts, still missing, joins them in the order of
    their part numbers, and refuses shares trained in groups of different sizes (their
    ``runs_per_call``): the shares of one group size join into the sweep trained unsplit with
    it, bit for bit. Metrics not in every part are left out."""
    if not parts:
        raise InvalidInput("merge needs at least one sweep")
    first = parts[0]
    _check_same_sweep(parts)
    own = _own_surrogates(parts)
    if all(part.config.get("part") for part in parts):
        # The shares of one split in their sweep's run order, whatever order they were named in:
        # a shell lists part-10 before part-2, and the order of the runs is the order of curves.csv.
        parts = sorted(parts, key=lambda part: part.config["part"][0])
        _check_one_group_size(parts)
    settings: list[Setting] = []
    runs: list[SweepRun] = []
    for part in parts:
        for setting in part.settings:
            if setting not in settings:
                settings.append(setting)
        for run in part.runs:
            index = settings.index(part.settings[run["setting"]])
            runs.append(SweepRun(setting=index, seed=run["seed"]))
    _check_each_run_once(settings, runs)
    _check_shares(parts, settings, runs)
    metrics = [name for name in first.metrics if all(name in p.metrics for p in parts)]
    seeds = list(dict.fromkeys(seed for part in parts for seed in part.seeds))
    grid = _merged_grid(parts)
    return SweepResult(
        settings=settings,
        seeds=seeds,
        runs=runs,
        metrics={name: np.concatenate([p.metrics[name] for p in parts]) for name in metrics},
        diverged=np.concatenate([np.asarray(p.diverged, np.int64) for p in parts]),
        config=dataclasses.replace(
            RunRecord.from_json(first.config, "sweep 1's record"),
            grid=grid or None,
            seeds=tuple(seeds),
            part=None,
            surrogates=own,
        ).to_json(),
        compile_seconds=sum(p.compile_seconds for p in parts),
        train_seconds=sum(p.train_seconds for p in parts),
        machines=list(dict.fromkeys(m for p in parts for m in p.machines)),
    )


def _merged_grid(parts: Sequence[SweepResult]) -> dict[str, list[Any]]:
    """Each axis's values from every part's grid, in the order they first appear."""
    grid: dict[str, list[Any]] = {}
    for part in parts:
        for axis, values in (part.config.get("grid") or {}).items():
            known = grid.setdefault(axis, [])
            known += [v for v in values if v not in known]
    return grid


def _check_same_sweep(parts: Sequence[SweepResult]) -> None:
    """Parts of one sweep differ in their seeds, settings and share alone: they share one
    protocol."""
    first = RunRecord.from_json(parts[0].config, "sweep 1's record").protocol()
    for number, part in enumerate(parts[1:], start=2):
        record = RunRecord.from_json(part.config, f"sweep {number}'s record").protocol()
        differing = record.differences(first, f"in sweep {number}", "in sweep 1")
        if differing:
            raise InvalidInput(
                f"sweep {number} is not a part of the same sweep as sweep 1: "
                + "; ".join(differing)
            )


def _check_one_group_size(parts: Sequence[SweepResult]) -> None:
    """The shares of one split trained the whole sweep's groups of one size: shares of other
    sizes computed other programs, and hold other runs than their part numbers say."""
    sizes = [part.config.get("runs_per_call") for part in parts]
    if len(set(map(repr, sizes))) > 1:
        each = ", ".join(
            f"part {part.config['part'][0]} of {part.config['part'][1]}: {size}"
            for part, size in zip(parts, sizes, strict=True)
        )
        raise InvalidInput(
            f"the sweeps are not shares of one split: their runs_per_call (the sweep's group "
            f"size, runs per compiled call) differ ({each}); train every part with one chunk "
            "(--chunk)"
        )


def _check_each_run_once(settings: list[Setting], runs: list[SweepRun]) -> None:
    seen: dict[tuple[int, int], int] = {}
    for run in runs:
        key = (run["setting"], run["seed"])
        seen[key] = seen.get(key, 0) + 1
    names = labels(settings)
    repeated = [f"{names[s]} seed {seed}" for (s, seed), count in seen.items() if count > 1]
    if repeated:
        raise InvalidInput(f"more than one part holds the run {', '.join(repeated[:5])}")


def _own_surrogates(parts: Sequence[SweepResult]) -> dict[str, SurrogateIdentity]:
    """The surrogates of one's own that `parts` ran, by name; two functions under one name
    (their records' digests differ) are refused."""
    own: dict[str, SurrogateIdentity] = {}
    for number, part in enumerate(parts, start=1):
        for name, identity in (part.config.get("surrogates") or {}).items():
            first = own.setdefault(name, identity)
            if first != identity:
                raise InvalidInput(
                    f"sweep {number} ran another surrogate named {name!r} than an earlier sweep "
                    f"(digest {identity.get('digest')} against {first.get('digest')}): give "
                    "each its own name"
                )
    return own


def _check_shares(
    parts: Sequence[SweepResult], settings: list[Setting], runs: list[SweepRun]
) -> None:
    """For shares of one sweep (``part`` in their configurations): all of one split, and every
    run of the whole sweep there."""
    shares: list[Any] = [p.config.get("part") for p in parts]
    if all(share is None for share in shares):
        return
    if any(share is None for share in shares) or len({share[1] for share in shares}) > 1:
        raise InvalidInput(
            "the sweeps are not shares of one split: their parts are "
            + ", ".join("whole" if s is None else f"{s[0]} of {s[1]}" for s in shares)
        )
    if any(p.config.get("grid") != parts[0].config.get("grid") for p in parts):
        raise InvalidInput("the sweeps are not shares of one split: their grids differ")
    count = shares[0][1]
    missing_parts = sorted(set(range(1, count + 1)) - {share[0] for share in shares})
    found = {(run["setting"], run["seed"]) for run in runs}
    names = labels(settings)
    missing = [
        f"{names[i]} seed {seed}"
        for i in range(len(settings))
        for seed in parts[0].config["seeds"]
        if (i, seed) not in found
    ]
    if missing:
        more = f" and {len(missing) - 5} more" if len(missing) > 5 else ""
        spelled = ", ".join(f"--part {k}/{count}" for k in missing_parts)
        many = len(missing_parts) > 1
        which = (
            f"part{'s' * many} {', '.join(map(str, missing_parts))} of {count} ({spelled}) "
            f"{'are' if many else 'is'} missing: " * bool(missing_parts)
        )
        raise InvalidInput(f"{which}the sweep's runs {', '.join(missing[:5])}{more} are not there")
