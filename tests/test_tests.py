"""The suite's own rules: a test waits as long as the machine needs, never against a clock, so
a loaded machine gives a slower run, not a failure."""

import re
from pathlib import Path

TESTS = Path(__file__).resolve().parent
# A limit in seconds on a subprocess, a wait or a polling loop.
LIMIT = re.compile(r"\btimeout\s*(:[^=\n]*)?=\s*\d|\.(wait|communicate)\(\s*\d|monotonic\(\)\s*\+")


def test_no_test_waits_against_a_wall_clock_limit():
    found = [
        f"{path.name}:{number}: {line.strip()}"
        for path in sorted(TESTS.glob("*.py"))
        for number, line in enumerate(path.read_text().splitlines(), 1)
        if LIMIT.search(line)
    ]
    assert not found, "\n".join(found)


def test_the_files_the_suite_runs_first_are_there():
    from conftest import LONGEST_FIRST

    assert [name for name in LONGEST_FIRST if not (TESTS / name).is_file()] == []
