"""fppo_jax/store/numpy_policy.py: a saved policy run by numpy alone gives Policy's actions."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fppo_jax import load_policy
from fppo_jax.store.numpy_policy import NumpyPolicy

MODULE = Path(__file__).resolve().parent.parent / "fppo_jax" / "store" / "numpy_policy.py"


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
def test_numpy_actions_are_the_policy_s(saved_policies, kind):
    policy, numpy_policy = load_policy(saved_policies[kind]), NumpyPolicy.load(saved_policies[kind])
    assert numpy_policy.discrete == (kind == "discrete")
    size = numpy_policy.observation_size
    # Far from the training data too, where normalisation clips and actions hit their bounds.
    obs = np.random.default_rng(0).normal(0.0, 30.0, (256, size)).astype(np.float32)
    expected, found = np.asarray(policy(obs)), numpy_policy(obs)
    if kind == "discrete":
        np.testing.assert_array_equal(found, expected)
        assert numpy_policy(obs[0]) == expected[0]
    else:
        np.testing.assert_allclose(found, expected, rtol=1e-5, atol=1e-6)
        assert np.any(found == numpy_policy.high) or np.any(found == numpy_policy.low)


def test_runs_without_jax_from_a_copy_of_the_file(saved_policies, tmp_path):
    copy = tmp_path / "numpy_policy.py"
    copy.write_text(MODULE.read_text())
    program = (
        "import sys; sys.modules['jax'] = None; sys.modules['fppo_jax'] = None\n"
        f"sys.path.insert(0, {str(tmp_path)!r})\n"
        "import numpy as np\n"
        "from numpy_policy import NumpyPolicy\n"
        f"policy = NumpyPolicy.load({str(saved_policies['discrete'])!r})\n"
        "print(int(policy(np.zeros(policy.observation_size))))\n"
    )
    done = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    expected = int(load_policy(saved_policies["discrete"])(np.zeros(4, np.float32)))
    assert done.stdout.strip() == str(expected)


def test_damaged_arrays_and_bad_observations_are_refused(saved_policies, tmp_path):
    policy = NumpyPolicy.load(saved_policies["discrete"])
    with pytest.raises(ValueError, match="observations of size 4"):
        policy(np.zeros(3))
    with pytest.raises(ValueError, match="NaN or infinity"):
        policy(np.array([0.0, np.nan, 0.0, 0.0]))
    edited = tmp_path / "edited"
    edited.mkdir()
    (edited / "policy.json").write_text((saved_policies["discrete"] / "policy.json").read_text())
    with np.load(saved_policies["discrete"] / "policy.npz") as npz:
        arrays = dict(npz)
    arrays["params/params/MLP_0/Dense_0/bias"] = arrays["params/params/MLP_0/Dense_0/bias"] + 1
    np.savez(edited / "policy.npz", **arrays)
    with pytest.raises(ValueError, match="does not match the digest"):
        NumpyPolicy.load(edited)
    whole = (saved_policies["discrete"] / "policy.npz").read_bytes()
    (edited / "policy.npz").write_bytes(whole[: len(whole) // 2])
    with pytest.raises(ValueError, match=f"{edited / 'policy.npz'} is damaged: .*BadZipFile"):
        NumpyPolicy.load(edited)
    (edited / "policy.json").write_text('{"digest": ')
    with pytest.raises(ValueError, match=f"{edited / 'policy.json'} is damaged: .*JSONDecode"):
        NumpyPolicy.load(edited)
