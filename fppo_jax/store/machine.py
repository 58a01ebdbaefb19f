"""The machine a time was measured on, in words. A record keeps it beside its seconds: the parts
of one experiment may run on different machines, and a time says little without its machine."""

from __future__ import annotations

import os
import platform

import jax

# What a record that joins parts says of a part whose own record predates machines.
NOT_RECORDED = "not recorded"


def describe_machine() -> str:
    """The processor, its cores (and how many this process may use, if fewer), the accelerator
    JAX sees and the jax version, e.g. ``AMD EPYC, 2 cores, no GPU; jax 0.10.2``."""
    try:
        with open("/proc/cpuinfo") as f:
            names = [line.split(":", 1)[1].strip() for line in f if line.startswith("model name")]
    except OSError:
        names = []
    device = jax.devices()[0]
    accelerator = "no GPU" if device.platform == "cpu" else device.device_kind
    cpu = names[0] if names else platform.processor() or platform.machine()
    cores = f"{os.cpu_count()} cores"
    usable = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    if usable != os.cpu_count():  # pinned to some of them (taskset, a SLURM job's share)
        cores += f" ({usable} used)"
    return f"{cpu}, {cores}, {accelerator}; jax {jax.__version__}"
