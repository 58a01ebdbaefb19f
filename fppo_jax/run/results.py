"""What a sweep produces: :class:`SweepResult` (its tables and comparisons), with each setting's
label and the paper's "max average return". One run's is :mod:`fppo_jax.run.train_result`'s
:class:`TrainResult`, and :mod:`fppo_jax.run.merge` joins a sweep's parts. A sweep's files are
:mod:`fppo_jax.store.sweep_files`'."""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, cast

import numpy as np

from fppo_jax.core.config import Setting
from fppo_jax.core.resolution import SYMBOLS, VARIANT_SPECIFIC
from fppo_jax.core.trainer import METRICS
from fppo_jax.errors import InvalidInput
from fppo_jax.stats import statistics
from fppo_jax.store.sweep_files import SweepRecord, SweepRun, read_sweep, write_sweep


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
    per-update values, `diverged[i]` the update (from 1) where it diverged, or 0; the machines
    it trained on, whose are its seconds (none in sweeps recorded before they were kept)."""

    settings: list[Setting]
    seeds: list[int]
    runs: list[SweepRun]
    metrics: dict[str, np.ndarray]
    diverged: np.ndarray
    config: dict[str, Any]
    compile_seconds: float
    train_seconds: float
    machines: list[str] = dataclasses.field(default_factory=list)

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
        record: SweepRecord = {
            "settings": self.settings,
            "seeds": self.seeds,
            "runs": self.runs,
            "diverged": self.diverged.tolist(),
            "config": self.config,
            "compile_seconds": self.compile_seconds,
            "train_seconds": self.train_seconds,
        }
        if self.machines:
            record["machines"] = self.machines
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
            machines=record.get("machines", []),
        )


# What may differ between parts of one study: which settings, seeds and share of its runs each
# ran, how many runs per call (but not between the shares of one split: merge checks it), and
# which surrogates of one's own (one function per name).
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
