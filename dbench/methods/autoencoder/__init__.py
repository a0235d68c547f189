"""``autoencoder``: the recurrent denoising autoencoder of Chaitanya et al. 2017
(docs/methods/autoencoder.md), served with ONNX Runtime from the shipped ``autoencoder.onnx`` (trained by
``dbench train autoencoder``; ``autoencoder.json`` beside it holds the training configuration,
data hash, losses and widths).

Pipeline (shapes for an H x W frame; C = 3 + feature channels, 11 for the shipped model):

    color, normal, albedo, depth --encode--> x (C, H, W), a_eff (H, W, 3)
      --replicate-pad to multiples of 32--> (1, C, H', W')   [both in one compiled pass,
                                                              kernels/learned_input.py]
      --ONNX Runtime: U-Net with a recurrent block per level; hidden states h1..h5 in and out-->
    y (1, 3, H', W') --crop, max(expm1(y), 0) * a_eff--> (H, W, 3)

The shipped model is residual (metadata ``residual``): the graph adds the input's colour channels
x[:, 0:3] to y, so the network predicts a correction of the noisy colour (see
``model.RecurrentAE``; a model trained with ``level_gate`` scales that correction by a trained
function of the noise level, metadata ``level_gate``). Its widths (``width_scale`` 0.5) and
inputs are in its metadata and in ``autoencoder.json``.

Recurrence: ``reset()`` forgets the hidden states; each ``denoise(frame)`` then uses and
updates them (``recurrent=True``). A frame with no state (the first after ``reset()``, and every
frame when ``recurrent=False``) runs the stateless graph, which equals the stateful graph with
zero hidden states. The harness resets before every call, so single frames are state-reset.
The shipped recurrent weights were trained on camera-animated training sequences
(``dbench train autoencoder``, stage 2); ``results/learned.md`` measures what carrying the state
adds on the catalogue's sequences.

Optional ``emitter`` buffer (coverage of lights seen directly or in smooth mirrors): those
pixels keep the input in proportion to their coverage
(:func:`dbench.methods.kernels.emitters.keep_emitters`, the NCA's rule).

Training: stage 1 on single frames, stage 2 on sequences, and stage 3, the consistency stage
whose loss asks every crop, the nearly converged ones included, to beat its input
(``dbench.learn.configs.AEConsistencyConfig``; results/learned.md).

Inputs (documented choice): albedo-demodulated colour ``log1p(color / a_eff)``, world-space
normal, albedo and depth divided by the frame's largest depth (docs/methods/autoencoder.md §1, the ``seed`` variant plus
depth).

Input policy (documented finite result): non-finite or negative colour values are treated as
missing and replaced by 0 before encoding; non-finite normal/albedo/depth by 0; normals clipped
to [-1, 1], albedo to [0, 1]. Huge finite colour (up to the float32 maximum) is encoded
without overflow (``log1p`` of the float64 quotient where the float32 one is Inf, at most ≈ 95)
and the decoder caps the network output at expm1(80). The output is finite everywhere. Missing
or mis-shaped buffers raise DbenchInputError naming the buffer.

Device path (``denoise_device``, :mod:`.device`): the same pipeline in PyTorch on the frame's
device, the hidden states kept there, equal to this one within the tolerance
tests/methods/test_autoencoder_device.py states.

Parameters: ``recurrent`` (carry state across frames), ``weights`` (path of another
``autoencoder.onnx``; None: the shipped file), ``threads`` (ONNX Runtime intra-op threads),
``spp`` (the input's sample count, for a model with the ``level`` input; None:
``data.meta["spp"]``, and 1 spp when that is absent too).

HDR input ([dbench], recorded in the model's metadata): with ``autoexposure`` the colour is
scaled by OIDN's auto-exposure (:func:`dbench.methods.hdr_input.autoexposure`) before the
encoding and the output divided by it; the ``level`` feature is log2(spp)/10 as a constant plane.

Example:
    >>> import numpy as np
    >>> from dbench.data import Frame
    >>> from dbench.registry import get
    >>> f = Frame(color=np.full((5, 7, 3), 0.5), albedo=np.full((5, 7, 3), 0.5),
    ...           normal=np.dstack([np.zeros((5, 7, 2)), np.ones((5, 7))]),
    ...           depth=np.ones((5, 7, 1)))
    >>> get("autoencoder").denoise(f).shape
    (5, 7, 3)
"""
from __future__ import annotations

import json
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from ...data import check_buffer
from ...errors import DbenchInputError
from ...denoiser import Denoiser, register
from ..kernels.emitters import keep_emitters
from ..kernels.hdr_input import autoexposure, check_run_options, frame_spp, noise_level
from ..kernels.learned_input import encode_planar
from ..ort_session import cpu_session
from .codec import FEATURE_CHANNELS, MULTIPLE, decode, encode, pad_to_multiple

SHIPPED_ONNX = Path(__file__).resolve().parent / "autoencoder.onnx"
SHIPPED_JSON = Path(__file__).resolve().parent / "autoencoder.json"


@lru_cache(maxsize=8)
def _load(path: str):
    import onnx

    from .export import gate_from_metadata

    p = Path(path)
    if not p.exists():
        raise DbenchInputError(f"weights: {p} does not exist; run `dbench train autoencoder` "
                               "or pass the path of an autoencoder.onnx")
    model = onnx.load(str(p))
    meta = {e.key: e.value for e in model.metadata_props}
    info = {"features": tuple(f for f in meta["features"].split(",") if f),
            "enc_widths": tuple(int(w) for w in meta["enc_widths"].split(",")),
            "in_channels": int(meta["in_channels"]),
            "width_scale": float(meta.get("width_scale", 1.0)),
            "residual": meta.get("residual") == "True", "blend": meta.get("blend") == "True",
            "autoexposure": meta.get("autoexposure") == "True"}
    info["level_gate"], info["gate_max"] = gate_from_metadata(meta)
    info["pixel_gate"] = meta.get("pixel_gate") == "True"
    return model, info


def model_info(weights: str | Path | None = None) -> dict[str, Any]:
    """features, enc_widths and in_channels of a (default: the shipped) model."""
    return dict(_load(str(weights or SHIPPED_ONNX))[1])


@lru_cache(maxsize=8)
def _session(path: str, stateful: bool, threads: int | None):
    """An ONNX Runtime session of the shipped model, with or without the hidden-state I/O."""
    from .export import stateless_from_stateful

    model, info = _load(path)
    if not stateful:
        model = stateless_from_stateful(model, info["in_channels"], info["enc_widths"])
    return cpu_session(model.SerializeToString(), threads)


def _buffers(color, albedo, normal, depth, features, spp=None) -> tuple[np.ndarray, dict]:
    color = check_buffer("color", color, (None, None, 3))
    h, w = color.shape[:2]
    given = {"albedo": albedo, "normal": normal, "depth": depth}
    out = {"albedo": check_buffer("albedo", albedo, (h, w, 3)),
           "level": 0.0 if spp is None else noise_level(spp)}
    for f in features:
        if f not in ("albedo", "level"):
            if given[f] is None:
                raise DbenchInputError(f"{f}: missing; the autoencoder needs an "
                                       f"(H, W, {FEATURE_CHANNELS[f]}) {f} buffer")
            arr = np.asarray(given[f])
            if f == "depth" and arr.ndim == 2:
                arr = arr[..., None]
            out[f] = check_buffer(f, arr, (h, w, FEATURE_CHANNELS[f]))
    return color, out


def autoencoder_denoise(color: np.ndarray, albedo: np.ndarray, normal: np.ndarray | None = None,
                        depth: np.ndarray | None = None, hidden: list[np.ndarray] | None = None,
                        weights: str | Path | None = None, threads: int | None = None,
                        spp: float | None = None) -> tuple[np.ndarray, list[np.ndarray]]:
    """Denoise one (H, W, 3) frame; returns ((H, W, 3) float32, new hidden states).

    ``hidden``: the states returned for the previous frame of the same size, or None (frame 0).
    ``spp``: the colour's sample count, for a model with the ``level`` input (None: 1 spp).
    """
    path = str(weights or SHIPPED_ONNX)
    _, info = _load(path)
    color, bufs = _buffers(color, albedo, normal, depth, info["features"], spp)
    h, w = color.shape[:2]
    exposure = autoexposure(color) if info["autoexposure"] else 1.0
    # encode + pad_to_multiple in one compiled pass (tested equal to them within 1e-6)
    xp, a_eff = encode_planar(color, bufs, info["features"], exposure, MULTIPLE)
    feeds = {"x": xp[None]}
    if hidden is not None:
        expect = [(1, e, xp.shape[1] >> l, xp.shape[2] >> l)
                  for l, e in enumerate(info["enc_widths"])]
        if len(hidden) != len(expect) or any(t.shape != s for t, s in zip(hidden, expect)):
            raise DbenchInputError(
                f"hidden: state of shapes {[t.shape for t in hidden]} does not fit a {h}x{w} "
                f"frame (expected {expect}); call reset() between sequences")
        feeds.update({f"h{l + 1}": t for l, t in enumerate(hidden)})
    outs = _session(path, hidden is not None, threads).run(None, feeds)
    y, new_hidden = outs[0][0, :, :h, :w], list(outs[1:])
    return decode(y, a_eff, exposure), new_hidden


def reference_denoise(color, albedo, normal=None, depth=None, hidden=None, weights=None,
                      spp=None):
    """The same through the PyTorch model (tests: ONNX Runtime equals PyTorch)."""
    import torch

    from .export import state_from_onnx
    from .model import RecurrentAE, widths

    path = str(weights or SHIPPED_ONNX)
    model, info = _load(path)
    state = state_from_onnx(model)
    scale = info["width_scale"]
    net = RecurrentAE(info["in_channels"], scale, residual=info["residual"], blend=info["blend"],
                      level_gate=info["level_gate"], gate_max=info["gate_max"],
                      pixel_gate=info["pixel_gate"])
    if widths(scale)[0] != info["enc_widths"]:
        raise ValueError(f"cannot rebuild widths {info['enc_widths']}")
    net.load_state_dict({k: torch.from_numpy(np.array(v)) for k, v in state.items()})
    color, bufs = _buffers(color, albedo, normal, depth, info["features"], spp)
    h, w = color.shape[:2]
    exposure = autoexposure(color) if info["autoexposure"] else 1.0
    x, a_eff = encode(color, bufs, info["features"], exposure)
    xp, _, _ = pad_to_multiple(x)
    with torch.no_grad():
        hid = None if hidden is None else [torch.from_numpy(t) for t in hidden]
        y, new_hidden = net(torch.from_numpy(xp)[None], hid)
    return decode(y[0, :, :h, :w].numpy(), a_eff, exposure), [t.numpy() for t in new_hidden]


def training_info(path: str | Path = SHIPPED_JSON) -> dict[str, Any]:
    """The JSON written beside the shipped weights (training configuration, losses, ...)."""
    return json.loads(Path(path).read_text(encoding="utf-8"))


@register("autoencoder")
class Autoencoder(Denoiser):
    """Recurrent denoising autoencoder (docs/methods/autoencoder.md); ``reset()`` between sequences."""

    kinds = {"steady", "sequence"}
    needs = {"color", "albedo", "normal", "depth"}
    optional_needs = {"emitter"}  # lights keep the input (keep_emitters)
    keeps_emitters = True  # so NAME+gate does not apply the rule a second time
    defaults = dict(recurrent=True, weights=None, threads=None, spp=None)
    device_backend = "torch"

    def __init__(self, **params):
        super().__init__(**params)
        from ..ort_session import check_weights
        check_weights(self.params["weights"], "autoencoder")
        check_run_options(self.params)  # refused here, before anything renders
        # hidden states of the previous frame: NumPy arrays after denoise, tensors on the
        # device after denoise_device (each path takes over the other's)
        self._hidden: list[Any] | None = None
        self._device_nets: dict[str, Any] = {}  # the PyTorch model per device

    def reset(self) -> None:
        self._hidden = None

    def denoise(self, data) -> np.ndarray:
        if getattr(data, "albedo", None) is None:
            raise DbenchInputError("albedo: missing; the autoencoder needs an (H, W, 3) albedo "
                                   "buffer")
        hidden = self._hidden if self.params["recurrent"] else None
        if hidden is not None and not isinstance(hidden[0], np.ndarray):  # left on a device
            from ...device import download
            hidden = [download(t) for t in hidden]
        out, new_hidden = autoencoder_denoise(
            data.color, data.albedo, getattr(data, "normal", None), getattr(data, "depth", None),
            hidden=hidden, weights=self.params["weights"], threads=self.params["threads"],
            spp=frame_spp(data, self.params["spp"]))
        if self.params["recurrent"]:
            self._hidden = new_hidden
        return keep_emitters(data.color, out, getattr(data, "emitter", None))

    def denoise_device(self, data):
        """The same pipeline in PyTorch on the frame's device, hidden states kept there
        (:mod:`.device`): (H, W, 3) float32 tensor; every parameter as ``denoise``,
        ``threads`` setting PyTorch's CPU threads on a CPU device and refused on a GPU."""
        from .device import denoise_device

        return denoise_device(self, data, *_load(str(self.params["weights"] or SHIPPED_ONNX)))


__all__ = ["Autoencoder", "autoencoder_denoise", "reference_denoise", "model_info",
           "training_info", "SHIPPED_ONNX", "SHIPPED_JSON"]
