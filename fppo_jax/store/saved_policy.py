"""A trained policy saved on its own, an artifact (:mod:`fppo_jax.store.artifact`):
``<directory>/policy.json`` (its description, the run's configuration and a SHA-256 digest of its
arrays) and ``<directory>/policy.npz`` (the arrays, named by their paths), each written to a
temporary name and renamed, the record last; ``policy.json`` names its layout (:data:`FORMAT`),
and one of another layout is refused, not taken for damage. :func:`load_policy` reads a saved
policy, or the policy of a run's newest readable checkpoint (:mod:`fppo_jax.store.checkpoint`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal, TypedDict, cast

import jax
from flax.traverse_util import flatten_dict, unflatten_dict

from fppo_jax.core.policy import Policy, PolicyDescription
from fppo_jax.errors import InvalidInput, MissingFile, first_line
from fppo_jax.store import artifact
from fppo_jax.store.artifact import DamagedArtifact
from fppo_jax.store.checkpoint import CheckpointRecord, Checkpoints
from fppo_jax.store.files import tree_digest

POLICY_FILE, ARRAYS_FILE = "policy.json", "policy.npz"
# The layout of policy.json and policy.npz (files.check_format; numpy_policy reads it too).
FORMAT = 1


class PolicyOrigin(TypedDict):
    """The run a saved policy comes from: its record as JSON
    (:meth:`~fppo_jax.store.record.RunRecord.to_json`) and the update it ended at."""

    config: dict[str, Any]
    update: int


class SavedPolicyRecord(PolicyOrigin):
    """``policy.json``: the :class:`PolicyOrigin`, its kind (``"policy"``), its layout, the
    policy's description and the digest of its arrays."""

    kind: Literal["policy"]
    format: int
    policy: PolicyDescription
    digest: str


def save_policy(
    directory: str | Path,
    policy: Policy,
    record: PolicyOrigin,
    *,
    overwrite: bool = False,
) -> Path:
    """Write `policy` and `record` (the run's ``config`` and its ``update``) to `directory` as
    ``policy.json`` and ``policy.npz``; a saved policy already there is refused unless
    `overwrite`. Returns the directory."""
    directory = Path(directory)
    check_no_saved_policy(directory, overwrite)
    arrays = flatten_dict(jax.device_get(policy.arrays()), sep="/")
    saved = artifact.seal(
        {**record, "kind": "policy"},
        FORMAT,
        policy=policy.describe(),
        digest=tree_digest(arrays),
    )
    # policy.json last: it marks the directory as a saved policy, and an overwrite killed
    # between the two renames leaves arrays that fail its digest, never a wrong policy.
    artifact.write(directory, POLICY_FILE, saved, {ARRAYS_FILE: artifact.arrays_file(arrays)})
    return directory


def check_no_saved_policy(
    directory: str | Path, overwrite: bool = False, *, replace: str = "pass overwrite=True"
) -> None:
    """Raise InvalidInput if `directory` holds a saved policy and not `overwrite`; the message
    says how to replace it (`replace`: the Python way unless told)."""
    if not overwrite and (Path(directory) / POLICY_FILE).exists():
        raise InvalidInput(
            f"{directory} already holds a saved policy; {replace} to replace it, or choose "
            "another directory"
        )


def load_policy(directory: str | Path) -> Policy:
    """The trained policy in `directory`, as a :class:`~fppo_jax.core.policy.Policy`: an inference
    function of raw observations that needs neither the trainer nor the environment.
    `directory` holds a saved policy (``TrainResult.save``) or the checkpoints of
    :func:`fppo_jax.train` (``checkpoint_dir``), whose newest readable one is used."""
    return read_policy(directory)[0]


def read_policy(directory: str | Path) -> tuple[Policy, SavedPolicyRecord | CheckpointRecord]:
    """The policy in `directory` and the record of its run (``config``, ``update``, ``kind``:
    ``"policy"`` for a saved policy, ``"train"`` for a checkpoint)."""
    directory = Path(directory)
    if directory.is_file():
        raise MissingFile(
            f"{directory} is a file: name the directory that holds a saved policy "
            f"({POLICY_FILE} and {ARRAYS_FILE}) or a run's checkpoints"
        )
    if not directory.is_dir():
        raise MissingFile(f"policy or checkpoint directory {directory} not found")
    if (directory / POLICY_FILE).exists():
        return _read_saved_policy(directory)
    checkpoints = Checkpoints(directory)
    try:
        if not checkpoints.steps():
            raise MissingFile(
                f"{directory} holds neither a saved policy ({POLICY_FILE} and {ARRAYS_FILE}) "
                "nor checkpoints"
            )
        return checkpoints.policy()
    finally:
        checkpoints.close()


def _read_saved_policy(directory: Path) -> tuple[Policy, SavedPolicyRecord]:
    what = f"the saved policy in {directory}"
    try:
        saved = artifact.read_record(directory / POLICY_FILE, what, FORMAT)
    except DamagedArtifact as error:
        raise _damaged(directory, error) from error
    try:
        arrays = artifact.read_arrays(directory / ARRAYS_FILE, saved["digest"])
        policy = Policy.from_parts(saved["policy"], unflatten_dict(arrays, sep="/"))
    except Exception as error:  # any failure to read back is damage
        raise _damaged(directory, error) from error
    return policy, cast(SavedPolicyRecord, saved)


def _damaged(directory: Path, error: Exception) -> DamagedArtifact:
    return DamagedArtifact(
        f"the saved policy in {directory} is damaged ({type(error).__name__}: {first_line(error)})"
    )
