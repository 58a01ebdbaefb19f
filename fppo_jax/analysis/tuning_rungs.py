"""A tune's loop over one task (:class:`TaskTune`): the scheduler's windows trained one after the
other by the task's population (:mod:`fppo_jax.analysis.population`), each a rung (a round)
recorded in ``<task>/rung-<r>/`` (its scores, and the state the next window goes on from) and
told to Optuna; or a share of one, for an array task, joined later into the rung trained
unsplit. The loop knows no scheduler (:mod:`fppo_jax.analysis.scheduling`)."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np

from fppo_jax.analysis.halving import ranked
from fppo_jax.analysis.population import (
    Population,
    Trained,
    Window,
    read_leaves,
    save_leaves,
)
from fppo_jax.analysis.preregistration import commit
from fppo_jax.analysis.scheduling import Scheduler
from fppo_jax.analysis.tune_files import (
    SCORES_FILE,
    STATE_FILE,
    read_rung,
    read_share,
    rung_directory,
)
from fppo_jax.analysis.tune_storage import study_name
from fppo_jax.analysis.tuning_records import ArmResults, ArmRung, RungScores, ShareScores
from fppo_jax.analysis.tuning_report import arm_results
from fppo_jax.errors import InvalidInput
from fppo_jax.run.stop_signals import StoppedAtSafePoint, stop_if_signalled
from fppo_jax.store.files import write_json
from fppo_jax.store.machine import NOT_RECORDED, describe_machine


class TaskTune:
    """One task's tune: its `population` trained window by window as the `scheduler` says,
    recorded in `directory`, each rung's scores told to Optuna's `storage`; progress lines go
    where the population's go."""

    def __init__(
        self,
        task: str,
        population: Population,
        scheduler: Scheduler,
        directory: Path,
        optuna: Any,
        storage: Any,
    ):
        self.task, self.population, self.scheduler = task, population, scheduler
        self.directory, self.optuna, self.storage = directory, optuna, storage
        self._say = population.say
        self.scores: list[RungScores] = []  # each recorded rung's

    @property
    def window(self) -> Window | None:
        """What trains next (None: the task is tuned)."""
        return self.scheduler.next_window(self.scores)

    @property
    def finished(self) -> bool:
        return self.window is None

    def read(self, join: bool) -> None:
        """Takes the rungs recorded, and where `join`, the rungs whose shares array tasks
        recorded, joined (a rung with some of its shares missing is refused)."""
        self.directory.mkdir(exist_ok=True)
        while (window := self.window) is not None:
            where = self._where(len(self.scores))
            if (where / SCORES_FILE).exists():
                self._recorded(read_rung(where / SCORES_FILE))
            elif join and any(where.glob(f"part-*/{SCORES_FILE}")):
                self._record(window, *self._read_shares(window))
            else:
                return

    def train(self, allowed: float, part: tuple[int, int] | None) -> int:
        """Trains up to `allowed` rungs after those read, each as its one share; with `part`,
        that share of the next rung alone, recorded for the join. Returns how many rungs it
        trained (or trained a share of). A stop signal (SIGTERM, SIGUSR1) stops it before the
        next rung, or in one after the compiled call in flight, with
        :class:`~fppo_jax.run.stop_signals.StoppedAtSafePoint` saying where the same call goes
        on: the rungs before are recorded, and the rung (or share) stopped in trains again from
        its start, bit for bit."""
        trained = 0
        try:
            while (window := self.window) is not None and trained < allowed:
                stop_if_signalled("")
                if part is not None:
                    self._train_part(window, part)
                    return 1
                self._record(window, [self._share(window, (1, 1))], [describe_machine()])
                trained += 1
        except StoppedAtSafePoint as stopped:
            rung, rounds = len(self.scores) + 1, self.scheduler.rounds
            said = f"at rung {rung} of {rounds} of {self.task}"
            if part is None:
                said += f"; the same command goes on from rung {rung}"
            else:
                said += (
                    f", part {part[0]} of {part[1]}; the same command trains that part again from "
                    "its start (one that cannot end within the job's time limit never ends: "
                    "split the rung into more parts)"
                )
            raise StoppedAtSafePoint(stopped.signal, said) from None
        return trained

    def _where(self, rung: int) -> Path:
        return rung_directory(self.directory, rung)

    def _recorded(self, scores: RungScores) -> None:
        """A rung's scores: taken as recorded, and told to Optuna (again, if a kill came
        between): each trial's score at the rung's end, a diverged trial failed; once the task
        is tuned, the trial chosen told its score (failed without one) and every other trial
        not yet ended pruned. A trial out of one rung may come back in a later one (a race's
        finalist), so none is pruned before the end."""
        window = self.window
        assert window is not None
        self.scores.append(scores)
        done = self.finished
        states = self.optuna.trial.TrialState
        for arm, measured in scores["arms"].items():
            name = study_name(self.storage, self.task, arm)
            study = self.optuna.load_study(study_name=name, storage=self.storage)
            by_number = {t.number: t for t in study.get_trials(deepcopy=False)}
            for row in measured["trials"]:
                frozen = by_number[row["trial"]]
                if frozen.state.is_finished():
                    continue
                value = math.nan if row["score"] is None else row["score"]
                if window.end not in frozen.intermediate_values:
                    self.optuna.trial.Trial(study, frozen._trial_id).report(value, window.end)
                if row["diverged"]:
                    study.tell(row["trial"], state=states.FAIL)
            if done:
                self._end(study, measured)

    def _end(self, study: Any, measured: ArmRung) -> None:
        """The arm's trials ended in Optuna: the one chosen with its score, the others pruned."""
        states = self.optuna.trial.TrialState
        rows = {row["trial"]: row for row in measured["trials"]}
        for frozen in study.get_trials(deepcopy=False):
            if frozen.state.is_finished():
                continue
            row = rows.get(frozen.number)
            if frozen.number not in measured["survivors"] or row is None:
                study.tell(frozen.number, state=states.PRUNED)
            elif row["score"] is None:
                study.tell(frozen.number, state=states.FAIL)  # no episode finished: no score
            else:
                study.tell(frozen.number, row["score"])

    def _record(self, window: Window, shares: list[Trained], machines: list[str]) -> None:
        """Records the next rung from its `shares`, in order, trained on `machines` (each
        share's): its scores and the state the window after it goes on from; then tells Optuna
        (the join alone writes to it)."""
        rung = len(self.scores)
        # A window of several run shapes trains in groups of one shape: back in its order.
        order = np.argsort(np.concatenate([_positions(share) for share in shares]), kind="stable")
        assert [[run for share in shares for run in share.runs][i] for i in order] == list(
            window.runs
        )
        scores_of_runs = np.concatenate([self._scored(share) for share in shares])[order]
        diverged = np.concatenate([share.diverged for share in shares])[order]
        arms = self.scheduler.measured(self.scores, scores_of_runs, diverged)
        seconds = sum(share.seconds for share in shares)
        compile_seconds = sum(share.compile_seconds for share in shares)
        scores: RungScores = {
            "arms": arms,
            "seconds": seconds,
            "compile_seconds": compile_seconds,
            "commit": commit(),
            "machines": list(dict.fromkeys(machines)),
        }
        where = self._where(rung)
        where.mkdir(exist_ok=True)
        after = self.scheduler.next_window([*self.scores, scores])
        if after is not None and after.continues is not None:
            leaves = zip(*(share.leaves for share in shares), strict=True)
            kept = list(after.continues)
            save_leaves(where / STATE_FILE, [np.concatenate(leaf)[order][kept] for leaf in leaves])
        write_json(where / SCORES_FILE, scores)
        self._recorded(scores)
        best = ", ".join(
            f"{arm} {found[0]['score']:.1f}"
            if found and found[0]["score"] is not None
            else f"{arm} —"
            for arm, found in ((arm, ranked(v["trials"])) for arm, v in arms.items())
        )
        self._say(f"{self.task}: rung {rung + 1} done in {seconds:.1f} s; best: {best}")

    def _train_part(self, window: Window, part: tuple[int, int]) -> None:
        """Trains `part`'s share of the next rung and records it in ``part-<K>/`` for the join
        (its runs' scores and state), unless it is recorded already."""
        rung, (k, n) = len(self.scores), part
        where = self._where(rung) / f"part-{k}"
        said = f"{self.task}: rung {rung + 1} of {self.scheduler.rounds}, part {k} of {n}"
        self._check_split(rung, n)
        if (where / SCORES_FILE).exists():
            self._say(f"{said}: recorded already (a call without a part joins the rung's parts)")
            return
        share = self._share(window, part)
        if not share.runs:
            groups = len(self.population.groups(window))
            self._say(
                f"{said}: nothing to train, the rung's {len(window.runs)} runs make {groups} "
                f"group{'s' * (groups > 1)}, fewer than the parts (a smaller --chunk makes more)"
            )
            return
        where.mkdir(parents=True, exist_ok=True)
        if share.leaves:
            save_leaves(where / STATE_FILE, share.leaves)
        recorded: ShareScores = {
            "part": [k, n],
            "runs": share.runs,
            "scores": [float(v) if math.isfinite(v) else None for v in self._scored(share)],
            "diverged": share.diverged.tolist(),
            "seconds": share.seconds,
            "compile_seconds": share.compile_seconds,
            "commit": commit(),
            "machine": describe_machine(),
        }
        write_json(where / SCORES_FILE, recorded)  # last: a share with its scores is whole
        self._say(f"{said}: {len(share.runs)} runs recorded in {share.seconds:.1f} s")

    def _check_split(self, rung: int, n: int) -> None:
        """Refuses a share of rung `rung` split into `n` parts where one of another split is
        recorded: its part-<K> would be taken for this one's ("recorded already"), or the join
        refuse the mix once every array task had trained."""
        for path in sorted(self._where(rung).glob(f"part-*/{SCORES_FILE}")):
            k, split = read_share(path)["part"]
            if split != n:
                raise InvalidInput(
                    f"{self.task}: rung {rung + 1} is split into {split} parts, not {n} (part {k} "
                    f"of {split} is recorded in {path.parent}): train its others with --part "
                    f"K/{split} (part=(K, {split})), or remove {path.parent.parent}/part-* to "
                    f"split it into {n}"
                )

    def _read_shares(self, window: Window) -> tuple[list[Trained], list[str]]:
        """The next rung's shares that array tasks recorded, every one that has runs to train,
        each checked to hold its runs (a missing one is refused by name), and the machine each
        trained on (``not recorded`` where its record predates them)."""
        rung = len(self.scores)
        where = self._where(rung)
        found: dict[tuple[int, ...], ShareScores] = {}
        for path in where.glob(f"part-*/{SCORES_FILE}"):
            recorded = read_share(path)
            found[tuple(recorded["part"])] = recorded
        splits = sorted({n for _, n in found})
        if len(splits) > 1:
            raise InvalidInput(
                f"{where} holds shares of splits into {' and '.join(map(str, splits))} parts: "
                "remove those of the split not carried through, then run this again"
            )
        n = splits[0]
        later = self._keeps_state(rung, window)
        shares, machines = [], []
        for k in range(1, n + 1):
            positions = self.population.positions(window, (k, n))
            runs = [window.runs[i] for i in positions]
            if not runs:
                continue  # a share past the rung's groups: nothing to train, nothing recorded
            if (k, n) not in found:
                raise InvalidInput(
                    f"{self.task}: rung {rung + 1} is split into {n} parts and part {k} is "
                    f"missing ({where}/part-{k}): train it with --part {k}/{n} (part=({k}, {n})), "
                    "then run this again"
                )
            share = self._share_read(where / f"part-{k}", found[k, n], runs, later, k, n)
            shares.append(dataclasses.replace(share, positions=positions))
            machines.append(found[k, n].get("machine", NOT_RECORDED))
        self._say(
            f"{self.task}: rung {rung + 1}: joining its parts ({len(shares)} of {n} had runs to "
            "train)"
        )
        return shares, machines

    def _share_read(
        self, where: Path, recorded: ShareScores, runs: list[Any], later: bool, k: int, n: int
    ) -> Trained:
        """Share `k` of `n`, recorded in `where`, checked to hold `runs` (and their state, if
        `later` windows go on from it)."""
        leaves = read_leaves(where / STATE_FILE) if later else []
        if [tuple(run) for run in recorded["runs"]] != runs or any(
            len(leaf) != len(runs) for leaf in leaves
        ):
            raise InvalidInput(
                f"{where} does not hold part {k} of {n} of this rung: remove it and train it "
                f"again with --part {k}/{n}"
            )
        last = [math.nan if v is None else v for v in recorded["scores"]]
        return Trained(
            runs,
            np.asarray(last, float),
            np.asarray(recorded["diverged"], bool),
            leaves,
            recorded["seconds"],
            recorded["compile_seconds"],
        )

    def _scored(self, share: Trained) -> np.ndarray:
        """The tune's score of each of `share`'s runs: its evaluation where the population
        evaluates, else its training return."""
        return share.last if share.evaluated is None else share.evaluated

    def _keeps_state(self, rung: int, window: Window) -> bool:
        """Whether a window may go on from rung `rung`'s state: all but the scheduler's last,
        where its runs have one shape (runs of several shapes are whole)."""
        shapes = {self.population.shape_of(run) for run in window.runs}
        return rung + 1 < self.scheduler.rounds and len(shapes) == 1

    def _share(self, window: Window, part: tuple[int, int]) -> Trained:
        """Trains `part`'s share of `window`, from the state the rung before saved."""
        rung = len(self.scores)
        groups = self.population.groups(window)
        runs = len(self.population.positions(window, part))
        if runs:
            live: dict[str, set[int]] = {}
            for arm, trial, _ in window.runs:
                live.setdefault(arm, set()).add(trial)
            seeds = len({seed for _, _, seed in window.runs})
            split = "" if part == (1, 1) else f", part {part[0]} of {part[1]}"
            grouped = "" if len(groups) == 1 else f" in {len(groups)} groups, {runs} runs here"
            self._say(
                f"{self.task}: rung {rung + 1} of {self.scheduler.rounds}{split}: trials "
                f"{', '.join(f'{len(t)} {arm}' for arm, t in live.items())} × {seeds} seeds = "
                f"{len(window.runs)} runs{grouped}, updates {window.start + 1}–{window.end} of "
                f"{self.population.prepared.config.num_updates}"
                + ("; compiling…" if self.population.compiles(window, part) else "")
            )
        saved = self._where(rung - 1) / STATE_FILE if window.continues is not None else None
        label = f"{self.task}: rung {rung + 1}"
        return self.population.share(window, part, saved, self._keeps_state(rung, window), label)

    def results(self, baseline: str) -> dict[str, ArmResults]:
        """Per arm: the chosen setting, trial 0's and the rungs' scores, the steps used."""
        windows = [self.scheduler.next_window(self.scores[:r]) for r in range(len(self.scores))]
        return {
            arm: arm_results(
                arm,
                baseline,
                self.scores,
                self.population.settings,
                [w for w in windows if w is not None],
                self.population.prepared.config.samples_per_update,
            )
            for arm in self.population.arms
        }


def _positions(share: Trained) -> np.ndarray:
    """Where `share`'s runs are in their window."""
    assert share.positions is not None
    return share.positions
