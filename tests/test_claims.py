"""The numbers the READMEs and docs quote from recorded results. Every interval they print,
``X [A, B]``, is one that a report under experiments/results/ records, to the precision quoted
(or negated, where a sentence says "below"); and tied to where it comes from: a row of a
report's table (or a sentence of a report) whose task the quoting sentence names (or, where it
names none, its paragraph), whose variant the paragraph names, in a column of the same endpoint
(the area under the curve where the clause says "area" or "AUC", final returns otherwise).
Likewise each "Holm p X" (a Holm p cell of a row in scope) and each count "N of M" (written so
in a report or plan, or two cells of a row in scope). The statements over many intervals
("every", "none", "16 of 18") are checked one by one against the tables they summarise.

Not checked: figures quoted without an interval (medians such as "388k", IQMs alone, sample
stds, the paper's gaps and "[A, B]" without a point), ranges ("0.76–0.94 points"), words
for counts ("two of six"), a figure from an earlier recording ("had been"), and which of two
variants a paragraph naming both a figure belongs to. A number typed by hand that drifts from
its report, or outlives it, fails here."""

from __future__ import annotations

import functools
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
QUOTING = [
    "README.md",
    "experiments/README.md",
    *sorted(f"docs/{p.name}" for p in (ROOT / "docs").glob("*.md")),
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
    return ROOT / name


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


# Each quoted figure tied to where it comes from: the report's Markdown tables, read as rows
# with the task (a column, or the heading above the table), the variant (its first column) and
# each cell under its column's header and the table's caption (the line above it), so that
# "P on the area under the curve" meets a column of the area, not of final returns.
TASKS = (
    "cartpole",
    "acrobot",
    "mountaincar",
    "hopper",
    "walker2d",
    "halfcheetah",
    "ant",
    "reacher",
    "swimmer",
)
VARIANTS = ("fppo-lp", "fppo-qp", "tr-ppo", "ppo-rb", "spo", "dpo", "ppo")
VARIANT_COLUMNS = ("variant", "candidate", "setting", "arm")
AREA = re.compile(r"\barea\b|\bAUC\b|\bauc\b")
AREA_AFTER = re.compile(r"\s*(?:on|in|of) (?:the )?(?:area|AUC)")  # "0.42 [0.35, 0.49] on the area"
HISTORY = re.compile(r"\bhad (?:been|given|put)\b")
HOLM = re.compile(r"Holm p (?:≤ )?(\d\.\d+(?:e-\d+)?)(?: to (\d\.\d+))?")
# A sequential decision's statistic against its boundary, and P's repeated interval, as a report
# of decisions writes them ("z = −4.46 against ±4.53", "repeated CI [0.31, 0.71]").
SEQUENTIAL = re.compile(r"z = [−-]?\d+\.\d+ against ±\d+\.\d+|repeated CI \[\d\.\d+, \d\.\d+\]")
COUNT = re.compile(r"\b(\d+) of (\d+)\b")


class Row(dict):
    """A table row: its cells by column label, with the report, task and variant."""

    report: str
    task: str | None
    variant: str | None
    heading: str

    def cell(self, header: str) -> str:
        """The cell under `header`, whatever the table's caption."""
        return next(c for label, c in self.items() if label.startswith(f"{header} ("))


@functools.cache
def _named(names: tuple[str, ...], text: str) -> frozenset[str]:
    """Which of `names` `text` names, as words (``PPO`` is not named by ``FPPO-QP``)."""
    return frozenset(
        name
        for name in names
        if re.search(rf"(?<![\w-]){re.escape(name)}(?![\w-])", text, re.IGNORECASE)
    )


def _rows() -> list[Row]:
    rows = []
    for report in sorted((ROOT / "experiments" / "results").rglob("*.md")):
        task, caption, header, heading = None, "", None, ""
        for line in report.read_text().splitlines():
            if line.startswith("#"):
                heading = line
                named = _named(TASKS, line)
                task = next(iter(named)) if len(named) == 1 else None
                header = None
            elif line.startswith("|") and header is None:
                header = [cell.strip() for cell in line.strip("|").split("|")]
            elif line.startswith("|---"):
                continue
            elif line.startswith("|") and header is not None:
                cells = [cell.strip() for cell in line.strip("|").split("|")]
                row = Row({f"{h} ({caption})": c for h, c in zip(header, cells, strict=False)})
                row.report = str(report.relative_to(ROOT))
                row.task = cells[0] if header[0] == "task" else task
                row.heading = heading
                first = next(
                    (c for h, c in zip(header, cells, strict=False) if h in VARIANT_COLUMNS), None
                )
                variant = _named(VARIANTS, first.split(" ")[0]) if first else set()
                row.variant = next(iter(variant)) if variant else None
                rows.append(row)
            else:
                header = None
                if line.strip():
                    caption = line.strip()
                    # A sentence of the report quotes its figures too: a row of its own.
                    named = _named(TASKS, line)
                    row = Row({"text": line})
                    row.report = str(report.relative_to(ROOT))
                    row.task = next(iter(named)) if len(named) == 1 else task
                    row.variant = None
                    row.heading = heading
                    rows.append(row)
    return rows


def _area(label: str) -> bool:
    """Whether a column is of the area under the curve: its header says so, or its table's
    caption does and the header does not name final returns."""
    header, _, caption = label.partition(" (")
    return bool(AREA.search(header)) or (bool(AREA.search(caption)) and "final" not in header)


def _blocks(text: str) -> list[str]:
    """A text's paragraphs and list items, each on one line."""
    blocks = re.split(r"\n\s*\n|\n(?=- )", text)
    return [" ".join(block.split()) for block in blocks]


def _sentences(block: str) -> list[str]:
    return re.split(r"(?<=\.)\s+(?=[A-Z(])", block)


def _in_scope(row: Row, sentence: str, block: str) -> bool:
    """Whether the sentence (or, where it names none, its paragraph) names `row`'s task, and the
    paragraph its variant, if it names any."""
    if row.task is not None:
        tasks = _named(TASKS, sentence) or _named(TASKS, block)
        if tasks and row.task not in tasks:
            return False
    if row.variant is not None:
        variants = _named(VARIANTS, block)
        if variants and row.variant not in variants:
            return False
    return True


def _untied_intervals(text: str, rows: list[Row]) -> list[str]:
    untied = []
    for block in _blocks(text):
        for sentence in _sentences(block):
            start = 0
            for match in INTERVAL.finditer(sentence):
                before = sentence[start : match.start()].split(";")[-1]  # its clause
                after = sentence[match.end() : match.end() + 25]
                start = match.end()
                if HISTORY.search(before):
                    continue  # an earlier recording's figure: no report holds it now
                area = bool(AREA.search(before) or AREA_AFTER.match(after))
                quoted = tuple(map(_value, match.groups()))
                tied = any(
                    _in_scope(row, sentence, block)
                    and (label == "text" or _area(label) == area)
                    and any(
                        _matches(quoted, tuple(_value(x)[0] for x in found))  # type: ignore[arg-type]
                        for found in INTERVAL.findall(cell)
                    )
                    for row in rows
                    for label, cell in row.items()
                )
                if not tied:
                    untied.append(f"{match.group(0)} in “{sentence[:120]}…”")
    return untied


def _untied_p_values(text: str, rows: list[Row]) -> list[str]:
    """Each "Holm p X" (or "Holm p ≤ X", "Holm p X to Y") that no Holm p cell of a row in
    scope holds."""
    untied = []
    for block in _blocks(text):
        for sentence in _sentences(block):
            for match in HOLM.finditer(sentence):
                for quoted in filter(None, match.groups()):
                    tied = any(
                        _in_scope(row, sentence, block)
                        and "Holm p" in label
                        and _same_p(quoted, cell)
                        for row in rows
                        for label, cell in row.items()
                    )
                    if not tied:
                        untied.append(f"Holm p {quoted} in “{sentence[:120]}…”")
    return untied


def _untied_sequential(text: str, rows: list[Row]) -> list[str]:
    """Each "z = X against ±Y" and "repeated CI [A, B]" that no cell of a row in scope holds as
    written: a z, a boundary or an interval that drifts from its report, or is another
    comparison's, fails."""
    untied = []
    for block in _blocks(text):
        for sentence in _sentences(block):
            for match in SEQUENTIAL.finditer(sentence):
                tied = any(
                    _in_scope(row, sentence, block) and match.group(0) in cell
                    for row in rows
                    for cell in row.values()
                )
                if not tied:
                    untied.append(f"{match.group(0)} in “{sentence[:120]}…”")
    return untied


def _same_p(quoted: str, cell: str) -> bool:
    """A quoted p is the cell's, to the precision quoted."""
    try:
        value = float(cell)
    except ValueError:
        return False
    if "e" in quoted:
        return quoted == f"{value:.1e}"
    decimals = len(quoted.split(".")[1])
    return abs(value - float(quoted)) <= 0.5 * 10.0**-decimals + 1e-12


def _untied_counts(text: str, rows: list[Row], sources: str) -> list[str]:
    """Each "N of M" that neither a report or plan writes as such nor a row in scope holds as
    two of its cells (a table's runs and those that reached a threshold, say)."""
    untied = []
    for block in _blocks(text):
        for sentence in _sentences(block):
            for match in COUNT.finditer(sentence):
                count, total = match.groups()
                if f"{count} of {total}" in sources:
                    continue
                tied = any(
                    _in_scope(row, sentence, block)
                    and count in row.values()
                    and total in row.values()
                    for row in rows
                )
                if not tied:
                    untied.append(f"{match.group(0)} in “{sentence[:120]}…”")
    return untied


def _sources() -> str:
    reports = (ROOT / "experiments" / "results").rglob("*.md")
    plans = (ROOT / "experiments" / "plans").glob("*.json")
    return "\n".join(path.read_text() for path in (*reports, *plans))


@pytest.mark.parametrize("name", QUOTING)
def test_every_quoted_figure_is_its_task_s_and_variant_s_in_a_report(name):
    """Each interval, Holm p and count the text quotes is one a report records for a task the
    sentence (or its paragraph) names, a variant its paragraph names, and a column of the same
    endpoint (the area under the curve, or not)."""
    rows, text = _rows(), _path(name).read_text()
    untied = [
        *_untied_intervals(text, rows),
        *_untied_p_values(text, rows),
        *_untied_sequential(text, rows),
        *_untied_counts(text, rows, _sources()),
    ]
    assert not untied, f"{name} quotes figures no report ties to what it names: {untied}"


def test_the_tie_tells_a_figure_quoted_for_the_wrong_task_variant_or_endpoint():
    rows = _rows()
    right = "FPPO-QP on MountainCar (P = 0.65 [0.54, 0.76]; Holm p 0.25)."
    assert not _untied_intervals(right, rows)
    assert _untied_intervals(right.replace("MountainCar", "Acrobot"), rows)  # another task's
    assert _untied_intervals(right.replace("FPPO-QP", "FPPO-LP"), rows)  # another variant's
    assert _untied_intervals(right.replace("(P = ", "(P on the area "), rows)  # another column
    # Hopper's FPPO-QP in the library's report: P(> PPO) 0.35 [0.18, 0.53] on final returns,
    # 0.31 [0.15, 0.49] on the area under the curve.
    assert not _untied_intervals("On Hopper FPPO-QP: 0.35 [0.18, 0.53].", rows)
    assert _untied_intervals("On Hopper FPPO-QP's area: 0.35 [0.18, 0.53].", rows)
    assert not _untied_intervals("On Hopper FPPO-QP's area: 0.31 [0.15, 0.49].", rows)
    assert _untied_p_values("DPO on Swimmer, Holm p 0.011.", rows) == []
    assert _untied_p_values("DPO on Swimmer, Holm p 0.012.", rows)
    assert _untied_p_values("DPO on Ant, Holm p 8.3e-05.", rows)  # baseline-shape's Swimmer
    # FPPO-LP on Hopper in the tuned plan's MuJoCo family, and in Hopper's own study.
    family = "On Hopper FPPO-LP is undecided in the plan's family (z = −4.46 against ±4.53)."
    assert not _untied_sequential(family, rows)
    assert not _untied_sequential(family.replace("4.53", "4.29"), rows)  # its study's, beside
    assert _untied_sequential(family.replace("4.53", "4.52"), rows)
    assert _untied_sequential(family.replace("Hopper", "Swimmer"), rows)
    assert not _untied_sequential("On Hopper FPPO-QP: repeated CI [0.31, 0.71].", rows)
    assert _untied_sequential("On Hopper FPPO-LP: repeated CI [0.31, 0.71].", rows)
    sources = _sources()
    assert _untied_counts("On HalfCheetah PPO 11 of 20 reach 80%.", rows, sources) == []
    # A count no report can hold, so that recording more results never ties it.
    assert _untied_counts("On HalfCheetah PPO 21 of 20 reach 80%.", rows, sources)


# The statements over many intervals ("every", "none", "16 of 18") that the READMEs make, each
# with the phrase it is made in and what the report's tables must show for it to stand.
def _interval(cell: str) -> tuple[float, float, float]:
    found = INTERVAL.search(cell)
    assert found, cell
    return tuple(_value(x)[0] for x in found.groups())  # type: ignore[return-value]


def _edges(report: str) -> str:
    """The report's sentences that name intervals at the edge."""
    text = (ROOT / "experiments" / "results" / report).read_text()
    return "\n".join(line for line in text.splitlines() if line.startswith("At the edge"))


def _quoted(phrase: str, *names: str) -> None:
    for name in names:
        assert phrase in " ".join(_path(name).read_text().split()), f"{name}: {phrase!r}"


def test_sixteen_of_the_18_fppo_intervals_hold_one_is_at_the_edge_and_one_excludes_half():
    _quoted(
        "16 intervals hold 0.5, with P between 0.35 and 0.60; one is at the edge", "docs/results.md"
    )
    _quoted("FPPO-QP on HalfCheetah (P = 0.34 [0.17, 0.52]", "docs/results.md")
    _quoted(
        "the one FPPO-against-PPO interval of the 18 that excludes 0.5 does not survive a "
        "correction for the number of comparisons",
        "README.md",
    )
    rows = [
        r
        for r in _rows()
        if r.report == "experiments/results/study.md"
        and r.heading.endswith(", paper protocol")
        and r.variant in ("fppo-lp", "fppo-qp")
        and "outcome (" in "".join(r)
    ]
    assert len(rows) == 18
    held = [r for r in rows if r.cell("outcome") == "not resolved"]
    assert len(held) == 16
    points = [_interval(r.cell("P(> ppo), final"))[0] for r in held]
    assert round(min(points), 2) == 0.35 and round(max(points), 2) == 0.60
    assert [(r.task, r.variant, r.cell("outcome")) for r in rows if r not in held] == [
        ("mountaincar", "fppo-qp", "better"),
        ("halfcheetah", "fppo-qp", "at the edge"),
    ]


def test_every_escape_interval_is_below_zero_but_walker2d_fppo_qp_s_at_the_edge():
    _quoted(
        "every interval below zero but FPPO-QP's on Walker2d, [−0.14, −0.00], which is at the "
        "edge of zero",
        "docs/results.md",
        "experiments/README.md",
    )
    rows = [r for r in _rows() if r.heading.startswith("## The escape speed") and "text" not in r]
    assert len(rows) == 4
    for row in rows:
        for header in ("FPPO-LP − PPO, points of % [95% CI]", "FPPO-QP − PPO [95% CI]"):
            _, _, high = _interval(row.cell(header))
            if row.task == "walker2d" and header.startswith("FPPO-QP"):
                assert -0.005 <= high <= 0  # −0.00, and named at the edge below
            else:
                assert high < 0, (row.task, header)
    edges = _edges("study.md")
    assert "walker2d FPPO-QP" in edges and edges.count("FPPO-") == 1


def test_every_p_dose_interval_on_final_returns_holds_half():
    _quoted("every P(dose > PPO) interval holds 0.5", "docs/results.md")
    _quoted("each P(dose > PPO) interval holds 0.5", "experiments/README.md")
    rows = [
        r
        for r in _rows()
        if r.report == "experiments/results/dose_response.md"
        and "P(> PPO), final [95% CI] (" in "".join(r)
    ]
    cells = [r.cell("P(> PPO), final [95% CI]") for r in rows if r.variant != "ppo"]
    assert len(cells) == 22
    assert all(low < 0.5 < high for _, low, high in map(_interval, cells))
    assert "P(> PPO), final" not in _edges("dose_response.md")


def test_no_steps_trend_excludes_zero_and_one_is_at_the_edge():
    _quoted(
        "no interval excludes 0, and one is at the edge of it (FPPO-QP's to 80% on Walker2d",
        "experiments/README.md",
    )
    rows = [
        r
        for r in _rows()
        if r.report == "experiments/results/dose_response.md"
        and "steps to 80% of PPO (" in "".join(r)
    ]
    assert len(rows) == 4
    for row in rows:
        for header in ("steps to 50% of PPO", "steps to 80% of PPO"):
            _, low, high = _interval(row.cell(header))
            assert low <= 0 <= high
    assert "walker2d fppo-qp, steps to 80% of PPO" in _edges("dose_response.md")


def test_none_of_the_library_s_24_comparisons_is_decided():
    _quoted("none of its 24 comparisons is decided", "docs/results.md")
    decisions = [
        r.cell("decision")
        for r in _rows()
        if r.report.startswith("experiments/results/study-command/") and "decision (" in "".join(r)
    ]
    assert decisions == ["undecided"] * 24


def test_every_spo_and_dpo_run_on_ant_ends_below_every_ppo_run():
    _quoted("on Ant, where every SPO and DPO run ends below every PPO run", "docs/results.md")
    rows = [
        r
        for r in _rows()
        if r.report == "experiments/results/spo-dpo.md" and r.task == "ant" and "text" not in r
    ]
    assert [_interval(r.cell("P(> ppo), final [95% CI]")) for r in rows] == [(0.0, 0.0, 0.0)] * 2


def _tuned_rows(header: str) -> list[Row]:
    """The rows of tuned.md's tables that have a column `header`."""
    return [
        r
        for r in _rows()
        if r.report == "experiments/results/tuned.md"
        and any(k.startswith(f"{header} (") for k in r)
    ]


def test_ten_of_the_13_tuned_mujoco_decisions_stand_in_the_plan_s_family():
    _quoted(
        "decided as the plan's family of 15 on the same runs, 10 of their 13 decisions stand and "
        "3 are not reached, undecided at the seeds their studies ran",
        "docs/results.md",
    )
    rows = _tuned_rows("the plan's family of 15, at the seeds run")
    assert len(rows) == 15
    decided = [
        (
            r.task,
            r.cell("candidate"),
            r.cell("the plan's family of 15, at the seeds run").split(":")[0],
        )
        for r in rows
        if r.cell("its task's study, a family of 5").split(" ")[0]
        in ("better", "worse", "equivalent")
    ]
    assert len(decided) == 13
    assert [d for d in decided if d[2] != "stands"] == [
        ("hopper", "fppo-lp", "not reached"),
        ("hopper", "fppo-qp", "not reached"),
        ("swimmer", "spo", "not reached"),
    ]


def test_which_tuned_variant_is_better_than_tuned_ppo_where():
    _quoted(
        "FPPO-QP is equivalent to tuned PPO or undecided on each of the six tasks tested, and "
        "FPPO-LP is better only on HalfCheetah",
        "docs/results.md",
    )
    _quoted(
        "SPO is better on HalfCheetah, against a PPO that tuning left below its default there, "
        "and DPO on Swimmer; neither is better on Hopper or a classic task",
        "docs/results.md",
    )
    rows = _tuned_rows("decision against tuned PPO")
    decided = {
        (r.task, r.cell("candidate")): r.cell("decision against tuned PPO").split(" ")[0]
        for r in rows
    }
    assert len(decided) == 30  # 5 candidates on each of the six tasks
    fppo_qp = {d for (_, candidate), d in decided.items() if candidate == "fppo-qp"}
    assert fppo_qp <= {"equivalent", "undecided"}
    better = sorted(key for key, d in decided.items() if d == "better")
    assert [k for k in better if k[1] in ("fppo-lp", "spo", "dpo")] == [
        ("halfcheetah", "fppo-lp"),
        ("halfcheetah", "spo"),
        ("swimmer", "dpo"),
    ]


def test_the_readme_s_headline_table_is_the_tuned_verdict_s():
    """Each cell of the README's table of FPPO against tuned PPO is tuned.md's row for its task
    and candidate (the plan's family's decision, P(candidate > PPO) as printed and the seeds it
    holds), and the counts the paragraph above it gives are those of the table."""
    recorded = {
        (r.task, r.cell("candidate")): (
            r.cell("decision against tuned PPO").split(" ")[0],
            r.cell("P(candidate > PPO), eval"),
            r.cell("seeds"),
        )
        for r in _tuned_rows("decision against tuned PPO")
        if r.cell("candidate") in ("fppo-lp", "fppo-qp")
    }
    assert len(recorded) == 12
    text = _path("README.md").read_text()
    header = "| task | FPPO-LP against tuned PPO | FPPO-QP against tuned PPO |"
    assert header in text
    rows = text.split(header)[1].split("\n\n")[0].splitlines()[2:]
    cell = re.compile(r"(\w+): (\d\.\d\d \[\d\.\d\d, \d\.\d\d\]), (\d+) seeds")
    quoted = {}
    for row in rows:
        task, *cells = (c.strip() for c in row.strip("|").split("|"))
        for candidate, written in zip(("fppo-lp", "fppo-qp"), cells, strict=True):
            found = cell.fullmatch(written)
            assert found, written
            quoted[task.lower(), candidate] = found.groups()
    assert quoted == recorded
    decisions = [decision for decision, _, _ in recorded.values()]
    counts = {d: decisions.count(d) for d in ("better", "equivalent", "undecided", "worse")}
    assert counts == {"better": 1, "equivalent": 5, "undecided": 6, "worse": 0}
    _quoted(
        "Of FPPO's 12 comparisons with tuned PPO (FPPO-LP and FPPO-QP on six tasks), one is "
        "better: FPPO-LP on HalfCheetah",
        "README.md",
    )
    _quoted("Five are equivalent to tuned PPO", "README.md")
    _quoted("six are undecided at the seeds their studies ran, and none is worse", "README.md")
    assert [k for k, (d, _, _) in recorded.items() if d == "better"] == [("halfcheetah", "fppo-lp")]
