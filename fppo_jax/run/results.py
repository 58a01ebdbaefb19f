"""What training produces: :class:`TrainResult` of one run, :class:`SweepResult` of a sweep
(its tables and comparisons), :func:`merge` of a sweep's parts, and the paper's "max average
return". A sweep's files are :mod:`fppo_jax.store.sweep_files`'."""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, cast

import numpy as np

from fppo_jax.core.policy import Policy
from fppo_jax.core.resolution import SYMBOLS, VARIANT_SPECIFIC
from fppo_jax.core.trainer import METRICS, TrainState
from fppo_jax.envs import Environment, backend_name, resets_itself
from fppo_jax.errors import InvalidInput
from fppo_jax.stats import statistics
from fppo_jax.store.files import write_atomically
from fppo_jax.store.record import RunRecord
from fppo_jax.store.saved_policy import save_policy
from fppo_jax.store.sweep_files import read_sweep, write_sweep


@dataclasses.dataclass
class TrainResult:
    """The outcome of :func:`train`.

    `metrics` maps each name of :data:`fppo_jax.core.trainer.METRICS` to one value per update.
    `policy(obs, key=None)` acts on raw observations (one or a batch): the most likely action
    without a key, a sample with one.
    """

    metrics: dict[str, np.ndarray]
    params: dict[str, Any]
    config: dict[str, Any]
    state: TrainState
    policy: Policy
    compile_seconds: float
    train_seconds: float
    env: Environment
    resumed_from: int = 0  # the update a resumed run started from its checkpoint
    stopped_at: int | None = None  # the update where a callback stopped training

    def write(self, directory: str | Path) -> None:
        """``summary.txt`` in `directory`, whole or not at all (``config.json`` and
        ``metrics.csv`` are written as training goes, by ``log_dir``)."""
        directory = Path(directory)
        directory.mkdir(parents=True, exist_ok=True)
        write_atomically(directory / "summary.txt", (self.summary() + "\n").encode())

    def save(self, directory: str | Path, *, overwrite: bool = False) -> Path:
        """Save the trained policy and the run's configuration in `directory`, for
        :func:`fppo_jax.load_policy` and ``fppo-jax eval --checkpoint`` (see
        :func:`fppo_jax.store.saved_policy.save_policy`); a saved policy already there is refused
        unless `overwrite`. Returns the directory."""
        record = {"config": self.config, "update": len(self.metrics["env_steps"])}
        return save_policy(directory, self.policy, record, overwrite=overwrite)

    def render(self, path: str | Path, *, seed: int = 0, max_steps: int = 1000) -> Path:
        """Save one episode of the trained policy (the most likely actions) on a MuJoCo task
        as a ``.png`` image strip, a ``.gif`` or an ``.mp4``; see :mod:`fppo_jax.export.render` (a
        native MuJoCo run is drawn on MJX, by :func:`~fppo_jax.export.render.drawable`)."""
        from fppo_jax.export.render import drawable, render_policy

        env = drawable(self.env, self.config["env"])
        return render_policy(env, self.policy, path, seed=seed, max_steps=max_steps)

    def summary(self) -> str:
        """A few lines: the run, its speed, its returns and its escape-speed diagnostic."""
        m, c = self.metrics, self.config
        steps = int(m["env_steps"][-1])
        returns = m["average_return"]
        own = (c.get("surrogates") or {}).get(c["variant"], {}).get("hyperparameters", {})
        shown = dict.fromkeys((*VARIANT_SPECIFIC, *own))
        settings = ", ".join(f"{k} = {c[k]:g}" for k in shown if k in c)
        settings = ", ".join(filter(None, [settings, f"epsilon = {c['epsilon']:g}"]))
        samples = c["num_envs"] * c["num_steps"]
        trained = steps - self.resumed_from * samples
        speed = f"{trained / self.train_seconds:,.0f} env steps/s" if trained else "nothing left"
        backend = backend_name(c.get("backend"))  # a MuJoCo run's, which physics stepped it
        resumed = f", resumed at update {self.resumed_from}" if self.resumed_from else ""
        if resumed and resets_itself(self.env):
            resumed += " in fresh environments"
        if self.stopped_at is not None:
            resumed += f", stopped by the callback at update {self.stopped_at}"
        shape = ", ".join(filter(None, [f"preset {c.get('preset', 'paper')}", backend]))
        lines = [
            f"{c['variant']} on {c['env']} ({settings}), seed {c['seed']}",
            f"  updates   {len(returns)} × {samples:,} samples = {steps:,} env steps "
            f"({shape}){resumed}",
            f"  time      compile {self.compile_seconds:.1f} s, train {self.train_seconds:.1f} s "
            f"({speed})",
        ]
        if np.isfinite(returns).any():
            best = int(np.nanargmax(returns))
            lines.append(
                f"  return    final {returns[-1]:.1f}, max {returns[best]:.1f} at "
                f"{int(m['env_steps'][best]):,} steps (mean of the last 100 episodes)"
            )
        else:
            lines.append("  return    no episode finished")
        lines += [
            f"  escape    in R+ ∪ R- after the update: {np.mean(m['negative_fraction_after']):.2%}"
            f" of samples (first epoch: {np.mean(m['negative_fraction_before']):.2%}), mean "
            f"distance past the bound {np.mean(m['negative_distance_after']):.3f}",
            f"  last      policy loss {m['policy_loss'][-1]:.4f}, value loss "
            f"{m['value_loss'][-1]:.4f}, entropy {m['entropy'][-1]:.3f}, approx KL "
            f"{m['approx_kl'][-1]:.4f}, clip fraction {m['clip_fraction'][-1]:.3f}",
        ]
        return "\n".join(lines)


def labels(settings: Sequence[Mapping[str, Any]]) -> list[str]:
    """Each setting in a few characters, e.g. ``fppo-lp α=1.3``: the variant, its own α, k or δ,
    and whatever else differs between the settings."""
    keys = dict.fromkeys(k for s in settings for k in s if k != "variant")
    varying = {k for k in keys if len({s.get(k) for s in settings}) > 1}
    shown = [k for k in keys if k in VARIANT_SPECIFIC or k in varying]
    return [
        " ".join([str(s["variant"]), *[f"{SYMBOLS.get(k, k)}={s[k]:g}" for k in shown if k in s]])
        for s in settings
    ]


@dataclasses.dataclass
class SweepResult:
    """Every run of a sweep: `runs[i]` is run i's setting and seed, `metrics[name][i]` its
    per-update values, `diverged[i]` the update (from 1) where it diverged, or 0."""

    settings: list[dict[str, Any]]
    seeds: list[int]
    runs: list[dict[str, Any]]
    metrics: dict[str, np.ndarray]
    diverged: np.ndarray
    config: dict[str, Any]
    compile_seconds: float
    train_seconds: float

    def setting_runs(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        """Setting `index`'s runs that did not diverge (indices into `runs`), and the update
        each of its other runs diverged at."""
        runs = np.flatnonzero([run["setting"] == index for run in self.runs])
        diverged = np.asarray(self.diverged)[runs]
        return runs[diverged == 0], diverged[diverged > 0]

    def setting_metrics(self, index: int) -> dict[str, np.ndarray]:
        """Metrics of setting `index`'s runs that did not diverge, [seed, update]: what its
        figures are over (:meth:`setting_seeds` says how many)."""
        kept, _ = self.setting_runs(index)
        return {name: values[kept] for name, values in self.metrics.items()}

    def setting_run_count(self, index: int) -> int:
        """How many runs setting `index` has, diverged ones included."""
        return sum(run["setting"] == index for run in self.runs)

    def setting_seeds(self, index: int) -> str:
        """How many seeds setting `index`'s figures are over, as the table's ``seeds`` column
        says it: ``5``, or ``3 of 5 (2 diverged)``."""
        kept, diverged = self.setting_runs(index)
        total = kept.size + diverged.size
        return f"{kept.size} of {total} ({diverged.size} diverged)" if diverged.size else f"{total}"

    def scores(self, endpoint: str = "final") -> list[np.ndarray]:
        """Each setting's score per run that did not diverge, by `endpoint` of its average-return
        curve, or of its evaluation returns for ``eval``
        (:data:`fppo_jax.stats.statistics.ENDPOINTS`)."""
        metric = "eval_return" if endpoint == "eval" else "average_return"
        if metric not in self.metrics:
            raise InvalidInput(
                "the eval endpoint needs evaluations, and this sweep recorded none: train it "
                "with eval_every (--eval-every)"
            )
        return [
            statistics.endpoint(self.setting_metrics(i)[metric], endpoint)
            for i in range(len(self.settings))
        ]

    def table(
        self,
        statistic: str = "paper",
        endpoint: str = "final",
        confidence: float = statistics.CONFIDENCE,
    ) -> str:
        """One row per setting, Markdown, over the seeds whose runs did not diverge (`seeds`
        says how many, and how many diverged: :meth:`setting_seeds`).

        ``statistic="paper"``, Table 1 style: the max average return (the maximum over updates
        of the seed-mean curve, ± the sample std across seeds there), the env steps it was
        reached at, the final average return and the share of samples in R± after the update; a
        setting whose runs all diverged reads ``diverged at update N`` instead of figures.
        Otherwise `statistic` (``iqm``, ``mean`` or ``median``) of each run's `endpoint` score,
        with its percentile bootstrap interval at level `confidence`, and the sample std
        (:mod:`fppo_jax.stats.statistics`)."""
        if statistic != "paper":
            return self._interval_table(statistic, endpoint, confidence)
        lines = [
            "| setting | seeds | max average return ± sample std | at env steps "
            "| final average return | in R± after update |",
            "|---|---|---|---|---|---|",
        ]
        for index, name in enumerate(labels(self.settings)):
            kept, diverged = self.setting_runs(index)
            if kept.size:
                figures = self._figures(kept)
            else:  # every run diverged, or the sweep stopped before this setting's runs
                failed = f"diverged at update {diverged.min()}" if diverged.size else "not trained"
                figures = [failed, "–", "–", "–"]
            lines.append(f"| {name} | {self.setting_seeds(index)} | {' | '.join(figures)} |")
        return "\n".join(lines)

    def _interval_table(self, statistic: str, endpoint: str, confidence: float) -> str:
        statistics.estimator(statistic)
        confidence = statistics.check_confidence(confidence)
        level = f"{confidence:.0%} CI"
        lines = [
            f"| setting | seeds | {statistics.STATISTICS[statistic]} of the {endpoint} score "
            f"[{level}] | sample std |",
            "|---|---|---|---|",
        ]
        scores = self.scores(endpoint)
        for index, name in enumerate(labels(self.settings)):
            point, low, high = statistics.interval(scores[index], statistic, confidence=confidence)
            std = statistics.sample_std(scores[index])
            figures = "–" if np.isnan(point) else f"{point:.1f} [{low:.1f}, {high:.1f}]"
            spread = "–" if np.isnan(std) else f"{std:.1f}"
            lines.append(f"| {name} | {self.setting_seeds(index)} | {figures} | {spread} |")
        return "\n".join(lines)

    def compare(
        self,
        baseline: str = "ppo",
        endpoint: str = "final",
        confidence: float = statistics.CONFIDENCE,
    ) -> str:
        """Every other setting against `baseline` (a setting's label, e.g. ``ppo`` or
        ``fppo-lp α=1.3``, or a variant that only one setting has), Markdown: the probability
        that a run of the setting scores above a run of the baseline, and the difference in
        IQM, each with its bootstrap interval at level `confidence`, on `endpoint` scores
        (:func:`fppo_jax.stats.statistics.compare`)."""
        names = labels(self.settings)
        index = self.setting_index(baseline)
        scores = self.scores(endpoint)
        level = f"{statistics.check_confidence(confidence):.0%} CI"
        lines = [
            f"Against {names[index]} ({self.setting_seeds(index)} seeds), {endpoint} return "
            f"({statistics.ENDPOINTS[endpoint]}):",
            "",
            f"| setting | seeds | P(setting > {names[index]}) [{level}] "
            f"| IQM difference [{level}] |",
            "|---|---|---|---|",
        ]
        for other, name in enumerate(names):
            if other == index:
                continue
            result = statistics.compare(scores[other], scores[index], confidence=confidence)
            cells = [
                "–" if np.isnan(point) else f"{point:{form}} [{low:{form}}, {high:{form}}]"
                for (point, low, high), form in zip(result.values(), (".2f", ".1f"), strict=True)
            ]
            lines.append(f"| {name} | {self.setting_seeds(other)} | {' | '.join(cells)} |")
        return "\n".join(lines)

    def setting_index(self, name: str) -> int:
        """The setting called `name`: its label (:func:`labels`), or a variant only it has."""
        names = labels(self.settings)
        if name in names:
            return names.index(name)
        matches = [i for i, s in enumerate(self.settings) if s["variant"] == name]
        if len(matches) == 1:
            return matches[0]
        found = "several settings" if matches else "no setting"
        raise InvalidInput(
            f"{found} of the sweep called {name!r}; its settings: {', '.join(names)}"
        )

    def _figures(self, runs: np.ndarray) -> list[str]:
        """The table's figures over `runs`, "–" for what is not known (no episode finished, a
        metric not recorded)."""
        returns = self.metrics["average_return"][runs]
        best, std, at = max_average_return(returns)
        if at < 0:
            return ["no episode finished", "–", "–", "–"]
        final = nanmean(returns[:, -1])
        fraction = self.metrics.get("negative_fraction_after")
        return [
            f"{best:.1f}" if np.isnan(std) else f"{best:.1f} ± {std:.1f}",  # one seed: no spread
            f"{int(self.metrics['env_steps'][runs[0], at]):,}",
            f"{final:.1f}" if np.isfinite(final) else "–",
            "–" if fraction is None else f"{np.mean(fraction[runs]):.2%}",
        ]

    def write(self, directory: str | Path, metrics: Sequence[str] | None = None) -> None:
        """`curves.csv` and `sweep.json` in `directory` (see :mod:`fppo_jax.store.sweep_files`),
        with a column per name in `metrics`: by default every metric recorded, the trainer's and
        the host's such as ``eval_return``; ``env_steps`` always. Fewer metrics make a smaller
        file to keep."""
        if metrics is None:
            metrics = [*(m for m in METRICS if m in self.metrics)]
            metrics += sorted(set(self.metrics) - set(METRICS))
        unknown = [name for name in metrics if name not in self.metrics]
        if unknown:
            raise InvalidInput(
                f"no metric {', '.join(map(repr, unknown))} in this sweep; it has "
                + ", ".join(self.metrics)
            )
        if "env_steps" not in metrics:  # every curve's x axis, which a reader needs
            metrics = ["env_steps", *metrics]
        record = {
            "settings": self.settings,
            "seeds": self.seeds,
            "runs": self.runs,
            "diverged": self.diverged.tolist(),
            "config": self.config,
            "compile_seconds": self.compile_seconds,
            "train_seconds": self.train_seconds,
        }
        write_sweep(directory, record, {name: self.metrics[name] for name in metrics})

    @classmethod
    def read(cls, directory: str | Path) -> SweepResult:
        """What :meth:`write` wrote, checked (see :func:`~fppo_jax.store.sweep_files.read_sweep`): a
        `curves.csv` filtered to some runs gives those runs, with a warning."""
        record, metrics, present = read_sweep(directory)
        return cls(
            settings=record["settings"],
            seeds=list(dict.fromkeys(record["runs"][i]["seed"] for i in present)),
            runs=[record["runs"][i] for i in present],
            metrics=metrics,
            diverged=np.asarray(record["diverged"], np.int64)[present],
            config=record["config"],
            compile_seconds=record["compile_seconds"],
            train_seconds=record["train_seconds"],
        )


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
    settings: list[dict[str, Any]] = []
    runs: list[dict[str, Any]] = []
    setting: dict[str, Any] | int  # a setting, then a setting's index
    for part in parts:
        for setting in part.settings:
            if setting not in settings:
                settings.append(setting)
        for run in part.runs:
            setting = settings.index(part.settings[run["setting"]])
            runs.append({"setting": setting, "seed": run["seed"]})
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


def _check_each_run_once(settings: list[dict[str, Any]], runs: list[dict[str, Any]]) -> None:
    seen: dict[tuple[int, int], int] = {}
    for run in runs:
        key = (run["setting"], run["seed"])
        seen[key] = seen.get(key, 0) + 1
    names = labels(settings)
    repeated = [f"{names[s]} seed {seed}" for (s, seed), count in seen.items() if count > 1]
    if repeated:
        raise InvalidInput(f"more than one part holds the run {', '.join(repeated[:5])}")


def _own_surrogates(parts: Sequence[SweepResult]) -> dict[str, Any]:
    """The surrogates of one's own that `parts` ran, by name; two functions under one name
    (their records' digests differ) are refused."""
    own: dict[str, Any] = {}
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
    parts: Sequence[SweepResult], settings: list[dict[str, Any]], runs: list[dict[str, Any]]
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


def max_average_return(average_return: np.ndarray) -> tuple[float, float, int]:
    """The paper's statistic on [seed, update]: the maximum over updates of the seed-mean curve,
    the sample std (ddof 1) across seeds at that update, and the update's index (NaN, NaN, −1 if
    no episode ever finished). It is biased upward, by an amount that differs between settings:
    compare settings on an endpoint chosen in advance (:mod:`fppo_jax.stats.statistics`)."""
    curve = nanmean(average_return, axis=0)
    if not np.isfinite(curve).any():
        return np.nan, np.nan, -1
    best = int(np.nanargmax(curve))
    return float(curve[best]), statistics.sample_std(average_return[:, best]), best


def nanmean(x: np.ndarray, axis: int | None = None) -> np.ndarray:
    with warnings.catch_warnings():
        # All-NaN slices (no episode finished yet in any seed) are meant to stay NaN.
        warnings.simplefilter("ignore", RuntimeWarning)
        return cast(np.ndarray, np.nanmean(x, axis=axis))
