"""fppo_jax/export/onnx_export.py and `fppo-jax export --onnx`: the exported model's actions are the
policy's, run by onnxruntime."""

import sys

import numpy as np
import pytest

from fppo_jax import load_policy
from fppo_jax.cli import main
from fppo_jax.export.onnx_export import export_onnx

onnxruntime = pytest.importorskip("onnxruntime")


@pytest.mark.parametrize("kind", ["discrete", "continuous"])
def test_the_model_s_actions_are_the_policy_s(saved_policies, kind, tmp_path):
    policy = load_policy(saved_policies[kind])
    path = export_onnx(policy, tmp_path / "policy.onnx")
    session = onnxruntime.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    obs = np.random.default_rng(1).normal(0.0, 30.0, (256, policy.observation_size))
    obs = obs.astype(np.float32)
    (found,) = session.run(["action"], {"observation": obs})
    expected = np.asarray(policy(obs))
    if kind == "discrete":
        assert found.dtype == np.int64
        np.testing.assert_array_equal(found, expected)
    else:
        np.testing.assert_allclose(found, expected, rtol=1e-5, atol=1e-6)
        high = np.asarray(policy.action_space.high, np.float32)
        assert np.any(found == high) or np.any(found == -high)  # bounds applied


def test_cli_exports_once_and_refuses_to_overwrite(saved_policies, tmp_path, capsys):
    out = tmp_path / "models" / "cartpole.onnx"
    args = ["export", "--policy", str(saved_policies["discrete"]), "--onnx", str(out)]
    assert main(args) == 0
    assert f"wrote {out}" in capsys.readouterr().out
    before = out.read_bytes()
    assert main(args) == 2
    assert "already exists" in capsys.readouterr().err
    assert out.read_bytes() == before


def test_without_onnx_the_error_says_how_to_install_it(saved_policies, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "onnx", None)
    with pytest.raises(ImportError, match=r"pip install 'fppo-jax\[onnx\]'"):
        export_onnx(load_policy(saved_policies["discrete"]), tmp_path / "policy.onnx")
