"""The numbers the READMEs and docs quote from recorded results: every interval they print,
``X [A, B]``, is one that a report under experiments/results/ records, to the precision quoted
(or negated, where a sentence says "below"). A number typed by hand that drifts from its
report, or outlives it, fails here."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
QUOTING = [
    "README.md",
    "experiments/README.md",
    *sorted(p.name for p in (ROOT / "docs").glob("*.md")),
]
NUMBER = r"[−+-]?\d[\d,]*(?:\.\d+)?%?"
INTERVAL = re.compile(rf"({NUMBER}) \[({NUMBER}), ({NUMBER})\]")

Quoted = tuple[tuple[float, int], ...]  # each value with its decimals


def _value(text: str) -> tuple[float, int]:
    """A printed number and its decimals: ``−1,179`` is (−1179, 0), ``+21%`` (0.21, 2)."""
    text = text.replace("−", "-").replace(",", "").replace("+", "")
    share = text.endswith("%")
    text = text.rstrip("%")
    decimals = len(text.split(".")[1]) if "." in text else 0
    return float(text) / (100 if share else 1), decimals + (2 if share else 0)


def _recorded() -> list[tuple[float, float, float]]:
    return [
        tuple(_value(x)[0] for x in match)  # type: ignore[misc]
        for report in (ROOT / "experiments" / "results").rglob("*.md")
        for match in INTERVAL.findall(report.read_text())
    ]


def _matches(quoted: Quoted, recorded: tuple[float, float, float]) -> bool:
    point, low, high = recorded
    for values in ((point, low, high), (-point, -high, -low)):
        if all(
            abs(v - x) <= 0.5 * 10.0**-d + 1e-9 for (x, d), v in zip(quoted, values, strict=True)
        ):
            return True
    return False


def _path(name: str) -> Path:
    return ROOT / name if (ROOT / name).exists() else ROOT / "docs" / name


@pytest.mark.parametrize("name", QUOTING)
def test_every_quoted_interval_is_a_recorded_one(name):
    recorded = _recorded()
    assert len(recorded) > 100  # the reports are there to check against
    quoted = INTERVAL.findall(_path(name).read_text())
    unrecorded = [
        " ".join(q) for q in quoted if not any(_matches(tuple(map(_value, q)), r) for r in recorded)
    ]
    assert not unrecorded, f"{name} quotes intervals no report records: {unrecorded}"


def test_the_check_tells_a_drifted_number():
    recorded = (2651.6, 2404.8, 2821.7)
    assert _matches(tuple(map(_value, ("2652", "2405", "2822"))), recorded)
    assert _matches(tuple(map(_value, ("−2652", "−2822", "−2405"))), recorded)  # "below"
    assert not _matches(tuple(map(_value, ("2652", "2420", "2822"))), recorded)
    assert not _matches(tuple(map(_value, ("2651.7", "2404.8", "2821.7"))), recorded)
    assert _value("+21%") == (0.21, 2) and _value("−1,179") == (-1179.0, 0)
