"""fppo_jax.store.sweep_files: a sweep's curves.csv and sweep.json read back whole, in any order of
rows and columns, and every flaw refused with its file named."""

import csv
import hashlib
import json
import random
import re

import numpy as np
import pytest
from helpers import sweep_by_hand

from fppo_jax import METRICS, IncompatibleFormat, SweepResult
from fppo_jax.cli import main


def rewrite_curves(directory, change) -> None:
    """`curves.csv` in `directory` as `change(header, rows)` makes it, lists of cells, and its
    digest in `sweep.json`: a pair that belongs together, whose curves are wrong."""
    path = directory / "curves.csv"
    with open(path, newline="") as f:
        header, *rows = list(csv.reader(f))
    with open(path, "w", newline="") as f:
        csv.writer(f).writerows(change(header, rows))
    rewrite_record(directory, "curves_sha256", hashlib.sha256(path.read_bytes()).hexdigest())


def rewrite_record(directory, key, value) -> None:
    """`sweep.json` in `directory` with `key` set to `value`, or removed if `value` is None."""
    path = directory / "sweep.json"
    record = json.loads(path.read_text())
    record.pop(key) if value is None else record.update({key: value})
    path.write_text(json.dumps(record))


def test_curves_are_read_by_run_and_update_in_any_order(tmp_path):
    result = sweep_by_hand()
    result.write(tmp_path)
    rewrite_curves(tmp_path, lambda h, r: [h, *random.Random(0).sample(r, len(r))])
    back = SweepResult.read(tmp_path)
    for name in METRICS:
        np.testing.assert_array_equal(back.metrics[name], result.metrics[name])
    assert back.table() == result.table()


def cell(row: int, column: str, value: str):
    """A change that puts `value` in one cell."""

    def change(header, rows):
        rows[row][header.index(column)] = value
        return [header, *rows]

    return change


def test_a_chosen_metric_is_one_the_sweep_has_and_env_steps_always_comes_along(tmp_path):
    result = sweep_by_hand()
    with pytest.raises(ValueError, match="no metric 'nonesuch' in this sweep; it has "):
        result.write(tmp_path / "unknown", metrics=["nonesuch"])
    assert not (tmp_path / "unknown" / "curves.csv").exists()
    result.write(tmp_path, metrics=["average_return"])
    back = SweepResult.read(tmp_path)
    assert set(back.metrics) == {"env_steps", "average_return"}
    np.testing.assert_array_equal(back.metrics["env_steps"], result.metrics["env_steps"])


@pytest.mark.parametrize(
    "change, match",
    [
        (lambda h, r: [["step" if c == "update" else c for c in h], *r], "has no update column"),
        (lambda h, r: [h], "has no rows"),
        (lambda h, r: [h, *r[:-3]], "has no rows for run 8 of sweep.json's 9"),
        (lambda h, r: [h, *r, ["9", *r[0][1:]]], "has rows for run 9; sweep.json has 9 runs"),
        (lambda h, r: [h, *r[:13], *r[14:]], "run 4 has no update 2 \\(the file goes to update 3"),
        (lambda h, r: [h, *r, r[0]], "line 29: run 0, update 1 a second time"),
        (lambda h, r: [h, r[0][:-1], *r[1:]], "line 2: not one value per column of the header"),
        (cell(4, "average_return", "many"), "line 6: average_return is 'many', not a number"),
        (cell(0, "run", "first"), "line 2: run is 'first', not an integer"),
        (cell(0, "update", "0"), "line 2: update 0, but updates count from 1"),
        (cell(3, "seed", "7"), "line 5: run 1 has seed 7, sweep.json 1"),
    ],
)
def test_malformed_curves_are_refused_saying_what_is_wrong(tmp_path, change, match):
    sweep_by_hand().write(tmp_path)
    rewrite_curves(tmp_path, change)
    with pytest.raises(ValueError, match=re.escape(str(tmp_path / "curves.csv")) + ".*" + match):
        SweepResult.read(tmp_path)


def refused(directory, name, message, capsys) -> None:
    """Reading the sweep in `directory` raises a ValueError that starts with the path of its
    file `name` and says `message`; ``fppo-jax table`` prints that as its one line of error."""
    with pytest.raises(ValueError) as raised:
        SweepResult.read(directory)
    error = str(raised.value)
    assert error.startswith(str(directory / name)) and message in error, error
    assert main(["table", str(directory)]) == 2
    assert capsys.readouterr() == ("", f"fppo-jax: error: {error}\n")


@pytest.mark.parametrize(
    "damage, message",
    [
        (lambda t: t[: len(t) // 2], " is not valid JSON (Unterminated string"),
        (lambda t: "\udcff" + t, " is not valid JSON ('utf-8' codec can't decode byte 0xff"),
        (lambda t: "[1, 2]", " holds a list, not a sweep's record (an object)"),
        (
            lambda t: t.replace('"runs"', '"rungs"').replace('"diverged"', '"x"'),
            " has no runs, diverged",
        ),
        (
            lambda t: t.replace("1.3", '"1.3"'),
            '"alpha": "1.3..., not a list of settings, each a variant and numbers',
        ),
        (
            lambda t: t.replace('"setting": 2', '"setting": 3'),
            ", not a list of runs, each a setting (an index into settings) and a seed",
        ),
        (
            lambda t: t.replace('"diverged": [0, ', '"diverged": ['),
            ": diverged is [3, 2, 3, 2, 3, 0, 0, 0], not a list of one update (from 1, or 0) "
            "per run",
        ),
        (
            lambda t: t.replace('"seeds": [0', '"seeds": [null'),
            ": seeds is [null, 1, 2], not a list of integers",
        ),
        (
            lambda t: t.replace('"env"', '"task"'),
            ': config is {"task": "cartpole"}, not an object naming the env',
        ),
        (
            lambda t: t.replace('"train_seconds": 0.0', '"train_seconds": "0"'),
            ': train_seconds is "0", not a number',
        ),
        (
            lambda t: t.replace('"curves_sha256": "', '"curves_sha256": "x'),
            ", not a SHA-256 digest in hex",
        ),
    ],
)
def test_a_damaged_sweep_json_is_refused_saying_what_is_wrong(tmp_path, damage, message, capsys):
    sweep_by_hand().write(tmp_path)
    path = tmp_path / "sweep.json"
    text = json.dumps(json.loads(path.read_text()))  # on one line, to edit
    path.write_bytes(damage(text).encode(errors="surrogateescape"))
    refused(tmp_path, "sweep.json", message, capsys)


def test_a_sweep_record_names_its_format_and_one_of_another_is_refused_not_damaged(tmp_path):
    result = sweep_by_hand()
    result.write(tmp_path)
    assert json.loads((tmp_path / "sweep.json").read_text())["format"] == 1
    rewrite_record(tmp_path, "format", None)  # as written before records named their format
    assert SweepResult.read(tmp_path).table() == result.table()
    rewrite_record(tmp_path, "format", 2)
    before = {f.name: f.read_bytes() for f in tmp_path.iterdir()}
    message = r"sweep record .*sweep\.json was written by a newer version of fppo-jax \(format 2"
    with pytest.raises(IncompatibleFormat, match=message):
        SweepResult.read(tmp_path)
    assert {f.name: f.read_bytes() for f in tmp_path.iterdir()} == before  # left as it was


def test_curves_not_written_with_the_sweep_json_beside_them_are_refused(tmp_path, capsys):
    # A sweep stopped between its two renames: the newer curves.csv, the older sweep.json. The
    # curves are whole and of the same runs, so only the runs' digests tell the pair apart.
    older, newer = sweep_by_hand(), sweep_by_hand()
    newer.metrics["average_return"] = newer.metrics["average_return"] + 1
    older.write(tmp_path)
    newer.write(tmp_path / "newer")
    (tmp_path / "newer" / "curves.csv").replace(tmp_path / "curves.csv")
    message = (
        ": the rows of run 0, 1, 2, 3, 4 and 4 more are not those "
        f"{tmp_path / 'sweep.json'} was written with (their digests differ)"
    )
    refused(tmp_path, "curves.csv", message, capsys)
    rewrite_record(tmp_path, "run_digests", None)  # a record from before runs had digests
    rewrite_record(tmp_path, "digest_columns", None)
    refused(tmp_path, "curves.csv", " is not the curves.csv that", capsys)
    rewrite_record(tmp_path, "curves_sha256", None)  # nor is a record without the digest read
    refused(tmp_path, "sweep.json", " has no curves_sha256", capsys)


def test_curves_re_sorted_reordered_or_filtered_still_give_their_runs(tmp_path):
    result = sweep_by_hand()
    result.write(tmp_path)
    with open(tmp_path / "curves.csv", newline="") as f:
        header, *rows = list(csv.reader(f))
    # As pandas might leave it: columns in another order, rows sorted by another column.
    order = [header.index(c) for c in reversed(header)]
    rows = sorted(rows, key=lambda r: (r[header.index("update")], r[header.index("run")]))
    with open(tmp_path / "curves.csv", "w", newline="") as f:
        csv.writer(f).writerows([[row[i] for i in order] for row in [header, *rows]])
    back = SweepResult.read(tmp_path)
    for name in METRICS:
        np.testing.assert_array_equal(back.metrics[name], result.metrics[name])
    assert back.table("iqm") == result.table("iqm")
    # Filtered to tr-ppo's runs (6, 7, 8): those runs, and a warning that says so.
    kept = [r for r in rows if r[header.index("run")] in {"6", "7", "8"}]
    with open(tmp_path / "curves.csv", "w", newline="") as f:
        csv.writer(f).writerows([header, *kept])
    with pytest.warns(UserWarning, match="holds rows for 3 of the 9 runs"):
        only = SweepResult.read(tmp_path)
    assert only.runs == result.runs[6:] and only.diverged.tolist() == [0, 0, 0]
    np.testing.assert_array_equal(
        only.metrics["average_return"], result.metrics["average_return"][6:]
    )
    assert only.table().splitlines()[-1] == result.table().splitlines()[-1]
    # A value changed in one run is caught by that run's digest.
    kept[0][header.index("average_return")] = "11.0"
    with open(tmp_path / "curves.csv", "w", newline="") as f:
        csv.writer(f).writerows([header, *kept])
    with pytest.raises(ValueError, match="the rows of run 6 are not those"):
        SweepResult.read(tmp_path)


def test_a_diverged_update_past_the_curves_is_refused(tmp_path):
    sweep_by_hand().write(tmp_path)
    rewrite_record(tmp_path, "diverged", [0, 3, 2, 3, 2, 9, 0, 0, 0])
    with pytest.raises(ValueError, match="diverged says run 5 diverged after the last of the 3"):
        SweepResult.read(tmp_path)
