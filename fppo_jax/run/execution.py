"""Running a training program: compiled once, then called in equal chunks of updates.

Its inputs, state and metrics always carry a leading run axis: a sweep's runs are vmapped along
it, and a single run is its own program with the axis added around it (:func:`one_run`).
Every chunk, and every group of runs of the same size, reuses the one compiled program, and so
does a later run in the same process with the same static configuration, environment object and
array shapes (hyperparameters are traced: their values are not part of the shape, and nor is
the step budget, which the program takes as one of them). What the host does between chunks is
the driver's (:mod:`fppo_jax.run.driver`).
"""

from __future__ import annotations

import collections
import contextlib
import dataclasses
import time
from collections.abc import Callable, Iterator, Sequence
from typing import Any, TypeVar, cast

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from fppo_jax.core.config import Hyperparameters, with_budget
from fppo_jax.core.trainer import Trainer, TrainState
from fppo_jax.run.distributed import fetch, input_sharding, place, state_shardings

PROGRAMS_KEPT = 8  # compiled programs kept for reuse, the most recently used first
# What JAX reports of its persistent compilation cache (jax.monitoring): a program looked up
# there, and one found there.
LOOKED_UP = "/jax/compilation_cache/compile_requests_use_cache"
FOUND = "/jax/compilation_cache/cache_hits"

F = TypeVar("F", bound=Callable[..., Any])
T = TypeVar("T")


def first_run(tree: T) -> T:
    """`tree` without its leading run axis: the first run's part of every leaf."""
    return cast(T, jax.tree.map(lambda x: x[0], tree))


def batch_of_one(tree: T) -> T:
    """`tree` with a leading run axis of length one on every leaf."""
    return cast(T, jax.tree.map(lambda x: x[None], tree))


# The same two, as one program for a whole tree of arrays on a device. Outside a trace, each
# leaf's slice would be a small program of its own, compiled on its first use for each shape
# and dtype: a few milliseconds each, for the dozens of leaves of a state, on every start.
first_run_on_device = jax.jit(first_run)
batch_of_one_on_device = jax.jit(batch_of_one)
_keys = jax.jit(jax.vmap(jax.random.key))


def run_keys(seeds: Sequence[int]) -> jax.Array:
    """``jax.random.key(seed)`` of each of `seeds` along a leading run axis, in one compiled
    call. A seed counts by its 64 bits (modulo 2**64): one from 2**63, which
    ``jax.random.key`` itself refuses, gives the key of its signed equal."""
    return cast(jax.Array, _keys(np.array([seed % 2**64 for seed in seeds], np.uint64)))


def one_run(fn: F) -> F:
    """`fn` of one run as a function of a batch of one: every argument's run axis taken off
    before, and put on every result after. It compiles to `fn`'s own program, bit for bit,
    where ``jax.vmap`` over one run rounds differently in the last bits (measured)."""

    def of_batch_of_one(*args: Any) -> Any:
        return batch_of_one(fn(*first_run(args)))

    return of_batch_of_one  # type: ignore[return-value]


def updates_per_call(num_updates: int, calls: int) -> int:
    """Updates per compiled call to run `num_updates` in (at most) `calls` equal calls."""
    return -(-num_updates // max(1, min(calls, num_updates)))


@dataclasses.dataclass(frozen=True)
class Program:
    """A trainer's compiled init and chunk of updates, for a batch of `runs`."""

    trainer: Trainer
    init: Callable[[jax.Array, Hyperparameters], TrainState]
    run: Callable[[TrainState, Hyperparameters], tuple[TrainState, Any]]  # hps with_budget
    runs: int
    updates_per_call: int
    compile_seconds: float  # spent compiling it for this run: 0 when reused
    loaded: bool = False  # from the persistent compilation cache, every part of it


class _Programs:
    """Compiled programs by what they were compiled for: the static configuration but its step
    budget, the environment (by identity: each entry keeps it alive), the inputs' tree
    structure, shapes and dtypes, the chunk length and the mesh. A trainer's networks follow
    from its configuration and environment, so equal keys make equal programs."""

    def __init__(self) -> None:
        self.entries: collections.OrderedDict[tuple[Any, ...], tuple[Any, Program]] = (
            collections.OrderedDict()
        )

    @staticmethod
    def key(
        trainer: Trainer,
        inputs: tuple[Any, ...],
        along_runs: Callable[..., Any],
        updates_per_call: int,
        mesh: Mesh | None,
    ) -> tuple[Any, ...]:
        leaves, treedef = jax.tree.flatten(inputs)
        shapes = tuple((x.shape, str(x.dtype)) for x in leaves)
        config = dataclasses.replace(trainer.config, total_steps=trainer.config.samples_per_update)
        static = (config, id(trainer.env), along_runs, updates_per_call, mesh)
        return (*static, treedef, shapes)

    def get(self, key: tuple[Any, ...]) -> Program | None:
        if key not in self.entries:
            return None
        self.entries.move_to_end(key)
        return self.entries[key][1]

    def add(self, key: tuple[Any, ...], program: Program) -> None:
        self.entries[key] = (program.trainer.env, program)
        while len(self.entries) > PROGRAMS_KEPT:
            self.entries.popitem(last=False)


_PROGRAMS = _Programs()


def compile_program(
    trainer: Trainer,
    keys: jax.Array,
    hps: Hyperparameters,
    along_runs: Callable[[Callable[..., Any]], Callable[..., Any]],
    updates_per_call: int,
    mesh: Mesh | None = None,
) -> Program:
    """Compile `trainer` for these keys and hyperparameters (along a leading run axis, as
    `along_runs` maps one run's functions: ``jax.vmap``, or :func:`one_run` for a single run),
    running `updates_per_call` updates per call, on `mesh` if given (see
    :mod:`fppo_jax.run.distributed`) or on the default device; or reuse the program compiled for
    the same (see :class:`_Programs`)."""
    key = _Programs.key(trainer, (keys, hps), along_runs, updates_per_call, mesh)
    compiled = _PROGRAMS.get(key)
    if compiled is not None:
        return dataclasses.replace(compiled, trainer=trainer, compile_seconds=0.0, loaded=False)

    def run(state: TrainState, hp: Hyperparameters) -> tuple[TrainState, Any]:
        return trainer.run(state, hp, updates_per_call)

    init, run = along_runs(trainer.init), along_runs(run)
    budgeted = with_budget(hps, trainer.config.num_updates)
    # Both programs are compiled here, ahead of time, so that compilation is never counted as
    # training time.
    start = time.perf_counter()
    with _cache_lookups() as heard:
        if mesh is None:
            state = jax.eval_shape(init, keys, hps)
            compiled_init: Callable[..., Any] = jax.jit(init).lower(keys, hps).compile()
            compiled_run: Callable[..., Any] = jax.jit(run).lower(state, budgeted).compile()
        else:
            compiled_init, compiled_run = _compile_on_mesh(init, run, keys, hps, budgeted, mesh)
    seconds = time.perf_counter() - start
    loaded = 0 < heard[FOUND] == heard[LOOKED_UP]
    runs = keys.shape[0]
    program = Program(trainer, compiled_init, compiled_run, runs, updates_per_call, seconds, loaded)
    _PROGRAMS.add(key, program)
    return program


@contextlib.contextmanager
def _cache_lookups() -> Iterator[collections.Counter[str]]:
    """Counts JAX's lookups in its persistent compilation cache (`LOOKED_UP`), and those that
    found the program (`FOUND`), while the block runs: a program whose every part was found
    was loaded, not compiled. Nothing is looked up where the cache is off, or for a program
    that calls back into Python."""
    heard: collections.Counter[str] = collections.Counter()

    def listen(event: str, **_: str | int) -> None:
        if event in (LOOKED_UP, FOUND):
            heard[event] += 1

    jax.monitoring.register_event_listener(listen)
    try:
        yield heard
    finally:
        jax.monitoring.unregister_event_listener(listen)


def _compile_on_mesh(
    init: Callable[..., Any],
    run: Callable[..., Any],
    keys: jax.Array,
    hps: Any,
    budgeted: Any,
    mesh: Mesh,
) -> tuple[_Placed, _Placed]:
    """`init` and `run` compiled with their inputs and state laid out on `mesh` (`run`'s
    hyperparameters `budgeted`: carrying the run's length)."""
    inputs, state = input_sharding(mesh), jax.eval_shape(init, keys, hps)
    placed = state_shardings(mesh, state)
    compiled_init = _Placed(
        jax.jit(init, in_shardings=(inputs, inputs), out_shardings=placed)
        .lower(keys, hps)
        .compile(),
        (inputs, inputs),
    )
    # Metrics are small: replicated, so that every process of a multi-process run can read
    # them all.
    metrics = NamedSharding(mesh, PartitionSpec())
    compiled_run = _Placed(
        jax.jit(run, in_shardings=(placed, inputs), out_shardings=(placed, metrics))
        .lower(state, budgeted)
        .compile(),
        (placed, inputs),
    )
    return compiled_init, compiled_run


@dataclasses.dataclass(frozen=True)
class _Placed:
    """A compiled program whose arguments are first laid out as it expects (a no-op for arrays
    already so, such as the state it returned)."""

    compiled: Any
    shardings: tuple[Any, ...]

    def __call__(self, *args: Any) -> Any:
        return self.compiled(*(place(a, s) for a, s in zip(args, self.shardings, strict=True)))


def run_chunks(
    program: Program, state: TrainState, hps: Hyperparameters
) -> Iterator[tuple[TrainState, dict[str, np.ndarray]]]:
    """Train from `state` to the end of the run, one compiled call at a time: yields the state
    after each call and that call's metrics ([run, update]). The next
    call is dispatched before the caller's work on the current one, so the two overlap."""
    config = program.trainer.config
    hps = with_budget(hps, config.num_updates)
    first = int(np.max(fetch(state.update)))
    calls = -(-(config.num_updates - first) // program.updates_per_call)
    pending = program.run(state, hps) if calls else None
    for call in range(calls):
        assert pending is not None  # calls > 0: a call is always dispatched ahead
        state, metrics = pending
        if call + 1 < calls:
            pending = program.run(state, hps)
        host = jax.device_get(metrics._asdict())  # a dict with its keys sorted
        yield state, _without_padding({name: host[name] for name in metrics._fields})


def _without_padding(metrics: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Without the updates past the run's end (the last chunk's padding, env_steps −1)."""
    ran = metrics["env_steps"][0] >= 0
    return {name: values[..., ran] for name, values in metrics.items()}


def concatenate(parts: list[dict[str, np.ndarray]], axis: int = -1) -> dict[str, np.ndarray]:
    """Metrics joined along updates (``axis=-1``: consecutive chunks of the same runs) or along
    runs (``axis=0``: groups of runs, [run, update]; a group stopped early is padded to the
    others' length with NaN, and env steps −1). A column a part lacks (an evaluation column
    that a resumed run added) is NaN there."""
    names = dict.fromkeys(name for p in parts for name in p)
    length = max(p["env_steps"].shape[-1] for p in parts)

    def column(p: dict[str, np.ndarray], name: str) -> np.ndarray:
        values: np.ndarray = (
            np.asarray(p[name]) if name in p else np.full(p["env_steps"].shape, np.nan, np.float32)
        )
        if axis == -1:
            return values
        fill = -1 if name == "env_steps" else np.nan
        width = [(0, 0)] * (values.ndim - 1) + [(0, length - values.shape[-1])]
        return np.pad(values, width, constant_values=fill)

    return {name: np.concatenate([column(p, name) for p in parts], axis=axis) for name in names}
