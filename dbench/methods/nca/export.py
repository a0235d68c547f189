"""ONNX graph of the NCA (docs/methods/nca.md), written node by node from W and b.

``torch.onnx.export``'s default (dynamo) exporter needs ``onnxscript``, which dbench does not
depend on; the automaton is small enough to write directly with ``onnx.helper``. The graph runs
the fast path of :mod:`.model`: per step ``Pad(edge) -> Conv(folded 9x9x3x3) -> Sigmoid ->
Add(b) -> Add(s)``, i.e. the 39 perception channels and the 39x9 product folded into one 3x3
convolution (:func:`~dbench.methods.nca.model.folded_kernel`). Tests prove ONNX Runtime's output
equal to the PyTorch reference (max abs 1e-4).

Model (opset 17):

* inputs ``state`` (N, 9, H, W) float32 (encoded, see ``model.encode``) and, in the looped form,
  ``iterations`` (int64 scalar) and ``gamma`` (float scalar: the step size, 1 for the seed's
  automaton, γ(ℓ) of the noise gate otherwise);
* output ``rgb`` (N, 3, H, W): the RGB part of the state after the last step.

Two forms from the same weights: ``iterations=None`` gives an ONNX ``Loop`` whose trip count is
an input (the shipped ``nca.onnx``, the plain update above); an integer unrolls that many steps
with the bias folded out of the state (``_unrolled_nodes``: Pad -> Conv+bias -> sigmoid -> Add per
step). Inference builds the unrolled form in memory for the requested step count.
W (39, 9) and b (9,) are stored in the model's metadata (JSON lists of the float32 values, exact
when read back as float32), with ``update_channels``, ``activation`` and ``iterations``.
"""
from __future__ import annotations

import json
from typing import Mapping

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

from .model import PERCEPTION_CHANNELS, RGB, STATE_CHANNELS, folded_kernel

OPSET = 17


def _step_nodes(prefix: str, s: str, out: str, update_channels: str, activation: str
                ) -> list[onnx.NodeProto]:
    """Nodes of one update reading state ``s`` and writing ``out``; weights are outer names."""
    n = []
    pad, conv, act, upd = (f"{prefix}_pad", f"{prefix}_conv", f"{prefix}_act", f"{prefix}_upd")
    n.append(helper.make_node("Pad", [s, "pads"], [pad], mode="edge"))
    n.append(helper.make_node("Conv", [pad, "K", "K_bias"], [conv], kernel_shape=[3, 3]))
    n.append(helper.make_node("Sigmoid" if activation == "sigmoid" else "Tanh", [conv], [act]))
    n.append(helper.make_node("Add", [act, "b_bcast"], [f"{prefix}_ungated"]))
    n.append(helper.make_node("Mul", [f"{prefix}_ungated", "gamma"], [upd]))
    if update_channels == "all":
        n.append(helper.make_node("Add", [s, upd], [out]))
    else:
        rgb, rest, new = f"{prefix}_rgb", f"{prefix}_rest", f"{prefix}_new"
        n.append(helper.make_node("Slice", [s, "c0", "c3", "axis1"], [rgb]))
        n.append(helper.make_node("Slice", [s, "c3", "c9", "axis1"], [rest]))
        n.append(helper.make_node("Add", [rgb, upd], [new]))
        n.append(helper.make_node("Concat", [new, rest], [out], axis=1))
    return n


def _scaled_name(name: str, gamma: float) -> str:
    return name if gamma == 1.0 else f"{name}_scaled"


def _scaled(name: str, gamma: float) -> list[onnx.NodeProto]:
    """``name`` × γ (no node when γ = 1)."""
    if gamma == 1.0:
        return []
    return [helper.make_node("Mul", [name, "gamma_const"], [f"{name}_scaled"])]


def _unrolled_nodes(K: np.ndarray, b: np.ndarray, iterations: int, update_channels: str,
                    activation: str, gamma: float = 1.0
                    ) -> tuple[list[onnx.NodeProto], list[onnx.TensorProto]]:
    """Unrolled steps with the bias folded out of the state (fewer passes over memory).

    With u_k = s_k - k γ b (the state minus its accumulated bias), edge padding keeps a constant
    image constant, so Conv(Pad(s_k)) = Conv(Pad(u_k)) + k γ c with
    c_o = sum_{c,i,j} K[o,c,i,j] b_c, and the update s_{k+1} = s_k + γ (act(Conv(Pad(s_k))) + b)
    becomes u_{k+1} = u_k + γ act(Conv(Pad(u_k)) + k γ c); at the end s = u + K γ b (K steps;
    γ = 1 without the noise gate, and then no multiplication is emitted).
    With ``update_channels="rgb"`` the normal/albedo part of the convolution is constant and is
    computed once (G), so each step convolves only the 3 RGB channels.
    """
    act_op = "Sigmoid" if activation == "sigmoid" else "Tanh"
    nodes, inits = [], []
    if update_channels == "all":
        c = (K.astype(np.float64).sum(axis=(2, 3)) @ b.astype(np.float64))
        u = "state"
        for k in range(iterations):
            inits.append(numpy_helper.from_array((k * gamma * c).astype(np.float32), f"bias{k}"))
            nodes += [helper.make_node("Pad", [u, "pads"], [f"p{k}"], mode="edge"),
                      helper.make_node("Conv", [f"p{k}", "K", f"bias{k}"], [f"z{k}"],
                                       kernel_shape=[3, 3]),
                      helper.make_node(act_op, [f"z{k}"], [f"a{k}"]),
                      *_scaled(f"a{k}", gamma),
                      helper.make_node("Add", [u, _scaled_name(f"a{k}", gamma)], [f"u{k + 1}"])]
            u = f"u{k + 1}"
        nodes.append(helper.make_node("Slice", [u, "c0", "c3", "axis1"], ["u_rgb"]))
    else:
        K_rgb, K_static = K[:RGB, :RGB].copy(), K[:RGB].copy()
        K_static[:, :RGB] = 0.0
        c = gamma * (K_rgb.astype(np.float64).sum(axis=(2, 3)) @ b[:RGB].astype(np.float64))
        inits += [numpy_helper.from_array(K_rgb, "K_rgb"),
                  numpy_helper.from_array(K_static, "K_static")]
        nodes += [helper.make_node("Pad", ["state", "pads"], ["p_static"], mode="edge"),
                  helper.make_node("Conv", ["p_static", "K_static", "K_bias"], ["G"],
                                   kernel_shape=[3, 3]),
                  helper.make_node("Slice", ["state", "c0", "c3", "axis1"], ["u0"])]
        u = "u0"
        for k in range(iterations):
            inits.append(numpy_helper.from_array((k * c).astype(np.float32), f"bias{k}"))
            nodes += [helper.make_node("Pad", [u, "pads"], [f"p{k}"], mode="edge"),
                      helper.make_node("Conv", [f"p{k}", "K_rgb", f"bias{k}"], [f"z{k}"],
                                       kernel_shape=[3, 3]),
                      helper.make_node("Add", [f"z{k}", "G"], [f"g{k}"]),
                      helper.make_node(act_op, [f"g{k}"], [f"a{k}"]),
                      *_scaled(f"a{k}", gamma),
                      helper.make_node("Add", [u, _scaled_name(f"a{k}", gamma)], [f"u{k + 1}"])]
            u = f"u{k + 1}"
        nodes.append(helper.make_node("Identity", [u], ["u_rgb"]))
    if gamma != 1.0:
        inits.append(numpy_helper.from_array(np.array(gamma, np.float32), "gamma_const"))
    inits.append(numpy_helper.from_array(
        (iterations * gamma * b[:RGB].astype(np.float64)).astype(np.float32)
        .reshape(1, RGB, 1, 1), "total_bias"))
    nodes.append(helper.make_node("Add", ["u_rgb", "total_bias"], ["rgb"]))
    return nodes, inits


def build_onnx(W: np.ndarray, b: np.ndarray, update_channels: str = "all",
               activation: str = "sigmoid", iterations: int | None = None,
               metadata: Mapping[str, str] | None = None, gamma: float = 1.0
               ) -> onnx.ModelProto:
    """The NCA as an ONNX model; ``iterations=None`` for the Loop form (trip count and step
    size γ are inputs), an integer for the unrolled, bias-folded form with the step size
    ``gamma`` built in."""
    W = np.asarray(W, np.float32)
    b = np.asarray(b, np.float32)
    if W.shape != (PERCEPTION_CHANNELS, STATE_CHANNELS) or b.shape != (STATE_CHANNELS,):
        raise ValueError(f"W, b: expected shapes (39, 9) and (9,), got {W.shape}, {b.shape}")
    K9 = folded_kernel(W)
    cout = STATE_CHANNELS if update_channels == "all" else RGB
    inits = [
        numpy_helper.from_array(np.array([0, 0, 1, 1, 0, 0, 1, 1], np.int64), "pads"),
        numpy_helper.from_array(np.zeros(cout, np.float32), "K_bias"),
        numpy_helper.from_array(np.array([0], np.int64), "c0"),
        numpy_helper.from_array(np.array([RGB], np.int64), "c3"),
        numpy_helper.from_array(np.array([1], np.int64), "axis1"),
    ]
    state_info = helper.make_tensor_value_info("state", TensorProto.FLOAT,
                                               ["N", STATE_CHANNELS, "H", "W"])
    inputs = [state_info]
    nodes: list[onnx.NodeProto] = []
    if iterations is None:
        inits += [numpy_helper.from_array(K9[:cout].copy(), "K"),
                  numpy_helper.from_array(b[:cout].reshape(1, cout, 1, 1).copy(), "b_bcast"),
                  numpy_helper.from_array(np.array(True), "true")]
        if update_channels == "rgb":
            inits.append(numpy_helper.from_array(np.array([STATE_CHANNELS], np.int64), "c9"))
        inputs.append(helper.make_tensor_value_info("iterations", TensorProto.INT64, []))
        inputs.append(helper.make_tensor_value_info("gamma", TensorProto.FLOAT, []))
        body_nodes = _step_nodes("step", "s_in", "s_out", update_channels, activation)
        body_nodes.append(helper.make_node("Identity", ["cond_in"], ["cond_out"]))
        body = helper.make_graph(
            body_nodes, "nca_step",
            [helper.make_tensor_value_info("i", TensorProto.INT64, []),
             helper.make_tensor_value_info("cond_in", TensorProto.BOOL, []),
             helper.make_tensor_value_info("s_in", TensorProto.FLOAT, None)],
            [helper.make_tensor_value_info("cond_out", TensorProto.BOOL, []),
             helper.make_tensor_value_info("s_out", TensorProto.FLOAT, None)])
        nodes.append(helper.make_node("Loop", ["iterations", "true", "state"], ["final"],
                                      body=body))
        nodes.append(helper.make_node("Slice", ["final", "c0", "c3", "axis1"], ["rgb"]))
    else:
        if int(iterations) < 0:
            raise ValueError(f"iterations: expected >= 0, got {iterations}")
        if update_channels == "all":
            inits.append(numpy_helper.from_array(K9, "K"))
        more_nodes, more_inits = _unrolled_nodes(K9, b, int(iterations), update_channels,
                                                 activation, float(gamma))
        nodes += more_nodes
        inits += more_inits
    graph = helper.make_graph(nodes, "tnnd_nca", inputs,
                              [helper.make_tensor_value_info("rgb", TensorProto.FLOAT,
                                                             ["N", RGB, "H", "W"])], inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)],
                              producer_name="dbench")
    model.ir_version = 8
    meta = {"W": json.dumps(W.tolist()), "b": json.dumps(b.tolist()),
            "update_channels": update_channels, "activation": activation, **(metadata or {})}
    for k, v in meta.items():
        entry = model.metadata_props.add()
        entry.key, entry.value = str(k), str(v)
    onnx.checker.check_model(model)
    return model


def metadata(model: onnx.ModelProto) -> dict[str, str]:
    return {p.key: p.value for p in model.metadata_props}


def weights_from_onnx(model: onnx.ModelProto) -> tuple[np.ndarray, np.ndarray]:
    """(W (39, 9), b (9,)) stored (as exact float32 values) in an NCA model's metadata."""
    meta = metadata(model)
    return (np.array(json.loads(meta["W"]), np.float32),
            np.array(json.loads(meta["b"]), np.float32))
