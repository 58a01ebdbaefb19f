"""A saved policy run with numpy alone: no JAX, no fppo-jax.

This file imports nothing but the standard library and numpy, so it can be copied beside other
code (deployment, an evaluation harness) and used there on its own::

    from numpy_policy import NumpyPolicy
    policy = NumpyPolicy.load("runs/policy")   # policy.json + policy.npz (TrainResult.save)
    action = policy(observation)               # one observation or a batch

It computes what ``fppo_jax.Policy`` computes for the most likely action, in float32:
observations normalised with the statistics training ended with, ``clip((x − μ) /
sqrt(σ² + 1e-8), −10, 10)`` (when training normalised them); then tanh hidden layers and a
linear head; then the arg max of the logits (discrete actions) or the Gaussian's mean clipped
to the action bounds (continuous ones). The arrays are checked against the SHA-256 digest
``policy.json`` records, so a damaged or edited ``policy.npz`` is refused.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import zipfile
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, cast

import numpy as np

POLICY_FILE, ARRAYS_FILE = "policy.json", "policy.npz"
FORMAT = 1
_NETWORK = "params/params/MLP_0"


@dataclasses.dataclass(frozen=True)
class NumpyPolicy:
    """The deterministic policy of a saved run: `layers` are the (kernel, bias) pairs of the
    network, hidden ones first; `obs_mean` and `obs_var` the observation statistics (None
    when training used raw observations); `low` and `high` the action bounds (None for
    discrete actions)."""

    layers: tuple[tuple[np.ndarray, np.ndarray], ...]
    obs_mean: np.ndarray | None
    obs_var: np.ndarray | None
    low: np.ndarray | None
    high: np.ndarray | None

    @property
    def observation_size(self) -> int:
        return int(self.layers[0][0].shape[0])

    @property
    def discrete(self) -> bool:
        return self.low is None

    def __call__(self, observation: np.ndarray) -> np.ndarray:
        """The most likely action for an observation (an int) or a batch of them."""
        x = np.asarray(observation, np.float32)
        if x.shape[-1:] != (self.observation_size,):
            raise ValueError(
                f"the policy takes observations of size {self.observation_size} (the last "
                f"axis), got shape {x.shape}"
            )
        if not np.isfinite(x).all():
            raise ValueError("the observation holds NaN or infinity: no action follows from it")
        if self.obs_mean is not None:
            scale = np.sqrt(cast(np.ndarray, self.obs_var) + np.float32(1e-8))
            x = np.clip((x - self.obs_mean) / scale, -10.0, 10.0).astype(np.float32)
        *hidden, (kernel, bias) = self.layers
        for w, b in hidden:
            x = np.tanh(x @ w + b)
        out = x @ kernel + bias
        if self.discrete:
            return cast(np.ndarray, np.argmax(out, axis=-1))
        return cast(np.ndarray, np.clip(out, self.low, self.high))

    @classmethod
    def load(cls, directory: str | Path) -> NumpyPolicy:
        """The policy saved in `directory` (``policy.json`` and ``policy.npz``)."""
        directory = Path(directory)
        description = _read(directory / POLICY_FILE, lambda path: json.loads(path.read_text()))
        if description.get("format", 1) != FORMAT:  # the layout fppo_jax.store.saved_policy writes
            raise ValueError(
                f"{directory / POLICY_FILE} is in format {description['format']!r}; this file "
                f"reads format {FORMAT}: use the numpy_policy.py of the fppo-jax that saved it"
            )
        arrays = _read(directory / ARRAYS_FILE, _arrays)
        named = ((f"[{name!r}]", arrays[name]) for name in sorted(arrays))
        if digest(named) != description["digest"]:
            raise ValueError(
                f"{directory / ARRAYS_FILE} does not match the digest in {POLICY_FILE}: damaged "
                "or edited"
            )
        policy = description["policy"]
        depth = len(policy["hidden_sizes"])
        layers = tuple(
            (arrays[f"{_NETWORK}/Dense_{i}/kernel"], arrays[f"{_NETWORK}/Dense_{i}/bias"])
            for i in range(depth + 1)
        )
        mean = var = None
        if policy["normalize_observations"]:
            mean, var = arrays["obs_stats/mean"], arrays["obs_stats/var"]
        space = policy["action_space"]
        low = high = None
        if "discrete" not in space:
            low, high = (np.asarray(space[k], np.float32) for k in ("low", "high"))
        return cls(layers, mean, var, low, high)


def _read(path: Path, read: Callable[[Path], Any]) -> Any:
    """`read(path)`; a file that is there but cannot be read back (cut short, say) is damaged,
    and the error names it."""
    try:
        return read(path)
    except (ValueError, EOFError, zipfile.BadZipFile) as error:
        raise ValueError(
            f"{path} is damaged: it cannot be read back ({type(error).__name__}: {error})"
        ) from error


def _arrays(path: Path) -> dict[str, np.ndarray]:
    with np.load(path, allow_pickle=False) as npz:
        return dict(npz)


def digest(arrays: Iterable[tuple[str | None, Any]]) -> str:
    """The SHA-256 digest fppo-jax records of arrays, each a (label, array) pair in the order
    given: the label, dtype and shape (``"<label> <dtype> <shape>"``; nothing for a label of
    None), then the array's bytes in C order. The one digest of the package: ``policy.json``
    records it of ``policy.npz``'s arrays labelled ``['<name>']`` in the order of their names,
    a checkpoint of each item's arrays labelled by their paths in the tree's order
    (``fppo_jax.store.files.tree_digest``), ``sweep.json`` of each run's values unlabelled."""
    sha = hashlib.sha256()
    for label, array in arrays:
        array = np.ascontiguousarray(array)
        if label is not None:
            sha.update(f"{label} {array.dtype} {array.shape}".encode())
        sha.update(array.tobytes())
    return sha.hexdigest()
