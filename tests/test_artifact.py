"""fppo_jax.store.artifact: a record and its data written whole, the record last, and read back
checked: damage named, another layout refused and left as it is, a damaged one set aside."""

import json

import numpy as np
import pytest

from fppo_jax import IncompatibleFormat
from fppo_jax.store import artifact
from fppo_jax.store.artifact import DamagedArtifact
from fppo_jax.store.files import tree_digest

ARRAYS = {"a/b": np.arange(6, dtype=np.float32).reshape(2, 3), "c": np.array([1, 2], np.int64)}


def write(directory, format=1):
    record = artifact.seal(
        {"config": {"sizes": (8,), "k": np.float32(0.5)}}, format, digest=tree_digest(ARRAYS)
    )
    artifact.write(directory, "thing.json", record, {"thing.npz": artifact.arrays_file(ARRAYS)})


def test_an_artifact_round_trips_with_its_format_first_and_values_as_json_has_them(tmp_path):
    write(tmp_path / "new" / "dir")
    where = tmp_path / "new" / "dir"
    assert sorted(p.name for p in where.iterdir()) == ["thing.json", "thing.npz"]  # no leftovers
    record = artifact.read_record(where / "thing.json", "the thing", 1)
    assert list(record) == ["format", "config", "digest"]
    assert record == {
        "format": 1,
        "config": {"sizes": [8], "k": 0.5},
        "digest": tree_digest(ARRAYS),
    }
    arrays = artifact.read_arrays(where / "thing.npz", record["digest"])
    assert set(arrays) == set(ARRAYS)
    for name, values in ARRAYS.items():
        np.testing.assert_array_equal(arrays[name], values)
        assert arrays[name].dtype == values.dtype


@pytest.mark.parametrize(
    "text, message",
    [("{", "is not valid JSON"), ("[1]", "holds a list, not an object")],
)
def test_a_record_that_is_not_a_json_object_is_damage_naming_the_file(tmp_path, text, message):
    write(tmp_path)
    (tmp_path / "thing.json").write_text(text)
    with pytest.raises(DamagedArtifact, match=f"{tmp_path / 'thing.json'} {message}"):
        artifact.read_record(tmp_path / "thing.json", "the thing", 1)


def test_data_that_do_not_match_their_digest_are_damage(tmp_path):
    write(tmp_path)
    digest = artifact.read_record(tmp_path / "thing.json", "the thing", 1)["digest"]
    with open(tmp_path / "thing.npz", "wb") as file:
        np.savez(file, **{**ARRAYS, "c": ARRAYS["c"] + 1})  # well formed, other values
    with pytest.raises(DamagedArtifact, match="its arrays do not match the digest written"):
        artifact.read_arrays(tmp_path / "thing.npz", digest)
    with pytest.raises(DamagedArtifact, match="its state arrays do not match"):
        artifact.verify(ARRAYS, digest[::-1], "state")
    artifact.verify(ARRAYS, digest)


def test_a_record_of_another_format_is_refused_and_one_without_is_the_first(tmp_path):
    write(tmp_path, format=3)
    before = (tmp_path / "thing.json").read_bytes()
    with pytest.raises(IncompatibleFormat, match=r"the thing was written by a newer .*format 3"):
        artifact.read_record(tmp_path / "thing.json", "the thing", (1, 2))
    assert (tmp_path / "thing.json").read_bytes() == before  # left as it is
    record = json.loads(before)
    del record["format"]
    (tmp_path / "thing.json").write_text(json.dumps(record))
    assert "format" not in artifact.read_record(tmp_path / "thing.json", "the thing", 1)


def test_a_damaged_artifact_is_set_aside_beside_it_replacing_one_set_aside_before(tmp_path):
    for content in ("first", "second"):
        write(tmp_path / "4")
        (tmp_path / "4" / "note").write_text(content)
        assert artifact.set_aside(tmp_path / "4") == tmp_path / "damaged" / "4"
        assert not (tmp_path / "4").exists()
    assert (tmp_path / "damaged" / "4" / "note").read_text() == "second"
