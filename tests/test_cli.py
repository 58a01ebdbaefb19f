import errno
import os
from types import SimpleNamespace

import pytest

import fppo_jax.cli.commands
import fppo_jax.store.metric_log
from fppo_jax.cli import _without_closed_loop_reports, main
from fppo_jax.errors import InvalidInput, MissingFile, MissingPackage, NotEnoughMemory

TINY_FLAGS = ["--num-envs", "4", "--num-steps", "32", "--minibatches", "4", "--epochs", "2"]


def test_out_of_range_hyperparameter_is_an_error_not_a_traceback(capsys):
    assert main(["train", "--variant", "fppo-lp", "--alpha", "0.5"]) == 2
    assert "error: alpha must be >= 1 for fppo-lp" in capsys.readouterr().err


def test_a_disk_that_fills_while_writing_is_one_line_naming_the_file(tmp_path, capsys, monkeypatch):
    def full(path, value):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))

    monkeypatch.setattr(fppo_jax.store.metric_log, "write_json", full)
    assert main(["train", "--quiet", *TINY_FLAGS, "--output", str(tmp_path)]) == 2
    error = capsys.readouterr().err
    assert error == f"fppo-jax: error: {tmp_path / 'config.json'}: No space left on device\n"


def test_an_os_error_that_names_no_file_is_not_taken_for_a_user_s_error(monkeypatch):
    def broken(*_):
        raise OSError("a bug, not a path")

    monkeypatch.setattr(fppo_jax.cli.commands, "COMMANDS", {"list": broken})
    with pytest.raises(OSError, match="a bug"):
        main(["list"])


@pytest.mark.parametrize("error", [ValueError, ImportError, MemoryError, ZeroDivisionError])
def test_a_built_in_error_from_inside_keeps_its_traceback(error, monkeypatch):
    def broken(*_):
        raise error("a bug deep inside")

    monkeypatch.setattr(fppo_jax.cli.commands, "COMMANDS", {"list": broken})
    with pytest.raises(error, match="a bug deep inside"):
        main(["list"])


@pytest.mark.parametrize("error", [InvalidInput, MissingPackage, MissingFile, NotEnoughMemory])
def test_a_project_error_is_one_line(error, monkeypatch, capsys):
    def refused(*_):
        raise error("what to do instead")

    monkeypatch.setattr(fppo_jax.cli.commands, "COMMANDS", {"list": refused})
    assert main(["list"]) == 2
    assert capsys.readouterr().err == "fppo-jax: error: what to do instead\n"


def test_the_command_drops_a_closed_event_loop_s_reports_and_passes_every_other_on():
    reported = []
    hook = _without_closed_loop_reports(reported.append)
    closed = SimpleNamespace(exc_value=RuntimeError("Event loop is closed"))
    other_message = SimpleNamespace(exc_value=RuntimeError("Event loop is running"))
    other_type = SimpleNamespace(exc_value=ValueError("Event loop is closed"))
    for unraisable in (closed, other_message, other_type):
        hook(unraisable)
    assert reported == [other_message, other_type]
