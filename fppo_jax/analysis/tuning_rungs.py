"""A tune's rungs: the successive-halving schedule (:func:`schedule`), and each task's
population trained rung by rung (:class:`TaskTune`), each rung one compiled program over every
arm's live trials × the tuning seeds (or a share of it, for an array task), its scores ranked
and recorded, told to Optuna, and its survivors' state saved for the next rung."""

from __future__ import annotations

import dataclasses
import io
import math
import sys
import time
from pathlib import Path
from typing import Any, cast

import jax
import numpy as np

from fppo_jax.analysis.halving import CALLS_A_RUNG, Rungs, ranked
from fppo_jax.analysis.tune_files import (
    SCORES_FILE,
    STATE_FILE,
    read_rung,
    read_share,
    rung_directory,
)
from fppo_jax.analysis.tuning_draws import setting_of
from fppo_jax.analysis.tuning_records import (
    ArmResults,
    ArmRung,
    RungScores,
    ShareScores,
    TrialScore,
)
from fppo_jax.analysis.tuning_report import arm_results
from fppo_jax.core.config import stack_hyperparameters, with_budget
from fppo_jax.core.resolution import resolve_hyperparameters
from fppo_jax.core.surrogates import Surrogate
from fppo_jax.core.trainer import TrainState
from fppo_jax.envs import resets_itself
from fppo_jax.errors import InvalidInput, MissingFile
from fppo_jax.run.execution import compile_program, run_keys
from fppo_jax.run.memory import check_host_memory
from fppo_jax.run.plan import share_bounds
from fppo_jax.run.prepare import Prepared
from fppo_jax.store.files import write_atomically, write_json


@dataclasses.dataclass
class _Share:
    """What a share of a rung trained: its `runs` (arm, trial, seed, in the rung's order), each
    run's score at the rung's end (NaN where no episode finished) and whether it diverged, the
    leaves of its state (as :func:`_save_leaves` writes them; none at the last rung, which no
    rung goes on from), and the seconds it trained and compiled."""

    runs: list[tuple[str, int, int]]
    last: np.ndarray
    diverged: np.ndarray
    leaves: list[np.ndarray]
    seconds: float
    compile_seconds: float


class TaskTune:
    """One task's population, rung by rung."""

    def __init__(
        self,
        task: str,
        prepared: Prepared,
        arms: list[Surrogate],
        population: dict[str, list[dict[str, float]]],
        rungs: Rungs,
        seeds: list[int],
        chunk: int | None,
        directory: Path,
        optuna: Any,
        storage: Any,
        progress: bool,
    ):
        self.task, self.prepared, self.arms = task, prepared, arms
        self.rungs, self.seeds, self.chunk = rungs, seeds, chunk
        self.settings = {arm: [setting_of(p) for p in params] for arm, params in population.items()}
        self.directory, self.optuna, self.storage, self.progress = (
            directory,
            optuna,
            storage,
            progress,
        )
        self.live = {arm.name: list(range(len(self.settings[arm.name]))) for arm in arms}
        self.scores: list[RungScores] = []  # each recorded rung's

    @property
    def finished(self) -> bool:
        return len(self.scores) == len(self.rungs.trials)

    def read(self, join: bool) -> None:
        """Takes the rungs recorded, and where `join`, the rungs whose shares array tasks
        recorded, joined (a rung with some of its shares missing is refused)."""
        self.directory.mkdir(exist_ok=True)
        while not self.finished:
            where = self._where(len(self.scores))
            if (where / SCORES_FILE).exists():
                self._recorded(read_rung(where / SCORES_FILE))
            elif join and any(where.glob(f"part-*/{SCORES_FILE}")):
                self._record(self._read_shares())
            else:
                return

    def train(self, allowed: float, part: tuple[int, int] | None) -> int:
        """Trains up to `allowed` rungs after those read, each as its one share; with `part`,
        that share of the next rung alone, recorded for the join. Returns how many rungs it
        trained (or trained a share of)."""
        if part is not None:
            if self.finished or allowed < 1:
                return 0
            self._train_part(part)
            return 1
        trained = 0
        while not self.finished and trained < allowed:
            self._record([self._share((1, 1))])
            trained += 1
        return trained

    def _where(self, rung: int) -> Path:
        return rung_directory(self.directory, rung)

    def _order(self) -> list[tuple[str, int, int]]:
        """The next rung's runs: each arm's live trials × the seeds, in that order."""
        return [
            (arm, t, seed)
            for arm, trials in self.live.items()
            for t in trials
            for seed in self.seeds
        ]

    def _groups(self, runs: int) -> tuple[int, int]:
        """The size and the count of the groups that a rung of `runs` runs trains in: `chunk`
        runs each (all of them if it has fewer), as the unsplit tune and its shares alike."""
        size = min(self.chunk or runs, runs)
        return size, -(-runs // size)

    def _recorded(self, scores: RungScores) -> None:
        """A rung's scores: told to Optuna (again, if a kill came between), and its survivors
        made the live trials."""
        rung = len(self.scores)
        self.scores.append(scores)
        last = rung == len(self.rungs.trials) - 1
        for arm in self.live:
            study = self.optuna.load_study(study_name=f"{self.task}/{arm}", storage=self.storage)
            by_number = {t.number: t for t in study.get_trials(deepcopy=False)}
            arms = scores["arms"]
            for trial, score in zip(self.live[arm], arms[arm]["trials"], strict=True):
                frozen = by_number[trial]
                step = self.rungs.ends[rung]
                if frozen.state.is_finished():
                    continue
                value = math.nan if score["score"] is None else score["score"]
                if step not in frozen.intermediate_values:
                    self.optuna.trial.Trial(study, frozen._trial_id).report(value, step)
                states = self.optuna.trial.TrialState
                if score["diverged"]:
                    study.tell(trial, state=states.FAIL)
                elif last and score["score"] is None:
                    study.tell(trial, state=states.FAIL)  # no episode finished: no score
                elif last and trial in arms[arm]["survivors"]:
                    study.tell(trial, value)
                elif trial not in arms[arm]["survivors"]:
                    study.tell(trial, state=states.PRUNED)
            self.live[arm] = list(arms[arm]["survivors"])

    def _record(self, shares: list[_Share]) -> None:
        """Records the next rung from its `shares`, in order: its scores, ranked, and the state
        its survivors go on from; then tells Optuna (the join alone writes to it)."""
        rung, order = len(self.scores), self._order()
        assert [run for share in shares for run in share.runs] == order
        last = np.concatenate([share.last for share in shares])
        diverged = np.concatenate([share.diverged for share in shares])
        arms = self._scores(order, last, diverged, rung)
        where = self._where(rung)
        where.mkdir(exist_ok=True)
        if rung + 1 < len(self.rungs.trials):
            keep = [i for i, (arm, t, _) in enumerate(order) if t in arms[arm]["survivors"]]
            leaves = zip(*(share.leaves for share in shares), strict=True)
            _save_leaves(where / STATE_FILE, [np.concatenate(leaf)[keep] for leaf in leaves])
        seconds = sum(share.seconds for share in shares)
        compile_seconds = sum(share.compile_seconds for share in shares)
        scores: RungScores = {"arms": arms, "seconds": seconds, "compile_seconds": compile_seconds}
        write_json(where / SCORES_FILE, scores)
        self._recorded(scores)
        best = ", ".join(
            f"{arm} {found[0]['score']:.1f}"
            if found and found[0]["score"] is not None
            else f"{arm} —"
            for arm, found in ((arm, ranked(v["trials"])) for arm, v in arms.items())
        )
        self._say(f"{self.task}: rung {rung + 1} done in {seconds:.1f} s; best: {best}")

    def _train_part(self, part: tuple[int, int]) -> None:
        """Trains `part`'s share of the next rung and records it in ``part-<K>/`` for the join
        (its runs' scores and state), unless it is recorded already."""
        rung, (k, n) = len(self.scores), part
        where = self._where(rung) / f"part-{k}"
        said = f"{self.task}: rung {rung + 1} of {len(self.rungs.trials)}, part {k} of {n}"
        if (where / SCORES_FILE).exists():
            self._say(f"{said}: recorded already (a call without a part joins the rung's parts)")
            return
        share = self._share(part)
        if not share.runs:
            runs = len(self._order())
            size, groups = self._groups(runs)
            self._say(
                f"{said}: nothing to train, the rung's {runs} runs make {groups} group"
                f"{'s' * (groups > 1)} of {size}, fewer than the parts"
            )
            return
        where.mkdir(parents=True, exist_ok=True)
        if share.leaves:
            _save_leaves(where / STATE_FILE, share.leaves)
        recorded: ShareScores = {
            "part": [k, n],
            "runs": share.runs,
            "scores": [float(v) if math.isfinite(v) else None for v in share.last],
            "diverged": share.diverged.tolist(),
            "seconds": share.seconds,
            "compile_seconds": share.compile_seconds,
        }
        write_json(where / SCORES_FILE, recorded)  # last: a share with its scores is whole
        self._say(f"{said}: {len(share.runs)} runs recorded in {share.seconds:.1f} s")

    def _read_shares(self) -> list[_Share]:
        """The next rung's shares that array tasks recorded, every one that has runs to train,
        each checked to hold its runs; a missing one is refused by name."""
        rung, order = len(self.scores), self._order()
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
        size, groups = self._groups(len(order))
        shares = []
        for k in range(1, n + 1):
            first, stop = share_bounds((k, n), groups)
            runs = order[first * size : stop * size]
            if not runs:
                continue  # a share past the rung's groups: nothing to train, nothing recorded
            if (k, n) not in found:
                raise InvalidInput(
                    f"{self.task}: rung {rung + 1} is split into {n} parts and part {k} is "
                    f"missing ({where}/part-{k}): train it with --part {k}/{n} (part=({k}, {n})), "
                    "then run this again"
                )
            recorded = found[k, n]
            later = rung + 1 < len(self.rungs.trials)
            leaves = _read_leaves(where / f"part-{k}" / STATE_FILE) if later else []
            if [tuple(run) for run in recorded["runs"]] != runs or any(
                len(leaf) != len(runs) for leaf in leaves
            ):
                raise InvalidInput(
                    f"{where}/part-{k} does not hold part {k} of {n} of this rung: remove it and "
                    f"train it again with --part {k}/{n}"
                )
            last = [math.nan if v is None else v for v in recorded["scores"]]
            shares.append(
                _Share(
                    runs,
                    np.asarray(last, float),
                    np.asarray(recorded["diverged"], bool),
                    leaves,
                    recorded["seconds"],
                    recorded["compile_seconds"],
                )
            )
        self._say(
            f"{self.task}: rung {rung + 1}: joining its parts ({len(shares)} of {n} had runs to "
            "train)"
        )
        return shares

    def _share(self, part: tuple[int, int]) -> _Share:
        """Trains `part`'s share of the next rung: whole groups of the rung's runs (:meth:`_groups`;
        the last one filled up with the rung's last run), each a call of one program."""
        rung, order = len(self.scores), self._order()
        size, groups = self._groups(len(order))
        first, stop = share_bounds(part, groups)
        runs = order[first * size : stop * size]
        if not runs:
            return _Share([], np.zeros(0), np.zeros(0, bool), [], 0.0, 0.0)
        rungs, trainer = self.rungs, self.prepared.trainer
        start = 0 if rung == 0 else rungs.ends[rung - 1]
        live = ", ".join(f"{len(t)} {arm}" for arm, t in self.live.items())
        split = "" if part == (1, 1) else f", part {part[0]} of {part[1]}"
        grouped = "" if groups == 1 else f" in groups of {size}, {len(runs)} of them here"
        self._say(
            f"{self.task}: rung {rung + 1} of {len(rungs.trials)}{split}: trials {live} × "
            f"{len(self.seeds)} seeds = {len(order)} runs{grouped}, updates {start + 1}–"
            f"{rungs.ends[rung]} of {trainer.config.num_updates}; compiling…"
        )
        check_host_memory(trainer, size)
        began, program = time.perf_counter(), None
        lasts, diverged, leaves = [], [], []
        for group in range(first, stop):
            # Every group has one shape, so one program: the rung's last run fills up its last.
            index = np.minimum(np.arange(group * size, (group + 1) * size), len(order) - 1)
            keys, hps = self._inputs([order[i] for i in index])
            if program is None:
                program = compile_program(trainer, keys, hps, jax.vmap, rungs.updates_per_call)
                self._say(
                    f"{self.task}: rung {rung + 1} compiled in {program.compile_seconds:.1f} s"
                )
            said = f"{self.task}: rung {rung + 1}" + (
                f", group {group + 1} of {groups}" if groups > 1 else ""
            )
            state, last = self._train(program, keys, hps, index, len(order), rung, said)
            kept = slice(0, len(order) - group * size)  # the group's own runs, not the fill
            lasts.append(last[kept])
            diverged.append(fetch_diverged(state)[kept])
            if rung + 1 < len(rungs.trials):  # the last rung's state goes on nowhere
                leaves.append([_plain(leaf)[kept] for leaf in jax.tree.leaves(state)])
        assert program is not None
        return _Share(
            runs,
            np.concatenate(lasts),
            np.concatenate(diverged),
            [np.concatenate(leaf) for leaf in zip(*leaves, strict=True)],
            time.perf_counter() - began - program.compile_seconds,
            program.compile_seconds,
        )

    def _inputs(self, runs: list[tuple[str, int, int]]) -> tuple[jax.Array, Any]:
        """The keys and the stacked hyperparameters of `runs` (arm, trial, seed)."""
        surrogates = {arm.name: arm for arm in self.arms}
        hps = stack_hyperparameters(
            [
                resolve_hyperparameters(surrogates[arm], None, **self.settings[arm][trial])[0]
                for arm, trial, _ in runs
            ]
        )
        return run_keys([seed for _, _, seed in runs]), hps

    def _train(
        self,
        program: Any,
        keys: jax.Array,
        hps: Any,
        index: np.ndarray,
        runs: int,
        rung: int,
        said: str,
    ) -> tuple[TrainState, np.ndarray]:
        """The runs `index` of the rung's `runs` (their `keys` and `hps`) trained by `program`
        through `rung`, from the recorded state of the rung before: their state and each
        run's score (`said` names them in progress lines)."""
        rungs, trainer = self.rungs, self.prepared.trainer
        start = 0 if rung == 0 else rungs.ends[rung - 1]
        if rung == 0:
            state = program.init(keys, hps)
        else:
            like = jax.eval_shape(jax.vmap(trainer.init), keys, hps)
            state = _load_state(self._where(rung - 1) / STATE_FILE, like, index, runs)
            if resets_itself(trainer.env):  # their state lived outside JAX, in another batch
                state = jax.jit(jax.vmap(trainer.restart_envs))(state)
        budgeted = with_budget(hps, trainer.config.num_updates)
        last = np.full(len(index), np.nan)
        calls = -(-(rungs.ends[rung] - start) // rungs.updates_per_call)
        began = time.perf_counter()
        for call in range(calls):
            state, metrics = program.run(state, budgeted)
            returns, steps = jax.device_get((metrics.average_return, metrics.env_steps))
            ran = steps[0] >= 0
            if ran.any():
                last = returns[:, ran][:, -1]
            if (call + 1) % -(-calls // CALLS_A_RUNG) == 0 and call + 1 < calls:
                done = min(start + (call + 1) * rungs.updates_per_call, rungs.ends[rung])
                rate = (done - start) * trainer.config.samples_per_update * len(index)
                self._say(
                    f"{said}: update {done} of {rungs.ends[rung]}, "
                    f"{rate / (time.perf_counter() - began):,.0f} env steps/s"
                )
        return state, last

    def _scores(
        self,
        order: list[tuple[str, int, int]],
        last: np.ndarray | None,
        diverged: np.ndarray,
        rung: int,
    ) -> dict[str, ArmRung]:
        """Each arm's live trials' scores at the end of `rung`, and those that go on."""
        scores: dict[str, ArmRung] = {}
        going_on = self.rungs.trials[min(rung + 1, len(self.rungs.trials) - 1)]
        for arm, trials in self.live.items():
            rows: list[TrialScore] = []
            for trial in trials:
                runs = [i for i, (a, t, _) in enumerate(order) if a == arm and t == trial]
                values = np.asarray(last)[runs].astype(float)
                bad = bool(diverged[runs].any())
                mean = float(np.mean(values))
                rows.append(
                    {
                        "trial": trial,
                        "score": mean if math.isfinite(mean) else None,
                        "seed_scores": [float(v) if math.isfinite(v) else None for v in values],
                        "diverged": bad,
                    }
                )
            scores[arm] = {
                "trials": rows,
                "survivors": sorted(r["trial"] for r in ranked(rows)[:going_on]),
            }
        return scores

    def results(self, baseline: str) -> dict[str, ArmResults]:
        """Per arm: the chosen setting, trial 0's and the rungs' scores, the steps used."""
        return {
            arm.name: arm_results(
                arm.name,
                baseline,
                self.scores,
                self.settings,
                self.rungs,
                len(self.seeds),
                self.prepared.config.samples_per_update,
            )
            for arm in self.arms
        }

    def _say(self, line: str) -> None:
        if self.progress:
            print(line, file=sys.stderr, flush=True)


def fetch_diverged(state: TrainState) -> np.ndarray:
    """Whether each run's loss or parameters stopped being finite."""
    return np.asarray(jax.device_get(state.nonfinite_update)) >= 0


def _save_leaves(path: Path, leaves: list[np.ndarray]) -> None:
    """A state's leaves (:func:`_plain`: keys as their data), atomically, in order."""
    path.parent.mkdir(parents=True, exist_ok=True)
    buffer = io.BytesIO()
    np.savez(buffer, *leaves)
    write_atomically(path, buffer.getvalue())


def _read_leaves(path: Path) -> list[np.ndarray]:
    """The leaves that :func:`_save_leaves` wrote in `path`."""
    if not path.exists():
        raise MissingFile(f"{path} is missing: remove its rung (or part) to train it again")
    try:
        with np.load(path) as saved:
            return [saved[f"arr_{i}"] for i in range(len(saved.files))]
    except Exception as error:  # a damaged or foreign file: NumPy's and zipfile's errors
        raise InvalidInput(
            f"cannot read {path}: {error}; remove its rung to train it again"
        ) from None


def _load_state(path: Path, like: Any, index: np.ndarray, runs: int) -> TrainState:
    """Runs `index` of the `runs` runs whose state `path` holds, checked against `like`
    (theirs), on the device."""
    leaves, treedef = jax.tree.flatten(like)
    arrays = _read_leaves(path)
    restored = []
    for saved, leaf in zip(arrays, leaves, strict=False):
        array: Any = saved[index] if len(saved) == runs else saved  # the check below refuses it
        if jax.numpy.issubdtype(leaf.dtype, jax.dtypes.prng_key):
            array = jax.random.wrap_key_data(array)
        if array.shape != leaf.shape:
            break
        restored.append(array)
    if len(arrays) != len(leaves) or len(restored) != len(leaves):
        raise InvalidInput(f"{path} does not hold this tune's state; remove its rung")
    return cast(TrainState, jax.device_put(jax.tree.unflatten(treedef, restored)))


def _plain(leaf: Any) -> np.ndarray:
    if jax.numpy.issubdtype(leaf.dtype, jax.dtypes.prng_key):
        leaf = jax.random.key_data(leaf)
    return np.asarray(jax.device_get(leaf))
