"""A SLURM job array task's part of a split sweep (fppo_jax.cli.slurm, --part auto): its index
among the array's tasks, the variables that name no part refused naming them, and a sweep split
over an array only when asked."""

import pytest

from fppo_jax.cli import main
from fppo_jax.errors import InvalidInput


def slurm_array(task, first, last, step, count):
    from fppo_jax.cli.slurm import ARRAY_VARIABLES

    values = (task, first, last, step, count)
    return {name: str(value) for name, value in zip(ARRAY_VARIABLES, values, strict=True)}


def test_a_slurm_array_task_takes_its_index_among_the_array_s_tasks():
    from fppo_jax.cli.slurm import array_part

    stepped = [array_part(slurm_array(task, 0, 6, 2, 4)) for task in (0, 2, 4, 6)]
    assert stepped == [(1, 4), (2, 4), (3, 4), (4, 4)]  # --array=0-6:2
    assert [array_part(slurm_array(task, 1, 8, 1, 8)) for task in (1, 8)] == [(1, 8), (8, 8)]
    assert array_part(slurm_array(3, 0, 7, 1, 8)) == (4, 8)


@pytest.mark.parametrize(
    "changed, problem",
    [
        ({}, "not a SLURM job array task"),
        ({"SLURM_ARRAY_TASK_ID": "abc"}, "SLURM_ARRAY_TASK_ID is not a whole number"),
        ({"SLURM_ARRAY_TASK_ID": ""}, "SLURM_ARRAY_TASK_ID is not a whole number"),
        ({"SLURM_ARRAY_TASK_MIN": "-1"}, "SLURM_ARRAY_TASK_MIN is not a whole number"),
        ({"SLURM_ARRAY_TASK_COUNT": "0"}, "must be at least 1"),
        ({"SLURM_ARRAY_TASK_STEP": None}, "set SLURM_ARRAY_TASK_ID but not SLURM_ARRAY_TASK_STEP"),
        ({"SLURM_ARRAY_TASK_COUNT": "5"}, "not one evenly stepped range"),
        ({"SLURM_ARRAY_TASK_ID": "3"}, "SLURM_ARRAY_TASK_ID is not one of the array's indices"),
        ({"SLURM_ARRAY_TASK_ID": "8"}, "SLURM_ARRAY_TASK_ID is not one of the array's indices"),
    ],
)
def test_slurm_variables_that_name_no_part_are_refused_naming_them(changed, problem):
    from fppo_jax.cli.slurm import array_part

    environ = {} if not changed else {**slurm_array(2, 0, 6, 2, 4), **changed}
    environ = {name: text for name, text in environ.items() if text is not None}
    with pytest.raises(ValueError, match=problem) as refused:
        array_part(environ)
    message = str(refused.value)
    assert message.startswith("--part auto cannot take this task's part from SLURM's job array")
    assert message.endswith("pass --part K/N instead (the K-th of N parts)")
    assert all(f"{name}={text!r}" in message for name, text in environ.items())


def test_a_resubmitted_array_task_is_refused_rather_than_training_another_part():
    from fppo_jax.cli.slurm import array_part

    with pytest.raises(ValueError, match=r"an array of one task.*SLURM_ARRAY_TASK_ID='2'"):
        array_part(slurm_array(2, 2, 2, 1, 1))  # sbatch --array=2
    with pytest.raises(ValueError, match="the array starts at 3, not 0 or 1"):
        array_part(slurm_array(5, 3, 5, 2, 2))  # sbatch --array=3,5


def test_a_sweep_is_split_over_a_slurm_array_only_when_asked(monkeypatch, capsys):
    import fppo_jax.cli.commands as commands

    asked = []

    def sweep_of(*args, part, **kwargs):
        asked.append(part)
        raise InvalidInput("stopped before training")

    monkeypatch.setattr(commands, "sweep", sweep_of)
    for name, text in slurm_array(4, 0, 6, 2, 4).items():
        monkeypatch.setenv(name, text)
    flags = ["sweep", "--env", "cartpole", "--seeds", "2"]
    assert main(flags) == 2
    assert "SLURM array task 4 trains the whole sweep; --part auto" in capsys.readouterr().err
    assert main([*flags, "--part", "auto"]) == 2 and main([*flags, "--part", "2/3"]) == 2
    assert asked == [None, (3, 4), (2, 3)]
    monkeypatch.setenv("SLURM_ARRAY_TASK_COUNT", "1")
    assert main([*flags, "--part", "auto"]) == 2
    assert "SLURM_ARRAY_TASK_COUNT='1'" in capsys.readouterr().err and len(asked) == 3
