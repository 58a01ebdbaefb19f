"""fppo_jax.store.machine: the machine a time was measured on, named in words, and kept by a
sweep's record beside its seconds (a record from before they were kept reads with none; one
whose machines are not names is refused)."""

import dataclasses
import json
import os

import jax
from helpers import sweep_by_hand
from test_sweep_files import refused, rewrite_record

from fppo_jax import SweepResult
from fppo_jax.store.machine import describe_machine


def test_the_machine_is_named_by_its_cores_accelerator_and_jax():
    named = describe_machine()
    assert named.endswith(f", {os.cpu_count()} cores, no GPU; jax {jax.__version__}")


def test_a_process_pinned_to_some_cores_says_how_many_it_uses(monkeypatch):
    monkeypatch.setattr(os, "cpu_count", lambda: 8)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1}, raising=False)
    assert ", 8 cores (2 used), " in describe_machine()


def test_a_sweep_keeps_its_machines_and_one_recorded_before_reads_with_none(tmp_path, capsys):
    kept = dataclasses.replace(sweep_by_hand(), machines=["A, 2 cores", "B, 16 cores"])
    kept.write(tmp_path)
    assert SweepResult.read(tmp_path).machines == ["A, 2 cores", "B, 16 cores"]
    rewrite_record(tmp_path, "machines", None)
    assert SweepResult.read(tmp_path).machines == []
    rewrite_record(tmp_path, "machines", [2])
    refused(tmp_path, "sweep.json", "not a list of machines, each named in words", capsys)
    sweep_by_hand().write(tmp_path / "none")  # a sweep that names none writes no key
    assert "machines" not in json.loads((tmp_path / "none" / "sweep.json").read_text())
