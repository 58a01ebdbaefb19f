import errno
import os
import subprocess
import sys
import textwrap

import pytest
from conftest import TINY

from fppo_jax import train
from fppo_jax.store.checkpoint_writes import (
    CheckpointNotWritten,
    Writes,
    _storage_failure,
    _storage_reason,
)

RUN = {"env": "cartpole", "variant": "fppo-qp", "seed": 3, "total_steps": 128 * 20, **TINY}


class LosesWrites:
    """Orbax's manager as it is when a write fails in its background thread: it logs the
    failure there, says it has finished, and the step is not on disk."""

    def __init__(self, steps):
        self.steps = list(steps)

    def save(self, step, args):
        return True

    def wait_until_finished(self):
        pass

    def is_saving_in_progress(self):
        return False

    def reload(self):
        pass

    def all_steps(self):
        return self.steps


@pytest.mark.parametrize(
    "kept, newest", [([1], "the newest intact one is step 1"), ([], "none is intact")]
)
def test_a_write_lost_in_the_background_is_one_error_naming_the_newest_intact_step(
    tmp_path, kept, newest
):
    writes = Writes(LosesWrites(kept), tmp_path)
    writes.start(2, args=None)
    with pytest.raises(
        CheckpointNotWritten, match=rf"\(step 2 is not on disk after writing it\); {newest}\."
    ):
        writes.wait()
    writes.wait()  # said once


@pytest.mark.parametrize(
    "error, reason",
    [
        (OSError(errno.ENOSPC, os.strerror(errno.ENOSPC)), os.strerror(errno.ENOSPC)),
        (ValueError("tensorstore: [os_error_code='27'] write failed"), os.strerror(27)),
    ],
)
def test_storage_refusing_a_write_is_told_in_the_operating_systems_words(error, reason):
    assert _storage_failure(error) and _storage_reason(error) == reason


def test_other_failures_of_a_write_are_not_storages():
    assert not _storage_failure(ValueError("a bug"))


def test_a_checkpoint_storage_refuses_is_one_error_naming_the_newest_intact_one(tmp_path):
    # Storage that refuses writes, as a full disk does: a file size limit set after the first
    # checkpoint (a write past it fails with EFBIG; the signal it would send is ignored).
    program = textwrap.dedent(f"""
        import resource, signal, sys
        import fppo_jax
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        def refuse(snapshot):
            if snapshot.update == 4:  # checkpoint 4 is being written in the background
                resource.setrlimit(resource.RLIMIT_FSIZE, (1000, resource.RLIM_INFINITY))
        try:
            fppo_jax.train(**{RUN!r}, checkpoint_dir={str(tmp_path)!r}, checkpoint_every=1,
                           keep=10, callback=refuse)
        except fppo_jax.CheckpointNotWritten as error:
            print(error)
            print(sys.unraisablehook is sys.__unraisablehook__)  # the library installs none
            sys.exit(3)
    """)
    done = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True)
    assert done.returncode == 3, done.stderr[-3000:]
    assert done.stdout == (
        f"could not write a checkpoint in {tmp_path} (File too large); the newest intact one is "
        "step 3. Free space, or choose another checkpoint directory, and resume (--resume)\n"
        "True\n"
    )
    # What else stderr holds is orbax's own report of the failed write, at its own level.
    assert sorted(int(p.name) for p in tmp_path.iterdir() if p.name.isdigit()) == [1, 2, 3]
    resumed = train(**RUN, checkpoint_dir=tmp_path, resume=True, checkpoint_every=1, keep=10)
    assert resumed.resumed_from == 3 and len(resumed.metrics["env_steps"]) == 20
