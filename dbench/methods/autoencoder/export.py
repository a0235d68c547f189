"""ONNX graph of the recurrent autoencoder, written node by node from its weights.

``torch.onnx.export``'s default (dynamo) exporter needs ``onnxscript``, which dbench does not
depend on, so the graph is built with ``onnx.helper`` from the state dict of
:class:`~dbench.methods.autoencoder.model.RecurrentAE`; tests prove ONNX Runtime's output equal to
the PyTorch model's (max abs 1e-4).

Graph (opset 17), H and W dynamic (multiples of 32):

* inputs ``x`` (N, C, H, W) and, when ``stateful``, ``h1``..``h5`` (N, e_l, H/2^(l-1), W/2^(l-1));
* outputs ``y`` (N, 3, H, W) and ``h1_out``..``h5_out`` (the next frame's hidden states);
  with ``residual`` the input's colour channels x[:, 0:3] are added to y (metadata
  ``residual``); with ``blend`` the last convolution's 4 channels (f, g) give
  y = f + sigmoid(g) (x[:, 0:3] - f) (metadata ``blend``); with ``level_gate`` the correction
  is first scaled by gate_max · sigmoid(v + u · x[:, level_gate]) (metadata ``level_gate``,
  ``gate_max``; initializer ``level_gate`` = (u, v)).

The stateless variant (frame 0 of a sequence, or single frames with the state reset) drops the
hidden inputs: the recurrent convolution conv3(concat(a, 0)) equals conv3(a) with the first half
of its input weights, because the zero half contributes exactly nothing. It is built from the same
weights at load time and saves the work of convolving zeros.
"""
from __future__ import annotations

from typing import Mapping

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

from .codec import LEVELS, SLOPE

OPSET = 17


class _Graph:
    def __init__(self, state: Mapping[str, np.ndarray]):
        self.state = {k: np.asarray(v, np.float32) for k, v in state.items()}
        self.nodes: list[onnx.NodeProto] = []
        self.inits: list[onnx.TensorProto] = []
        self._n = 0

    def name(self, prefix: str) -> str:
        self._n += 1
        return f"{prefix}_{self._n}"

    def const(self, name: str, array: np.ndarray) -> str:
        self.inits.append(numpy_helper.from_array(np.asarray(array), name))
        return name

    def conv(self, x: str, key: str, act: bool = True, weight: np.ndarray | None = None) -> str:
        w = self.state[f"{key}.weight"] if weight is None else weight
        b = self.state[f"{key}.bias"]
        wn = self.const(f"{key}.weight", w)
        bn = self.const(f"{key}.bias", b)
        out = self.name(key)
        self.nodes.append(helper.make_node("Conv", [x, wn, bn], [out], kernel_shape=[3, 3],
                                           pads=[1, 1, 1, 1]))
        if not act:
            return out
        y = self.name(key + "_lrelu")
        self.nodes.append(helper.make_node("LeakyRelu", [out], [y], alpha=SLOPE))
        return y

    def op(self, op: str, inputs: list[str], prefix: str, **attrs) -> str:
        out = self.name(prefix)
        self.nodes.append(helper.make_node(op, inputs, [out], **attrs))
        return out


def build_onnx(state: Mapping[str, np.ndarray], in_channels: int, enc_widths: tuple[int, ...],
               stateful: bool = True, metadata: Mapping[str, str] | None = None,
               residual: bool = False, blend: bool = False, level_gate: int | None = None,
               gate_max: float = 2.0, pixel_gate: bool = False) -> onnx.ModelProto:
    """The autoencoder as an ONNX model from a state dict (NumPy arrays, PyTorch key names);
    ``level_gate``/``gate_max`` as in :class:`~dbench.methods.autoencoder.model.RecurrentAE`
    (the state's ``level_gate`` holds (u, v))."""
    g = _Graph(state)
    inputs = [helper.make_tensor_value_info("x", TensorProto.FLOAT, ["N", in_channels, "H", "W"])]
    outputs = [helper.make_tensor_value_info("y", TensorProto.FLOAT, ["N", 3, "H", "W"])]
    scales = g.const("up_scales", np.array([1, 1, 2, 2], np.float32))
    x = "x"
    skips = []
    for level in range(LEVELS):
        e = enc_widths[level]
        x = g.conv(x, f"enc_in.{level}")
        a = g.conv(x, f"rec_a.{level}")
        if stateful:
            h_in = f"h{level + 1}"
            inputs.append(helper.make_tensor_value_info(
                h_in, TensorProto.FLOAT, ["N", e, f"H{level + 1}", f"W{level + 1}"]))
            cat = g.op("Concat", [a, h_in], f"rec_cat{level}", axis=1)
            b = g.conv(cat, f"rec_b.{level}")
        else:
            w_full = g.state[f"rec_b.{level}.weight"]
            b = g.conv(a, f"rec_b.{level}", weight=w_full[:, :e])
        o = g.conv(b, f"rec_o.{level}")
        skips.append(o)
        h_out = f"h{level + 1}_out"
        g.nodes.append(helper.make_node("Identity", [o], [h_out]))
        outputs.append(helper.make_tensor_value_info(
            h_out, TensorProto.FLOAT, ["N", e, f"H{level + 1}", f"W{level + 1}"]))
        x = g.op("MaxPool", [o], f"pool{level}", kernel_shape=[2, 2], strides=[2, 2])
    x = g.conv(x, "bottleneck")
    for i, level in enumerate(reversed(range(LEVELS))):
        x = g.op("Resize", [x, "", scales], f"up{level}", mode="nearest",
                 coordinate_transformation_mode="asymmetric", nearest_mode="floor")
        x = g.op("Concat", [x, skips[level]], f"dec_cat{level}", axis=1)
        x = g.conv(x, f"dec_a.{i}")
        x = g.conv(x, f"dec_b.{i}")
    y = g.conv(x, "out", act=False)
    if pixel_gate:  # y = y[:, 0:3] * sigmoid(y[:, 3:4])
        p0, p3, p4 = (g.const(f"pg{i}", np.array([i], np.int64)) for i in (0, 3, 4))
        pax = g.const("pg_axis", np.array([1], np.int64))
        delta = g.op("Slice", [y, p0, p3, pax], "pg_delta")
        gate = g.op("Sigmoid", [g.op("Slice", [y, p3, p4, pax], "pg_logit")], "pg_gate")
        y = g.op("Mul", [delta, gate], "pg_scaled")
    if level_gate is not None:  # y *= gate_max · sigmoid(v + u · x[:, level])
        uv = g.const("level_gate", g.state["level_gate"])
        i0, i1, i2 = (g.const(f"gate_index{i}", np.array([i], np.int64)) for i in (0, 1, 2))
        axis0, axis1 = (g.const(f"gate_axis{i}", np.array([i], np.int64)) for i in (0, 1))
        lo, hi = (g.const(f"gate_level{i}", np.array([level_gate + i], np.int64)) for i in (0, 1))
        u = g.op("Slice", [uv, i0, i1, axis0], "gate_u")
        v = g.op("Slice", [uv, i1, i2, axis0], "gate_v")
        lv = g.op("Slice", ["x", lo, hi, axis1], "gate_level")
        z = g.op("Add", [g.op("Mul", [lv, u], "gate_ul"), v], "gate_z")
        gamma = g.op("Mul", [g.op("Sigmoid", [z], "gate_sig"),
                             g.const("gate_max", np.array([gate_max], np.float32))], "gate_gamma")
        y = g.op("Mul", [y, gamma], "gate_scaled")
    if residual or blend:
        c0, c3, c4 = (g.const(f"chan{i}", np.array([i], np.int64)) for i in (0, 3, 4))
        axes = g.const("chan_axis", np.array([1], np.int64))
        rgb = g.op("Slice", ["x", c0, c3, axes], "x_rgb")
    if residual:  # y += x[:, 0:3]
        y = g.op("Add", [y, rgb], "residual")
    elif blend:  # y = f + sigmoid(g) (x_rgb - f)
        f = g.op("Slice", [y, c0, c3, axes], "blend_f")
        keep = g.op("Sigmoid", [g.op("Slice", [y, c3, c4, axes], "blend_g")], "blend_keep")
        y = g.op("Add", [f, g.op("Mul", [keep, g.op("Sub", [rgb, f], "blend_diff")],
                                 "blend_mul")], "blend")
    g.nodes.append(helper.make_node("Identity", [y], ["y"]))
    graph = helper.make_graph(g.nodes, "recurrent_autoencoder", inputs, outputs, g.inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", OPSET)],
                              producer_name="dbench")
    model.ir_version = 8
    gate_meta = {} if level_gate is None else {"level_gate": str(int(level_gate)),
                                               "gate_max": repr(float(gate_max))}
    if pixel_gate:
        gate_meta["pixel_gate"] = "True"
    for k, v in {"residual": str(bool(residual)), "blend": str(bool(blend)), **gate_meta,
                 **(metadata or {})}.items():
        entry = model.metadata_props.add()
        entry.key, entry.value = str(k), str(v)
    onnx.checker.check_model(model)
    return model


def state_from_onnx(model: onnx.ModelProto) -> dict[str, np.ndarray]:
    """The weights (PyTorch key names) stored in a stateful autoencoder ONNX model."""
    return {t.name: numpy_helper.to_array(t) for t in model.graph.initializer
            if t.name.endswith((".weight", ".bias")) or t.name == "level_gate"}


def gate_from_metadata(meta: Mapping[str, str]) -> tuple[int | None, float]:
    """(level_gate channel or None, gate_max) recorded in a model's metadata."""
    if not meta.get("level_gate"):
        return None, 2.0
    return int(meta["level_gate"]), float(meta.get("gate_max", 2.0))


def stateless_from_stateful(model: onnx.ModelProto, in_channels: int,
                            enc_widths: tuple[int, ...]) -> onnx.ModelProto:
    """The single-frame variant (no hidden inputs) built from a shipped stateful model."""
    meta = {p.key: p.value for p in model.metadata_props}
    level_gate, gate_max = gate_from_metadata(meta)
    return build_onnx(state_from_onnx(model), in_channels, enc_widths, stateful=False,
                      residual=meta.get("residual") == "True", blend=meta.get("blend") == "True",
                      level_gate=level_gate, gate_max=gate_max,
                      pixel_gate=meta.get("pixel_gate") == "True")
