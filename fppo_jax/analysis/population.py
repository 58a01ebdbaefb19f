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
from fppo_jax.core.shape_space import ChoiceValue, split_setting
from fppo_jax.core.surrogates import Surrogate
from fppo_jax.core.trainer import Trainer, TrainState
from fppo_jax.envs import resets_itself
from fppo_jax.errors import InvalidInput, MissingFile
from fppo_jax.run.evaluation import evaluation_key, make_evaluator
from fppo_jax.run.execution import Program, compile_program, run_keys, updates_per_call
from fppo_jax.run.memory import check_host_memory
from fppo_jax.run.plan import share_bounds
from fppo_jax.run.prepare import Prepared
from fppo_jax.run.stop_signals import stop_if_signalled
from fppo_jax.store.files import write_atomically

# A run of a population: its arm (a variant's name), its trial (the setting's number) and seed.
Run = tuple[str, int, int]
# A run's shape as a key: its setting's run-shape values by name, sorted (empty: the task's own).
Shape = tuple[tuple[str, ChoiceValue], ...]


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
    positions: np.ndarray | None = None  # where each run is in the window


@dataclasses.dataclass
class _Group:
    """What one group of a share trained: its own runs' `positions` in the window (the fill
    left out), and theirs of :class:`Trained`'s fields."""

    positions: np.ndarray
    last: np.ndarray
    diverged: np.ndarray
    leaves: list[np.ndarray]
    evaluated: np.ndarray | None


class Population:
    """The arms' settings (`settings`: per arm, each trial's) on `prepared`'s task, trained a
    window at a time in groups of `chunk` runs (all of a window's runs if None), each compiled
    call `updates_per_call` updates; with `eval_episodes`, each run's deterministic policy is
    evaluated over that many episodes at the window's end (the episodes of
    :func:`~fppo_jax.run.evaluation.evaluation_key`, as a study's evaluations); `say` takes
    progress lines. A setting with run-shape values (:mod:`fppo_jax.core.shape_space`) trains
    on the task as `shaped` prepares it for them, in groups of its shape alone, whole runs."""

    def __init__(
        self,
        prepared: Prepared,
        arms: Sequence[Surrogate],
        settings: dict[str, list[dict[str, Any]]],
        updates_per_call: int,
        chunk: int | None,
        say: Callable[[str], None],
        eval_episodes: int | None = None,
        shaped: Callable[[Shape], Prepared] | None = None,
    ):
        self.prepared, self.arms, self.settings = prepared, {a.name: a for a in arms}, settings
        self.updates_per_call, self.chunk, self.say = updates_per_call, chunk, say
        self.eval_episodes, self._shaped = eval_episodes, shaped
        self._prepared: dict[Shape, Prepared] = {(): prepared}
        # Each program's evaluator, compiled with it (by the program's key).
        self._evaluators: dict[tuple[Shape, int], Callable[..., Any]] = {}
        # Every window's groups of one shape and size train by one program, compiled once
        # for the whole population.
        self._programs: dict[tuple[Shape, int], Program] = {}
        self._states: dict[tuple[int, int, Any], Any] = {}  # see _state_shapes

    def shape_of(self, run: Run) -> Shape:
        """The run-shape values of `run`'s setting, as a key (empty: the task's own shape)."""
        arm, trial, _ = run
        return tuple(sorted(split_setting(self.settings[arm][trial])[1].items()))

    def groups(self, window: Window) -> list[np.ndarray]:
        """The groups that `window` trains in, as the window trained whole and its shares
        alike: each the window's indices of its runs, `chunk` of one shape each (all of them
        if it has fewer), shapes in the order the window first names them, the last group of a
        shape filled up with its last run (one program, one batch size)."""
        by_shape: dict[Shape, list[int]] = {}
        for index, run in enumerate(window.runs):
            by_shape.setdefault(self.shape_of(run), []).append(index)
        groups = []
        for indices in by_shape.values():
            size = min(self.chunk or len(indices), len(indices))
            for first in range(0, len(indices), size):
                members = indices[first : first + size]
                groups.append(np.asarray(members + [members[-1]] * (size - len(members))))
        return groups

    def positions(self, window: Window, part: tuple[int, int]) -> np.ndarray:
        """Where the runs of `part`'s share of `window` are in the window, in the share's
        order (:meth:`share`'s)."""
        groups = self.groups(window)
        first, stop = share_bounds(part, len(groups))
        own = [i for group in groups[first:stop] for i in dict.fromkeys(group.tolist())]
        return np.asarray(own, dtype=int)

    def compiles(self, window: Window, part: tuple[int, int]) -> bool:
        """Whether `part`'s share of `window` needs a program not compiled yet."""
        groups = self.groups(window)
        first, stop = share_bounds(part, len(groups))
        return any(
            self._program_key(window, groups[n]) not in self._programs for n in range(first, stop)
        )

    def _program_key(self, window: Window, index: np.ndarray) -> tuple[Shape, int]:
        return self.shape_of(window.runs[index[0]]), len(index)

    def prepared_for(self, shape: Shape) -> Prepared:
        """The task prepared for run-shape values `shape`."""
        if shape not in self._prepared:
            if self._shaped is None:
                raise InvalidInput("this population trains the task's own run shape alone")
            self._prepared[shape] = self._shaped(shape)
        return self._prepared[shape]

    def share(
        self, window: Window, part: tuple[int, int], saved: Path | None, keep: bool, label: str
    ) -> Trained:
        """Trains `part`'s share of `window`: whole groups of its runs (:meth:`groups`), each a
        call of one program, from the states in `saved` (one per run of the window, in its
        order) where it goes on from the window before; `keep`: the state is returned for a
        later window. Its runs are in the groups' order (`Trained.positions`: where each is in
        the window)."""
        groups = self.groups(window)
        first, stop = share_bounds(part, len(groups))
        if first == stop:
            return Trained([], np.zeros(0), np.zeros(0, bool), [], 0.0, 0.0, None, np.zeros(0, int))
        hps = self._hyperparameters(window.runs)
        began, compiled = time.perf_counter(), 0.0
        trained: list[_Group] = []
        for number in range(first, stop):
            index = groups[number]
            key = self._program_key(window, index)
            if key not in self._programs:
                program = self._compile(key[0], window, index, hps)
                seconds = program.compile_seconds + self._compile_evaluator(
                    key, program, _rows(hps, index)
                )
                self._programs[key] = program
                compiled += seconds
                how = "loaded from the compilation cache" if program.loaded else "compiled"
                self.say(f"{label} {how} in {seconds:.1f} s")
            said = label + (f", group {number + 1} of {len(groups)}" if len(groups) > 1 else "")
            trained.append(self._group(key, window, index, hps, saved, keep, said))
        return Trained(
            [window.runs[i] for group in trained for i in group.positions],
            np.concatenate([group.last for group in trained]),
            np.concatenate([group.diverged for group in trained]),
            [np.concatenate(leaf) for leaf in zip(*(g.leaves for g in trained), strict=True)],
            time.perf_counter() - began - compiled,
            compiled,
            None if self.eval_episodes is None else np.concatenate([g.evaluated for g in trained]),
            np.concatenate([group.positions for group in trained]),
        )

    def _compile(
        self, shape: Shape, window: Window, index: np.ndarray, hps: Hyperparameters
    ) -> Program:
        """The program of a group of `index`'s runs of run shape `shape`, through `window`."""
        prepared = self.prepared_for(shape)
        check_host_memory(prepared.trainer, len(index))
        per_call = self._span(window, prepared)[2]
        keys = run_keys([window.runs[i][2] for i in index])
        return compile_program(prepared.trainer, keys, _rows(hps, index), jax.vmap, per_call)

    def _compile_evaluator(
        self, key: tuple[Shape, int], program: Program, hps: Hyperparameters
    ) -> float:
        """Where the population evaluates, the evaluator of `program`'s runs (at `hps`, a
        group's) compiled or loaded from the cache beside it, so that no group waits on it:
        its seconds."""
        if self.eval_episodes is None:
            return 0.0
        began = time.perf_counter()
        trainer = program.trainer
        state = self._state_shapes(trainer, run_keys([0] * program.runs), hps)
        evaluate = jax.jit(jax.vmap(make_evaluator(trainer.env, self.eval_episodes)))
        policy = make_policy(trainer, state)
        self._evaluators[key] = evaluate.lower(policy, _evaluation_keys(program.runs)).compile()
        return time.perf_counter() - began

    def _state_shapes(self, trainer: Trainer, keys: jax.Array, hps: Hyperparameters) -> Any:
        """The shapes of a group's state (traced once per trainer, size and hyperparameters'
        structure: the same for every group of them)."""
        shaped_as = (id(trainer), keys.shape[0], jax.tree.structure(hps))
        if shaped_as not in self._states:
            self._states[shaped_as] = jax.eval_shape(jax.vmap(trainer.init), keys, hps)
        return self._states[shaped_as]

    def _span(self, window: Window, prepared: Prepared) -> tuple[int, int, int]:
        """`window`'s first and last update and the updates per call on `prepared`'s shape:
        the window's own on the task's shape, the whole run on another (so that
        it takes as many calls)."""
        if prepared is self.prepared:
            return window.start, window.end, self.updates_per_call
        whole = self.prepared.config.num_updates
        if (window.start, window.end) != (0, whole):
            raise InvalidInput(
                "a searched run shape trains whole runs alone: its updates are not the task's"
            )
        end = prepared.config.num_updates
        return 0, end, updates_per_call(end, -(-whole // self.updates_per_call))

    def _group(
        self,
        key: tuple[Shape, int],
        window: Window,
        index: np.ndarray,
        hps: Hyperparameters,
        saved: Path | None,
        keep: bool,
        said: str,
    ) -> _Group:
        """A group of `index`'s runs trained through `window` by the program of `key`."""
        program = self._programs[key]
        keys = run_keys([window.runs[i][2] for i in index])
        group_hps = _rows(hps, index)
        state = self._start(program, window, keys, group_hps, index, saved)
        span = self._span(window, self.prepared_for(self.shape_of(window.runs[index[0]])))
        state, last = self._train(program, state, group_hps, span, len(index), said)
        own = len(set(index.tolist()))  # the group's own runs, not the fill after them
        return _Group(
            index[:own],
            last[:own],
            fetch_diverged(state)[:own],
            [_plain(leaf)[:own] for leaf in jax.tree.leaves(state)] if keep else [],
            self._evaluate(key, program.trainer, state)[:own] if self.eval_episodes else None,
        )

    def _evaluate(self, key: tuple[Shape, int], trainer: Trainer, state: TrainState) -> np.ndarray:
        """Each run's deterministic policy's mean return over the population's evaluation
        episodes, every run on the same episodes' keys (its own environments)."""
        runs = state.nonfinite_update.shape[0]
        evaluate = self._evaluators[key]
        returns = np.asarray(evaluate(make_policy(trainer, state), _evaluation_keys(runs)), float)
        return cast(np.ndarray, returns.mean(axis=-1))

    def _hyperparameters(self, runs: Sequence[Run]) -> Hyperparameters:
        """The stacked hyperparameters of `runs` (arm, trial, seed), over every arm's
        surrogates."""
        return stack_hyperparameters(
            [
                resolve_hyperparameters(
                    self.arms[arm], None, **split_setting(self.settings[arm][trial])[0]
                )[0]
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
        like = self._state_shapes(trainer, keys, hps)
        state = load_state(saved, like, index, len(window.runs))
        if resets_itself(trainer.env):  # their state lived outside JAX, in another batch
            state = jax.jit(jax.vmap(trainer.restart_envs))(state)
        return state

    def _train(
        self,
        program: Program,
        state: TrainState,
        hps: Hyperparameters,
        span: tuple[int, int, int],
        runs: int,
        said: str,
    ) -> tuple[TrainState, np.ndarray]:
        """`state` trained by `program` over `span` (the first and last update, the updates
        per call): the state and each run's score (`said` names the runs in progress lines)."""
        trainer = program.trainer
        start, end, per_call = span
        budgeted = with_budget(hps, trainer.config.num_updates)
        last = np.full(runs, np.nan)
        calls = -(-(end - start) // per_call)
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
                done = min(start + (call + 1) * per_call, end)
                rate = (done - start) * trainer.config.samples_per_update * runs
                self.say(
                    f"{said}: update {done} of {end}, "
                    f"{rate / (time.perf_counter() - began):,.0f} env steps/s"
                )
        return state, last


def _evaluation_keys(runs: int) -> jax.Array:
    """:func:`~fppo_jax.run.evaluation.evaluation_key` for each of `runs` runs: the same
    episodes for every run, each stepping its own environments."""
    key = evaluation_key()
    return jax.numpy.broadcast_to(key, (runs, *key.shape))


@jax.jit
def _rows(hps: Hyperparameters, index: np.ndarray) -> Hyperparameters:
    """The hyperparameters of runs `index` of a stacked batch, in one call: a slice of each
    leaf apart would be a call of its own, dozens a group."""
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
