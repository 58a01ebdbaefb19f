"""fppo_jax.store.files: writable directories, one writer per directory, whole-or-nothing writes,
JSON as written, array digests and one-line error messages."""

import errno
import hashlib
import json
import os
import threading

import jax.numpy as jnp
import numpy as np
import pytest

from fppo_jax.store.files import (
    DirectoryBusy,
    DirectoryLock,
    DirectoryLost,
    NotWritten,
    json_value,
    tree_digest,
    writable_directory,
    write_atomically,
    write_json,
)


def test_writable_directory_makes_missing_parents_and_refuses_a_file(tmp_path):
    made = writable_directory(str(tmp_path / "a" / "b"))
    assert made == tmp_path / "a" / "b" and made.is_dir() and not any(made.iterdir())
    assert writable_directory(made) == made  # an existing one is fine
    (tmp_path / "file").write_text("x")
    with pytest.raises(ValueError, match=f"cannot write to {tmp_path / 'file'}: it is not a direc"):
        writable_directory(tmp_path / "file")


def test_write_atomically_replaces_the_file_whole_and_leaves_no_temporary(tmp_path):
    path = tmp_path / "data.bin"
    write_atomically(path, b"first")
    write_atomically(path, b"second, longer")
    assert path.read_bytes() == b"second, longer"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["data.bin"]


def test_a_write_that_fails_leaves_the_previous_file_as_it_was(tmp_path, monkeypatch):
    path = tmp_path / "record.json"
    write_json(path, {"update": 1})
    with pytest.raises(TypeError):
        write_atomically(path, "not bytes")  # fails mid-write, after the file was opened
    with pytest.raises(TypeError, match="object is not JSON-serialisable"):
        write_json(path, {"update": object()})

    def fail(*_):
        raise OSError("disk full")

    monkeypatch.setattr(os, "fsync", fail)  # fails before the rename
    with pytest.raises(OSError, match="disk full"):
        write_json(path, {"update": 2})
    assert json.loads(path.read_text()) == {"update": 1}


def full_disk(*_):
    """What a full disk gives a write: the system's error, which names no file."""
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def test_a_full_disk_is_one_line_naming_the_file_and_leaves_no_part_of_it(tmp_path, monkeypatch):
    path = tmp_path / "record.json"
    write_json(path, {"update": 1})
    monkeypatch.setattr(os, "fsync", full_disk)
    with pytest.raises(NotWritten) as refused:
        write_json(path, {"update": 2})
    assert str(refused.value) == f"cannot write {path}: No space left on device"
    assert isinstance(refused.value, OSError)  # as the system's error was
    assert json.loads(path.read_text()) == {"update": 1}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["record.json"]  # no temporary


def test_a_command_that_finds_the_disk_full_says_so_in_one_line(tmp_path, monkeypatch, capsys):
    from fppo_jax.cli import main

    monkeypatch.setattr(os, "fsync", full_disk)
    output = tmp_path / "tune"
    flags = ["--variants", "ppo", "--tasks", "cartpole", "--trials", "4", "--eta", "2"]
    flags += ["--steps", "1024", "--num-envs", "4", "--num-steps", "32", "--quiet"]
    assert main(["tune", *flags, "--output", str(output)]) == 2  # its plan, before any run
    assert capsys.readouterr().err == (
        f"fppo-jax: error: cannot write {output / 'tune.json'}: No space left on device\n"
    )


def test_write_json_writes_indented_json_with_numpy_scalars_as_numbers(tmp_path):
    path = tmp_path / "config.json"
    write_json(path, {"k": np.float32(0.5), "n": np.int64(3), "sizes": (64, 64), "ok": np.True_})
    lines = ["{", '  "k": 0.5,', '  "n": 3,', '  "sizes": [', "    64,", "    64", "  ],"]
    assert path.read_text() == "\n".join([*lines, '  "ok": true', "}", ""])


def test_json_value_is_what_reading_the_written_file_gives(tmp_path):
    value = {"sizes": (64, (1, 2)), "k": np.float32(0.25), "seed": np.uint64(2**63), "x": None}
    assert json_value(value) == {"sizes": [64, [1, 2]], "k": 0.25, "seed": 2**63, "x": None}
    write_json(tmp_path / "v.json", value)
    assert json.loads((tmp_path / "v.json").read_text()) == json_value(value)
    assert json_value(value) != value  # tuples became lists: compare json_value with a file's


def test_tree_digest_is_the_sha256_of_each_leafs_path_dtype_shape_and_bytes():
    tree = {"b": np.arange(6, dtype=np.float32).reshape(2, 3), "a": [np.array([7], np.int32)]}
    sha = hashlib.sha256()
    sha.update(b"['a'][0] int32 (1,)")
    sha.update(np.int32(7).tobytes())
    sha.update(b"['b'] float32 (2, 3)")
    sha.update(np.arange(6, dtype=np.float32).tobytes())
    assert tree_digest(tree) == sha.hexdigest()
    # The same arrays on a device, or not contiguous on the host, have the same digest.
    on_device = {"b": jnp.asarray(tree["b"]), "a": [jnp.array([7], jnp.int32)]}
    assert tree_digest(on_device) == sha.hexdigest()
    transposed = np.asfortranarray(tree["b"])
    assert tree_digest({"b": transposed, "a": tree["a"]}) == sha.hexdigest()


def test_tree_digest_tells_apart_values_names_dtypes_and_shapes_with_the_same_bytes():
    x = np.arange(4, dtype=np.float32)
    digests = {
        tree_digest({"x": x}),
        tree_digest({"x": x + 1}),
        tree_digest({"y": x}),
        tree_digest({"x": x.view(np.int32)}),  # the same bytes, another dtype
        tree_digest({"x": x.reshape(2, 2)}),  # the same bytes, another shape
        tree_digest({"x": x[:2], "y": x[2:]}),  # the same bytes, split
    }
    assert len(digests) == 6


def test_one_lock_per_directory_until_released(tmp_path):
    held = DirectoryLock(tmp_path, "checkpoints")
    assert (tmp_path / ".lock").read_text() == f"{os.getpid()}\n"
    message = (
        rf"another process \(pid {os.getpid()}\) is writing checkpoints in {tmp_path}; wait "
        "for it to end, or choose another directory"
    )
    with pytest.raises(DirectoryBusy, match=message):
        DirectoryLock(tmp_path, "checkpoints")
    assert issubclass(DirectoryBusy, ValueError)
    held.release()
    held.release()  # twice is harmless
    again = DirectoryLock(tmp_path, "checkpoints")
    # A holder that takes its turn is waited for, as long as asked; then it is busy.
    threading.Timer(0.3, again.release).start()
    waited = DirectoryLock(tmp_path, "checkpoints", wait=30)
    with pytest.raises(DirectoryBusy, match=message):
        DirectoryLock(tmp_path, "checkpoints", wait=0.2)
    waited.release()


def test_a_lock_notices_its_directory_vanishing_or_replaced(tmp_path):
    directory, elsewhere = tmp_path / "logs", tmp_path / "moved"
    directory.mkdir()
    lock = DirectoryLock(directory, "a run's outputs")
    lock.check()  # still there
    directory.rename(elsewhere)
    message = f"{directory}, where this run writes a run's outputs, vanished or was replaced"
    with pytest.raises(DirectoryLost, match=message):
        lock.check()  # vanished
    directory.mkdir()  # another directory of the same name
    with pytest.raises(DirectoryLost, match=message):
        lock.check()
    directory.rmdir()
    elsewhere.rename(directory)  # the one locked, back in its place
    lock.check()
    lock.release()


def test_a_lock_on_a_full_disk_is_refused_naming_its_file_and_holds_nothing(tmp_path, monkeypatch):
    def full(*_):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))  # as a write names no file

    with monkeypatch.context() as patch:
        patch.setattr(os, "pwrite", full)
        with pytest.raises(NotWritten, match=f"cannot write {tmp_path / '.lock'}: No space left"):
            DirectoryLock(tmp_path, "a tune")
    DirectoryLock(tmp_path, "a tune").release()  # the refused lock was let go
