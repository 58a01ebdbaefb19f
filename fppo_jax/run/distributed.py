"""Several devices, and several hosts, with JAX's own sharding and distributed runtime.

A run's program is the same on one device or many: its inputs and state are laid out on a
:class:`jax.sharding.Mesh` with two axes, ``runs`` (the runs of a sweep) and ``data`` (the
environments of one run), and XLA partitions the computation. Each device steps its share of
the environments and computes its share of the batch; the means over the batch (the gradient,
the normaliser statistics, the advantage normalisation) become sums across devices, and the
parameters stay replicated. A sweep's runs are independent, so sharding the ``runs`` axis
needs no communication at all.
"""

from __future__ import annotations

import dataclasses
import os
import pickle
from collections.abc import Callable
from typing import Any, cast

import jax
import numpy as np
from jax.experimental import multihost_utils
from jax.sharding import Mesh, NamedSharding
from jax.sharding import PartitionSpec as P

from fppo_jax.core.trainer import TrainState
from fppo_jax.errors import InvalidInput


def make_mesh(devices: int | None, num_envs: int, data_parallel: int | None = None) -> Mesh | None:
    """The mesh of `devices` devices (default: all JAX sees), or None for a single device.

    Each run's environments are split over `data_parallel` of them (default: all, which is one
    run's case) and the runs of a sweep over the rest. Raises InvalidInput, before anything is
    compiled, for a count that JAX does not have or that does not divide the environments.
    """
    available = jax.devices()
    count = len(available) if devices is None else devices  # a positive count (Options)
    if count > len(available):
        raise InvalidInput(
            f"devices={count}, but JAX sees {len(available)} {available[0].platform} "
            f"device{'s' if len(available) > 1 else ''}"
        )
    data = count if data_parallel is None else data_parallel  # a positive count (sweep)
    if count % data:
        raise InvalidInput(f"data_parallel must divide the devices ({count}), got {data}")
    if num_envs % data:
        raise InvalidInput(
            f"num_envs ({num_envs}) must be divisible by the devices each run is split over "
            f"({data})"
        )
    if count == 1:
        return None
    grid = np.asarray(available[:count]).reshape(count // data, data)
    return Mesh(grid, ("runs", "data"))


def state_shardings(mesh: Mesh, state: TrainState) -> TrainState:
    """Where each leaf of a training state (along runs) lives on `mesh`: the runs split over
    the `runs` axis, and each run's environments over the `data` axis, everything else
    replicated on it."""
    replicated = NamedSharding(mesh, P("runs"))
    per_environment = NamedSharding(mesh, P("runs", "data"))
    shardings: TrainState = jax.tree.map(lambda _: replicated, state)
    envs = jax.tree.map(lambda _: per_environment, state.envs)
    return dataclasses.replace(shardings, envs=envs)


def input_sharding(mesh: Mesh) -> NamedSharding:
    """Keys and hyperparameters: split over runs."""
    return NamedSharding(mesh, P("runs"))


def initialize() -> None:
    """Join a multi-process run with ``jax.distributed.initialize``, before anything else uses
    JAX.

    The coordinator is ``JAX_COORDINATOR_ADDRESS`` (host:port of process 0), the process count
    ``JAX_NUM_PROCESSES`` and this process's rank ``JAX_PROCESS_ID``; any that is unset is
    detected by JAX from the cluster (SLURM, Open MPI, Kubernetes). CPU devices talk through
    gloo.
    """
    num_processes, process_id = (
        int(os.environ[v]) if v in os.environ else None
        for v in ("JAX_NUM_PROCESSES", "JAX_PROCESS_ID")
    )
    jax.config.update("jax_cpu_collectives_implementation", "gloo")
    try:
        jax.distributed.initialize(num_processes=num_processes, process_id=process_id)
    except ValueError as error:  # what JAX could not detect, such as the coordinator
        raise InvalidInput(
            f"cannot join a multi-process run: {str(error).rstrip('.')}; set "
            "JAX_COORDINATOR_ADDRESS (host:port of process 0), JAX_NUM_PROCESSES and "
            "JAX_PROCESS_ID, or start it under SLURM, Open MPI or Kubernetes, which JAX detects"
        ) from error


def place(tree: Any, shardings: Any) -> Any:
    """`tree` laid out as `shardings` (a matching tree, or one sharding for every leaf).

    In one process this is ``jax.device_put``. In a multi-process run a sharding spans other
    processes' devices too; an array not yet laid out so is assembled from this process's host
    copy, which every process holds alike (keys, hyperparameters, a restored state)."""
    if isinstance(shardings, NamedSharding):
        shardings = jax.tree.map(lambda _: shardings, tree)

    def one(x: Any, sharding: NamedSharding) -> jax.Array:
        if isinstance(x, jax.Array) and x.sharding == sharding:
            return x
        if sharding.is_fully_addressable:
            return cast(jax.Array, jax.device_put(x, sharding))
        if jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key):  # type: ignore[attr-defined]  # jax.dtypes does not re-export it
            return cast(jax.Array, jax.random.wrap_key_data(one(jax.random.key_data(x), sharding)))
        host = np.asarray(x)
        return jax.make_array_from_callback(host.shape, sharding, lambda index: host[index])

    return jax.tree.map(one, tree, shardings)


def fetch(x: jax.Array) -> np.ndarray:
    """`x` on the host, whole, even where its shards live on other processes' devices (a
    restored state is on the host already). In a multi-process run every process calls it."""
    if not isinstance(x, jax.Array) or x.is_fully_addressable:
        return np.asarray(x)
    return np.asarray(multihost_utils.process_allgather(x, tiled=True))


def fetch_tree(tree: Any) -> Any:
    """Every leaf of `tree` on the host (:func:`fetch`), PRNG keys as keys of host data."""

    def one(x: Any) -> Any:
        if isinstance(x, jax.Array) and jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key):  # type: ignore[attr-defined]  # jax.dtypes does not re-export it
            return jax.random.wrap_key_data(fetch(jax.random.key_data(x)))  # type: ignore[arg-type]  # host key data is a valid argument
        return fetch(x)

    return jax.tree.map(one, tree)


def on_main_process(work: Callable[[], Any]) -> Any:
    """`work()` done by process 0 alone, its result (or the exception it raised) handed to
    every process of a multi-process run, which all call this; in one process, `work()`.

    This is how a run's files stay with one writer: process 0 reads its checkpoints, and
    the others learn what it read, or the error it met, from it."""
    if jax.process_count() == 1:
        return work()
    outcome: tuple[Any, BaseException | None] = (None, None)
    if is_main_process():
        try:
            outcome = (work(), None)
        except Exception as error:
            outcome = (None, error)
    result, error = _from_main_process(outcome)  # type: ignore[misc]  # `error` of the except clause above is free again here
    if error is not None:
        raise error
    return result


def _from_main_process(value: Any) -> Any:
    """Process 0's `value` on every process (pickled, then broadcast as bytes)."""
    data = np.frombuffer(pickle.dumps(value), np.uint8) if is_main_process() else None
    size = int(multihost_utils.broadcast_one_to_all(np.int32(0 if data is None else data.size)))
    buffer = data if data is not None else np.zeros(size, np.uint8)
    return pickle.loads(np.asarray(multihost_utils.broadcast_one_to_all(buffer)).tobytes())


def is_main_process() -> bool:
    """Whether this process reports and writes files (process 0 of a multi-process run)."""
    return jax.process_index() == 0
