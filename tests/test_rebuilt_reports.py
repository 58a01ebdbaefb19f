"""The reports built from recorded curves, rebuilt here by their own scripts and compared with
the committed files: the seed study's (``verdict.py``: ``study.md`` and the three
``study-command/<family>/report.md``), the planned verdicts (``planned_verdict.py``:
``spo-dpo.md``, ``baseline-shape.md``), the dose-response (``dose_response.py``) and the tuned
verdict (``tuned_verdict.py``: ``tuned.md``) and its second plan's parts so far
(``tuned_v2.py``: ``tuned-v2.md``). Nothing
is trained; the bootstrap and permutation seeds are the scripts' own, fixed, so a rebuild is
the committed text line for line but for what names when, where and at which commit it was
made. A number or decision edited by hand, or a report left stale by a change to its script,
fails here until the script writes the file again.

About a minute and a half on a 2-core CPU, most of it ``verdict.py``'s three library studies."""

from __future__ import annotations

import difflib
import re
import shutil
from pathlib import Path

import pytest
from helpers import run_script

EXPERIMENTS = Path(__file__).resolve().parent.parent / "experiments"
RESULTS = EXPERIMENTS / "results"
STUDY_COMMAND = ("mujoco", "classic", "classic-unnormalised")
REPORTS = (
    "study.md",
    *(f"study-command/{family}/report.md" for family in STUDY_COMMAND),
    "spo-dpo.md",
    "baseline-shape.md",
    "dose_response.md",
    "tuned.md",
    "tuned-v2.md",
)
# What a rebuild may write differently without any result changing: the header's machine, date,
# command and commit, the commit a study's plan was written at, and where its parts were read.
WHEN_AND_WHERE = re.compile(r"^- (Machine|Command): ")
COMMIT = re.compile(r"\b[0-9a-f]{40}\b")
PARTS = re.compile(r"Runs recorded under \S+ were")


def normalised(text: str) -> list[str]:
    lines = [line for line in text.splitlines() if not WHEN_AND_WHERE.match(line)]
    lines = [COMMIT.sub("<commit>", line) for line in lines]
    return [PARTS.sub("Runs recorded under <parts> were", line) for line in lines]


def differences(committed: str, rebuilt: str) -> list[str]:
    """The lines of `committed` and `rebuilt` that differ, as a unified diff (empty if none)."""
    return list(difflib.unified_diff(normalised(committed), normalised(rebuilt), lineterm="", n=0))


@pytest.fixture(scope="module")
def rebuilt(tmp_path_factory) -> Path:
    """Every report rebuilt into a temporary folder laid out as experiments/results/. The
    seed study's parts are copied there (the library's study looks for reusable runs without
    following links), so verdict.py's figures land there too and nothing under
    experiments/results/ is written."""
    out = tmp_path_factory.mktemp("rebuilt")
    shutil.copytree(RESULTS / "study", out / "study", ignore=shutil.ignore_patterns("*.png"))
    (out / "escape_speed").symlink_to(RESULTS / "escape_speed", target_is_directory=True)
    before = sorted(path.stat().st_mtime_ns for path in RESULTS.rglob("*"))
    studies = EXPERIMENTS / "studies"
    runs = [
        run_script(studies / "verdict.py", "--results", str(out), cwd=EXPERIMENTS),
        *(
            run_script(
                studies / "planned_verdict.py",
                f"plans/{plan}.json",
                "--output",
                str(out / f"{plan}.md"),
                cwd=EXPERIMENTS,
            )
            for plan in ("spo-dpo", "baseline-shape")
        ),
        run_script(
            studies / "dose_response.py",
            "--output",
            str(out / "dose_response.md"),
            cwd=EXPERIMENTS,
        ),
        run_script(
            studies / "tuned_verdict.py", "--output", str(out / "tuned.md"), cwd=EXPERIMENTS
        ),
        run_script(studies / "tuned_v2.py", "--output", str(out / "tuned-v2.md"), cwd=EXPERIMENTS),
    ]
    for done in runs:
        assert done.returncode == 0, done.stdout + done.stderr
    after = sorted(path.stat().st_mtime_ns for path in RESULTS.rglob("*"))
    assert after == before  # nothing recorded was written
    return out


@pytest.mark.parametrize("report", REPORTS)
def test_a_report_is_what_its_script_writes_from_the_recorded_curves(rebuilt, report):
    changed = differences((RESULTS / report).read_text(), (rebuilt / report).read_text())
    assert not changed, (
        f"experiments/results/{report} is not what its script writes from the recorded "
        "curves (- committed, + rebuilt); run the script again:\n" + "\n".join(changed)
    )


def test_the_comparison_catches_a_number_or_decision_edited_by_hand(rebuilt, tmp_path):
    committed = (RESULTS / "spo-dpo.md").read_text()
    rebuilt_text = (rebuilt / "spo-dpo.md").read_text()
    assert not differences(committed, rebuilt_text)
    shutil.copy(RESULTS / "spo-dpo.md", tmp_path / "spo-dpo.md")
    copy = tmp_path / "spo-dpo.md"
    # One digit of one bound: DPO's Swimmer IQM.
    assert "| 89.5 [81.8, 97.0] |" in committed
    copy.write_text(committed.replace("| 89.5 [81.8, 97.0] |", "| 89.5 [81.9, 97.0] |"))
    changed = differences(copy.read_text(), rebuilt_text)
    assert [line[0] for line in changed if line[:1] in "-+" and line[:3] not in ("---", "+++")] == [
        "-",
        "+",
    ]
    assert any("81.9" in line for line in changed) and any("81.8" in line for line in changed)
    # A decision: DPO's Swimmer verdict.
    swimmer = next(line for line in committed.splitlines() if line.startswith("| swimmer | dpo"))
    copy.write_text(committed.replace(swimmer, swimmer.replace("| better |", "| worse |")))
    assert differences(copy.read_text(), rebuilt_text)
    # What names when, where and at which commit a report was made is not a result.
    copy.write_text(
        committed.replace("- Machine: AMD EPYC", "- Machine: another").replace(
            "planned_verdict.py plans/spo-dpo.json`",
            "studies/planned_verdict.py plans/spo-dpo.json --force`, at " + "0" * 40,
        )
    )
    assert not differences(copy.read_text(), rebuilt_text)
