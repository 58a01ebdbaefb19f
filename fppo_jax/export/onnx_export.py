"""A trained policy as an ONNX model, for runtimes without JAX (the ``onnx`` extra).

The model computes the deterministic policy, as ``Policy(obs)`` does: from an input
``observation`` (float32, ``[batch, observation_size]``), the observation normalised with the
statistics training ended with, ``clip((x − μ) / sqrt(σ² + 1e-8), −10, 10)`` (when training
normalised them), then tanh hidden layers and a linear head, then ``action``: the arg max of
the logits (int64) for discrete actions, or the Gaussian's mean clipped to the action bounds
(float32) for continuous ones. Opset 17, standard operators only.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from fppo_jax.core.networks import policy_layers
from fppo_jax.core.policy import Policy
from fppo_jax.envs import Discrete
from fppo_jax.errors import MissingPackage, install_hint

OPSET = 17


def export_onnx(policy: Policy, path: str | Path) -> Path:
    """Write `policy`'s deterministic action as an ONNX model to `path`; returns the path."""
    try:
        import onnx
        from onnx import TensorProto, helper
    except ImportError:
        raise MissingPackage(
            f"exporting to ONNX needs the onnx package: {install_hint('onnx')}"
        ) from None
    graph = _Graph()
    x = _network(graph, policy, _normalised(graph, policy, "observation"))
    space = policy.action_space
    if isinstance(space, Discrete):
        graph.node("ArgMax", [x], "action", axis=-1, keepdims=0)
        action = helper.make_tensor_value_info("action", TensorProto.INT64, ["batch"])
    else:
        x = graph.node("Max", [x, graph.constant("action_low", space.low)], "above_low")
        graph.node("Min", [x, graph.constant("action_high", space.high)], "action")
        action = helper.make_tensor_value_info(
            "action", TensorProto.FLOAT, ["batch", len(space.low)]
        )
    observation = helper.make_tensor_value_info(
        "observation", TensorProto.FLOAT, ["batch", policy.observation_size]
    )
    model = helper.make_model(
        helper.make_graph(graph.nodes, "fppo_jax_policy", [observation], [action], graph.constants),
        opset_imports=[helper.make_opsetid("", OPSET)],
    )
    model.producer_name = "fppo-jax"
    onnx.checker.check_model(model)
    path = Path(path)
    onnx.save(model, path)
    return path


class _Graph:
    """An ONNX graph's nodes and constants, added one by one, each named by its output."""

    def __init__(self) -> None:
        self.constants: list[Any] = []
        self.nodes: list[Any] = []

    def constant(self, name: str, value: Any) -> str:
        from onnx import numpy_helper

        self.constants.append(numpy_helper.from_array(np.asarray(value, np.float32), name))
        return name

    def node(self, op: str, inputs: list[str], output: str, **attributes: Any) -> str:
        from onnx import helper

        self.nodes.append(helper.make_node(op, inputs, [output], **attributes))
        return output


def _normalised(graph: _Graph, policy: Policy, x: str) -> str:
    """`x` normalised with the statistics training ended with, if it normalised them."""
    if policy.obs_stats is None:
        return x
    stats = policy.obs_stats
    scale = np.sqrt(np.asarray(stats.var, np.float32) + np.float32(1e-8))
    x = graph.node("Sub", [x, graph.constant("obs_mean", stats.mean)], "centred")
    x = graph.node("Div", [x, graph.constant("obs_scale", scale)], "scaled")
    bounds = [graph.constant("clip_low", -10.0), graph.constant("clip_high", 10.0)]
    return graph.node("Clip", [x, *bounds], "normalised")


def _network(graph: _Graph, policy: Policy, x: str) -> str:
    """The policy network's output at `x`: tanh hidden layers, then a linear head."""
    for i, dense in enumerate(policy_layers(policy.params)):
        x = graph.node(
            "MatMul", [x, graph.constant(f"kernel_{i}", dense["kernel"])], f"product_{i}"
        )
        x = graph.node("Add", [x, graph.constant(f"bias_{i}", dense["bias"])], f"layer_{i}")
        if i < len(policy.hidden_sizes):
            x = graph.node("Tanh", [x], f"hidden_{i}")
    return x
