"""Programs the distributed tests run in fresh processes (the device count and the distributed
runtime are fixed when JAX starts).

    python tests/distributed_workers.py devices OUT.npz   # with 4 CPU devices
    python tests/distributed_workers.py process OUT.npz   # one of a jax.distributed group
    CHECKPOINTS=DIR [KILL_AT=3] python tests/distributed_workers.py process OUT.npz
    CHECKPOINTS=DIR TERM_AT=2 UPDATES=12 python tests/distributed_workers.py process OUT.npz
"""

import os
import signal
import sys
import time

import numpy as np

SMALL = {"num_envs": 8, "num_steps": 32, "num_minibatches": 4, "num_epochs": 2}
GRID = {"variant": ["ppo", "fppo-lp", "fppo-qp"]}


def flat(tree) -> list[np.ndarray]:
    import jax

    return [np.asarray(x) for x in jax.tree.leaves(tree)]


def devices(out: str) -> None:
    """One run on 1 and on 4 devices; a sweep unsharded, over runs, and on a 2 × 2 mesh; the
    errors of bad device counts."""
    import fppo_jax

    results: dict[str, np.ndarray] = {}
    for count in (1, 4):
        run = fppo_jax.train("cartpole", "fppo-lp", total_steps=256 * 6, devices=count, **SMALL)
        results[f"train{count}_loss"] = run.metrics["policy_loss"]
        results[f"train{count}_return"] = run.metrics["average_return"]
        for i, leaf in enumerate(flat(run.params)):
            results[f"train{count}_param{i}"] = leaf
        results[f"train{count}_obs_sharding"] = np.asarray(str(run.state.envs.obs.sharding))
    for name, options in {
        "sweep1": {"devices": 1},
        "sweep4": {"devices": 4},
        "sweep2x2": {"devices": 4, "data_parallel": 2},
    }.items():
        result = fppo_jax.sweep("cartpole", GRID, seeds=2, total_steps=256 * 4, **options, **SMALL)
        for metric, values in result.metrics.items():
            results[f"{name}_{metric}"] = values
        results[f"{name}_runs_per_call"] = np.asarray(result.config["runs_per_call"])
    errors = []
    for options in ({"devices": 5}, {"devices": 3}):
        try:
            fppo_jax.train("cartpole", total_steps=4096, **options, **SMALL)
        except ValueError as error:
            errors.append(str(error))
    try:
        fppo_jax.sweep("cartpole", GRID, seeds=1, total_steps=4096, devices=4, data_parallel=3)
    except ValueError as error:
        errors.append(str(error))
    results["errors"] = np.asarray(errors)
    np.savez(out, **results)


def process(out: str) -> None:
    """Join the group described by the JAX_* variables, train, save the parameters.

    With CHECKPOINTS set, checkpoint every update there and resume from what is there; with
    KILL_AT set too, kill this process (SIGKILL) once that update is done; with TERM_AT, send
    process 1 SIGTERM once that update is done (as a cluster does to preempt a job), and save
    the update at which training stopped."""
    from fppo_jax.run import distributed

    distributed.initialize()
    import jax

    import fppo_jax

    checkpoints = {}
    updates = int(os.environ.get("UPDATES", "6"))
    if "CHECKPOINTS" in os.environ:
        checkpoints = {"checkpoint_dir": os.environ["CHECKPOINTS"], "resume": True}
        checkpoints["checkpoint_every"] = 1
    if "KILL_AT" in os.environ:
        kill_at = int(os.environ["KILL_AT"])

        def kill(snapshot):
            if snapshot.update >= kill_at:
                os.kill(os.getpid(), signal.SIGKILL)

        checkpoints["callback"] = kill
    if "TERM_AT" in os.environ:
        term_at = int(os.environ["TERM_AT"])

        def preempt(snapshot):
            if snapshot.update == term_at and jax.process_index() == 1:
                os.kill(os.getpid(), signal.SIGTERM)
            if snapshot.update >= term_at:  # time for the notice to reach every process
                time.sleep(0.3)

        checkpoints["callback"] = preempt
        try:
            fppo_jax.train("cartpole", "fppo-lp", total_steps=256 * updates, **SMALL, **checkpoints)
        except fppo_jax.StoppedBySignal as stopped:
            np.savez(out, stopped_at=stopped.update, signal=int(stopped.signal))
        else:  # trained to the end: the test says so, rather than miss a file
            np.savez(out, stopped_at=-1, signal=0)
        return
    run = fppo_jax.train("cartpole", "fppo-lp", total_steps=256 * updates, **SMALL, **checkpoints)
    leaves = flat(run.params)
    np.savez(
        out,
        *leaves,
        policy_loss=run.metrics["policy_loss"],
        process=jax.process_index(),
        devices=len(jax.devices()),
        resumed_from=run.resumed_from,
    )


if __name__ == "__main__":
    {"devices": devices, "process": process}[sys.argv[1]](sys.argv[2])
