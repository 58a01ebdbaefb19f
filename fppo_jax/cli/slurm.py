"""What the command line reads from a SLURM job's variables: the part of a sweep that a job
array's task trains (``--part auto``)."""

from __future__ import annotations

import os
from collections.abc import Mapping

from fppo_jax.errors import InvalidInput

ARRAY_VARIABLES = (
    "SLURM_ARRAY_TASK_ID",
    "SLURM_ARRAY_TASK_MIN",
    "SLURM_ARRAY_TASK_MAX",
    "SLURM_ARRAY_TASK_STEP",
    "SLURM_ARRAY_TASK_COUNT",
)


def array_part(environ: Mapping[str, str] = os.environ) -> tuple[int, int]:
    """``--part auto``: this job array task's share of a sweep split over the whole array,
    (its index among the array's tasks from 1, the array's task count), where the index is
    (ID − MIN) / STEP. Raises InvalidInput naming the variables read where they do not describe
    a whole array of evenly stepped indices from 0 or 1: a resubmission of some of its tasks
    (``sbatch --array=2``) looks like an array of its own, and would silently train other runs
    than the task it replaces."""
    read = {name: environ[name] for name in ARRAY_VARIABLES if name in environ}
    shown = ", ".join(f"{name}={text!r}" for name, text in read.items()) or "none of them set"

    def refuse(problem: str) -> InvalidInput:
        return InvalidInput(
            f"--part auto cannot take this task's part from SLURM's job array: {problem} "
            f"(read {shown}); pass --part K/N instead (the K-th of N parts)"
        )

    if "SLURM_ARRAY_TASK_ID" not in read:
        raise refuse("this is not a SLURM job array task")
    numbers = {}
    for name in ARRAY_VARIABLES:
        if name not in read:
            raise refuse(f"SLURM set SLURM_ARRAY_TASK_ID but not {name}")
        text = read[name]
        if not (text.isascii() and text.isdigit()):
            raise refuse(f"{name} is not a whole number ≥ 0")
        numbers[name] = int(text)
    task, first, last, step, count = (numbers[name] for name in ARRAY_VARIABLES)
    if count == 0 or step == 0:
        raise refuse("SLURM_ARRAY_TASK_COUNT and SLURM_ARRAY_TASK_STEP must be at least 1")
    if last != first + step * (count - 1):
        raise refuse(
            "the array is not one evenly stepped range (MAX ≠ MIN + STEP × (COUNT − 1)), as a "
            "list of indices such as 1,4,5 is not"
        )
    if not first <= task <= last or (task - first) % step:
        raise refuse("SLURM_ARRAY_TASK_ID is not one of the array's indices")
    if count == 1:
        raise refuse("an array of one task, such as a resubmitted task, splits nothing")
    if first not in (0, 1):
        raise refuse(
            f"the array starts at {first}, not 0 or 1, as a resubmission of some of a split's "
            "tasks would"
        )
    return (task - first) // step + 1, count
