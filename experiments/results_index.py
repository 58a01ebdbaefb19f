"""The index of what is recorded: every Markdown result under results/, with its title and the
machine, date, command and commit that made it, each as the file itself says.

    python experiments/results_index.py           # writes results/README.md
    python experiments/results_index.py --check   # exits 1 where results/README.md is not current

Nothing is typed here by hand: a result recorded before results named their commit (2026-12-04)
shows none, and one whose header names no machine or command shows a dash. A command names its
script where it was then; where the script has moved since (into a folder by purpose), the
index adds where it is now. The index is rebuilt from the records, so it is written again
freely; a test keeps it current.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

from common import RESULTS, UNCOMMITTED, argument_parser

INDEX = RESULTS / "README.md"
REPOSITORY = RESULTS.parents[1]
SCRIPT = re.compile(r"\bexperiments/[\w/]+\.py\b")
DATE = re.compile(r"\b\d{4}-\d{2}-\d{2}\b")
MACHINE = re.compile(r"\bMachine: (?P<machine>.*?)(?:;|\. |\.?$)")
COMMIT = rf"[0-9a-f]{{40}}(?: {UNCOMMITTED})?"  # as common.commit() writes it
COMMAND = re.compile(
    rf"\b(?:Command:|Written by) `(?P<command>[^`]*)`(?:, at (?P<commit>{COMMIT}))?"
)


def described(path: Path) -> dict[str, str]:
    """What `path`'s header says of it: title, machine, date, command and commit ("–" where it
    says nothing)."""
    found = dict.fromkeys(("title", "machine", "date", "command", "commit"), "–")
    for line in path.read_text().splitlines()[:12]:
        if line.startswith("# ") and found["title"] == "–":
            found["title"] = line[2:].strip()
        if (machine := MACHINE.search(line)) and found["machine"] == "–":
            found["machine"] = machine["machine"].strip()
            date = DATE.search(line)
            found["date"] = date.group() if date else "–"
        if (command := COMMAND.search(line)) and found["command"] == "–":
            found["command"] = f"`{command['command']}`"
            if command["commit"]:
                found["commit"] = command["commit"][:12] + command["commit"][40:]
    return found


def now_at(command: str) -> str | None:
    """Where the script `command` runs is now, if it has moved since (None if it has not, or
    if it is gone)."""
    script = SCRIPT.search(command)
    if script is None or (REPOSITORY / script.group()).exists():
        return None
    name = Path(script.group()).name
    moved = sorted(REPOSITORY.glob(f"experiments/*/{name}"))
    return moved[0].relative_to(REPOSITORY).as_posix() if moved else None


def index() -> str:
    """The index's text, from every Markdown file under results/ but itself."""
    records = sorted(p for p in RESULTS.rglob("*.md") if p != INDEX)
    lines = [
        "# Recorded results",
        "",
        "Every Markdown result under this folder, with what its own header says of it. Written",
        "by `python experiments/results_index.py` from the files themselves; `–`: the file does",
        "not say (results recorded before 2026-12-04 name no commit). A command names its script",
        "where it was then, and where it is now if it has moved since. What each one shows, and",
        "how it bears on the project's claims, is in `experiments/README.md`.",
        "",
        "| file | what | machine | date | command | commit |",
        "|---|---|---|---|---|---|",
    ]
    for path in records:
        about = described(path)
        if moved := now_at(about["command"]):
            about["command"] += f" (now `{moved}`)"
        name = path.relative_to(RESULTS).as_posix()
        cells = [f"[{name}]({name})", *(about[k].replace("|", "\\|") for k in list(about))]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argument_parser(__doc__)
    parser.add_argument("--check", action="store_true", help="only say whether it is current")
    args = parser.parse_args()
    text = index()
    if args.check:
        if not INDEX.exists() or INDEX.read_text() != text:
            sys.exit(f"{INDEX} is not current: run python experiments/results_index.py")
        print(f"{INDEX} is current")
        return
    INDEX.write_text(text)
    print(f"wrote {INDEX}")


if __name__ == "__main__":
    main()
