"""A population trained as one program: runs of several arms, each at its own setting and seed,
vmapped side by side over a window of updates (a round of a tune), from scratch or from the
state an earlier window saved, in groups of one shape (one compiled program) that a SLURM job
array may share out. Every scheduler of a tune trains through it: what trains, to which update
and from which state is the scheduler's; how is this module's.

A run's setting is a traced hyperparameter, so a window of many settings is one program; the
settings of every arm are stacked once over the whole window (never per group), so that each
group computes the same surrogates and a share trains as the window trained whole, bit for bit.
"""

from __future__ import annotations

import dataclasses
import io
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, cast

import jax
import numpy as np

from fppo_jax.core.config import Hyperparameters, stack_hyperparameters, with_budget
from fppo_jax.core.policy import make_policy
from fppo_jax.core.resolution import resolve_hyperparameters
from fppo_jax.core.surrogates import Surrogate
from fppo_jax.core.trainer import TrainState
from fppo_jax.envs import resets_itself
from fppo_jax.errors import InvalidInput, MissingFile
from fppo_jax.run.evaluation import evaluation_key, make_evaluator
from fppo_jax.run.execution import Program, compile_program, run_keys
from fppo_jax.run.memory import check_host_memory
from fppo_jax.run.plan import share_bounds
from fppo_jax.run.prepare import Prepared
from fppo_jax.run.stop_signals import stop_if_signalled
from fppo_jax.store.files import write_atomically

# A run of a population: its arm (a variant's name), its trial (the setting's number) and seed.
Run = tuple[str, int, int]


CALLS_A_WINDOW = 10  # progress lines a window gives, at most


@dataclasses.dataclass(frozen=True)
class Window:
    """What a population trains at once: its `runs` in order, from update `start` to `end`;
    with `start` > 0, run i goes on from the state in which run ``continues[i]`` of the window
    before ended (its own run's, or another's: a copy, at a setting of its own)."""

    runs: tuple[Run, ...]
    start: int
    end: int
    continues: tuple[int, ...] | None = None

    def __post_init__(self) -> None:
        if (self.start > 0) != (self.continues is not None):
            raise InvalidInput("a window after update 0 goes on from saved state, and only it")
        if self.continues is not None and len(self.continues) != len(self.runs):
            raise InvalidInput("a window goes on from one saved state for each of its runs")


@dataclasses.dataclass
class Trained:
    """What a share of a window trained: its `runs` (in the window's order), each run's score at
    the window's end (the training return, mean of its last episodes; NaN where no episode
    finished) and whether it diverged, the leaves of its state (:func:`save_leaves`; none
    where no window goes on from it), the seconds it trained and compiled, and where the
    population evaluates, each run's deterministic policy's mean return at the window's end
    (`evaluated`)."""

    runs: list[Run]
    last: np.ndarray
    diverged: np.ndarray
    leaves: list[np.ndarray]
    seconds: float
    compile_seconds: float
    evaluated: np.ndarray | None = None


class Population:
    """The arms' settings (`settings`: per arm, each trial's) on `prepared`'s task, trained a
    window at a time in groups of `chunk` runs (all of a window's runs if None), each compiled
    call `updates_per_call` updates; with `eval_episodes`, each run's deterministic policy is
    evaluated over that many episodes at the window's end (the episodes of
    :func:`~fppo_jax.run.evaluation.evaluation_key`, as a study's evaluations); `say` takes
    progress lines."""

    def __init__(
        self,
        prepared: Prepared,
        arms: Sequence[Surrogate],
        settings: dict[str, list[dict[str, float]]],
        updates_per_call: int,
        chunk: int | None,
        say: Callable[[str], None],
        eval_episodes: int | None = None,
    ):
        self.prepared, self.arms, self.settings = prepared, {a.name: a for a in arms}, settings
        self.updates_per_call, self.chunk, self.say = updates_per_call, chunk, say
        self.eval_episodes = eval_episodes
        self._evaluator: Callable[..., Any] | None = None

    def groups(self, runs: int) -> tuple[int, int]:
        """The size and the count of the groups that a window of `runs` runs trains in: `chunk`
        runs each (all of them if it has fewer), as the window trained whole and its shares
        alike."""
        size = min(self.chunk or runs, runs)
        return size, -(-runs // size)

    def share(
        self, window: Window, part: tuple[int, int], saved: Path | None, keep: bool, label: str
    ) -> Trained:
        """Trains `part`'s share of `window`: whole groups of its runs (the last one filled up
        with the window's last run), each a call of one program, from the states in `saved`
        (one per run of the window, in its order) where it goes on from the window before;
        `keep`: the state is returned for a later window."""
        size, groups = self.groups(len(window.runs))
        first, stop = share_bounds(part, groups)
        runs = list(window.runs[first * size : stop * size])
        if not runs:
            return Trained([], np.zeros(0), np.zeros(0, bool), [], 0.0, 0.0)
        check_host_memory(self.prepared.trainer, size)
        hps = self._hyperparameters(window.runs)
        began, program = time.perf_counter(), None
        lasts, diverged, leaves, evaluated = [], [], [], []
        for group in range(first, stop):
            # Every group has one shape, so one program: the window's last run fills up its last.
            index = np.minimum(np.arange(group * size, (group + 1) * size), len(window.runs) - 1)
            keys = run_keys([window.runs[i][2] for i in index])
            group_hps = _rows(hps, index)
            if program is None:
                program = compile_program(
                    self.prepared.trainer, keys, group_hps, jax.vmap, self.updates_per_call
                )
                how = "loaded from the compilation cache" if program.loaded else "compiled"
                self.say(f"{label} {how} in {program.compile_seconds:.1f} s")
            said = label + (f", group {group + 1} of {groups}" if groups > 1 else "")
            state = self._start(program, window, keys, group_hps, index, saved)
            state, last = self._train(program, state, group_hps, window, len(index), said)
            kept = slice(0, len(window.runs) - group * size)  # the group's own runs, not the fill
            lasts.append(last[kept])
            diverged.append(fetch_diverged(state)[kept])
            if self.eval_episodes:
                evaluated.append(self._evaluate(state)[kept])
            if keep:
                leaves.append([_plain(leaf)[kept] for leaf in jax.tree.leaves(state)])
        assert program is not None
        return Trained(
            runs,
            np.concatenate(lasts),
            np.concatenate(diverged),
            [np.concatenate(leaf) for leaf in zip(*leaves, strict=True)],
            time.perf_counter() - began - program.compile_seconds,
            program.compile_seconds,
            np.concatenate(evaluated) if evaluated else None,
        )

    def _evaluate(self, state: TrainState) -> np.ndarray:
        """Each run's deterministic policy's mean return over the population's evaluation
        episodes, every run on the same episodes' keys (its own environments)."""
        assert self.eval_episodes is not None
        if self._evaluator is None:
            evaluator = make_evaluator(self.prepared.trainer.env, self.eval_episodes)
            self._evaluator = jax.jit(jax.vmap(evaluator))
        policy = make_policy(self.prepared.trainer, state)
        runs = state.nonfinite_update.shape[0]
        key = evaluation_key()
        keys = jax.numpy.broadcast_to(key, (runs, *key.shape))
        returns = np.asarray(self._evaluator(policy, keys), dtype=float)
        return cast(np.ndarray, returns.mean(axis=-1))

    def _hyperparameters(self, runs: Sequence[Run]) -> Hyperparameters:
        """The stacked hyperparameters of `runs` (arm, trial, seed), over every arm's
        surrogates."""
        return stack_hyperparameters(
            [
                resolve_hyperparameters(self.arms[arm], None, **self.settings[arm][trial])[0]
                for arm, trial, _ in runs
            ]
        )

    def _start(
        self,
        program: Program,
        window: Window,
        keys: jax.Array,
        hps: Hyperparameters,
        index: np.ndarray,
        saved: Path | None,
    ) -> TrainState:
        """The group's state at the window's start: drawn afresh, or the saved states its runs
        go on from."""
        if window.continues is None:
            return program.init(keys, hps)
        assert saved is not None
        trainer = self.prepared.trainer
        like = jax.eval_shape(jax.vmap(trainer.init), keys, hps)
        state = load_state(saved, like, index, len(window.runs))
        if resets_itself(trainer.env):  # their state lived outside JAX, in another batch
            state = jax.jit(jax.vmap(trainer.restart_envs))(state)
        return state

    def _train(
        self,
        program: Program,
        state: TrainState,
        hps: Hyperparameters,
        window: Window,
        runs: int,
        said: str,
    ) -> tuple[TrainState, np.ndarray]:
        """`state` trained by `program` through the window: the state and each run's score
        (`said` names the runs in progress lines)."""
        trainer = self.prepared.trainer
        budgeted = with_budget(hps, trainer.config.num_updates)
        last = np.full(runs, np.nan)
        calls = -(-(window.end - window.start) // self.updates_per_call)
        began = time.perf_counter()
        for call in range(calls):
            # A stop signal's safe point: after the call in flight (or once compiled), with
            # nothing of the call after it dispatched.
            stop_if_signalled(said)
            state, metrics = program.run(state, budgeted)
            returns, steps = jax.device_get((metrics.average_return, metrics.env_steps))
            ran = steps[0] >= 0
            if ran.any():
                last = returns[:, ran][:, -1]
            if (call + 1) % -(-calls // CALLS_A_WINDOW) == 0 and call + 1 < calls:
                done = min(window.start + (call + 1) * self.updates_per_call, window.end)
                rate = (done - window.start) * trainer.config.samples_per_update * runs
                self.say(
                    f"{said}: update {done} of {window.end}, "
                    f"{rate / (time.perf_counter() - began):,.0f} env steps/s"
                )
        return state, last


def _rows(hps: Hyperparameters, index: np.ndarray) -> Hyperparameters:
    """The hyperparameters of runs `index` of a stacked batch."""
    return cast(Hyperparameters, jax.tree.map(lambda x: x[index], hps))


def fetch_diverged(state: TrainState) -> np.ndarray:
    """Whether each run's loss or parameters stopped being finite."""
    return np.asarray(jax.device_get(state.nonfinite_update)) >= 0


def save_leaves(path: Path, leaves: list[np.ndarray]) -> None:
    """A state's leaves (keys as their data), atomically, in order."""
    path.parent.mkdir(parents=True, exist_ok=True)
    buffer = io.BytesIO()
    np.savez(buffer, *leaves)
    write_atomically(path, buffer.getvalue())


def read_leaves(path: Path) -> list[np.ndarray]:
    """The leaves that :func:`save_leaves` wrote in `path`."""
    if not path.exists():
        raise MissingFile(f"{path} is missing: remove its rung (or part) to train it again")
    try:
        with np.load(path) as saved:
            return [saved[f"arr_{i}"] for i in range(len(saved.files))]
    except Exception as error:  # a damaged or foreign file: NumPy's and zipfile's errors
        raise InvalidInput(
            f"cannot read {path}: {error}; remove its rung to train it again"
        ) from None


def load_state(path: Path, like: Any, index: np.ndarray, runs: int) -> TrainState:
    """Runs `index` of the `runs` runs whose state `path` holds, checked against `like`
    (theirs), on the device."""
    leaves, treedef = jax.tree.flatten(like)
    arrays = read_leaves(path)
    restored = []
    for saved, leaf in zip(arrays, leaves, strict=False):
        if len(saved) != runs:
            break
        array: Any = saved[index]
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
