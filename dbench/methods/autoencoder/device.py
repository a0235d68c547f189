"""The recurrent autoencoder on a device (``Autoencoder.denoise_device``, :mod:`dbench.device`):
the host pipeline of :func:`dbench.methods.autoencoder.autoencoder_denoise` with every step a
PyTorch operation on the frame's device, and the hidden states kept there between frames.

Pipeline (shapes for an H x W frame; C = 3 + feature channels, 11 for the shipped model):

    color, albedo, normal, depth tensors
      --auto-exposure, encoding, replicate padding to multiples of 32
        (kernels/learned_torch.py)--> x (1, C, H', W'), a_eff (H, W, 3)
      --RecurrentAE (model.py, the shipped weights from the .onnx's initializers);
        hidden states h1..h5 (1, e_l, H' / 2^(l-1), W' / 2^(l-1)) in and out-->
    y (1, 3, H', W') --crop, max(expm1(min(y, 80)), 0) · a_eff / exposure, keep_emitters-->
    (H, W, 3)

Recurrence: the hidden states stay on the device in the method's ``_hidden`` (a list of
tensors) and ``reset()`` forgets them, as on the host; a state left by the host path (NumPy
arrays) is carried over to the device, so the two paths continue one history. A frame without
state runs the model with zero states, which equals the host's stateless graph (export.py).
Convolutions run in IEEE float32 (:func:`~dbench.methods.kernels.learned_torch.float32_precision`):
with cuDNN's default TF32 the output differed from ONNX Runtime's by 6.5e-2 on an H200.

Agreement with the host path (ONNX Runtime): the tolerance is stated and measured in
tests/methods/test_autoencoder_device.py: |device − host| ≤ 3e-6 + 3e-5 |host| (measured on the
CPU over recurrent sequences of 32x48 frames at 1-1024 spp: max abs 1.4e-6, max relative
1.2e-5; on an H200 at 1280x720: 1.8e-6 and 1.6e-5, 6.5 ms per frame against the host path's
174 ms, and 1.3e-3 and 1.4e-2 with TF32 left on).
The input policy is the host's (module docstring of :mod:`dbench.methods.autoencoder`); a
non-finite network output, which the host decoder passes on as NaN, decodes as 0 here.
"""
from __future__ import annotations

from typing import Any

import numpy as np
import torch

from ...errors import DbenchInputError
from ..kernels import learned_torch as lt
from ..kernels.hdr_input import frame_spp, noise_level
from .codec import FEATURE_CHANNELS, MULTIPLE


def build_net(model: Any, info: dict[str, Any], device: torch.device) -> torch.nn.Module:
    """:class:`~dbench.methods.autoencoder.model.RecurrentAE` with the weights stored as the
    initializers of the ONNX ``model`` (loaded once per process, ``autoencoder._load``) and
    the settings of its ``info``, in eval mode on ``device``."""
    from .export import state_from_onnx
    from .model import RecurrentAE, widths

    scale = info["width_scale"]
    if widths(scale)[0] != info["enc_widths"]:
        raise DbenchInputError(f"weights: the model has encoder widths {info['enc_widths']}, "
                               f"which width_scale {scale} does not rebuild")
    net = RecurrentAE(info["in_channels"], scale, residual=info["residual"], blend=info["blend"],
                      level_gate=info["level_gate"], gate_max=info["gate_max"],
                      pixel_gate=info["pixel_gate"])
    net.load_state_dict({k: torch.from_numpy(np.array(v, np.float32))
                         for k, v in state_from_onnx(model).items()})
    net = net.to(device).eval()
    net.requires_grad_(False)
    return net


def _buffers(data: Any, features: tuple[str, ...], spp: float | None
             ) -> tuple[torch.Tensor, dict[str, Any]]:
    """(color (H, W, 3), {albedo, the features' (H, W, C) tensors, level}) checked as the host's
    ``_buffers`` does, naming a missing or mis-shaped buffer."""
    color = lt.check_tensor("color", getattr(data, "color", None), 3)
    hw = tuple(color.shape[:2])
    if getattr(data, "albedo", None) is None:
        raise DbenchInputError("albedo: missing; the autoencoder needs an (H, W, 3) albedo "
                               "buffer")
    out: dict[str, Any] = {"albedo": lt.check_tensor("albedo", data.albedo, 3, hw),
                           "level": 0.0 if spp is None else noise_level(spp)}
    for f in features:
        if f not in ("albedo", "level"):
            t = getattr(data, f, None)
            if t is None:
                raise DbenchInputError(f"{f}: missing; the autoencoder needs an "
                                       f"(H, W, {FEATURE_CHANNELS[f]}) {f} buffer")
            out[f] = lt.check_tensor(f, t, FEATURE_CHANNELS[f], hw)
    return color, out


def _state_on(hidden: list | None, device: torch.device, expect: list[tuple[int, ...]],
              hw: tuple[int, int]) -> list[torch.Tensor] | None:
    """The previous frame's hidden states as tensors on ``device`` (NumPy states of the host
    path are copied there), or a DbenchInputError when they do not fit this frame's size."""
    if hidden is None:
        return None
    if len(hidden) != len(expect) or any(tuple(t.shape) != s for t, s in zip(hidden, expect)):
        raise DbenchInputError(
            f"hidden: state of shapes {[tuple(t.shape) for t in hidden]} does not fit a "
            f"{hw[0]}x{hw[1]} frame (expected {expect}); call reset() between sequences")
    return [t if isinstance(t, torch.Tensor) and t.device == device
            else torch.as_tensor(t, dtype=torch.float32).to(device) for t in hidden]


def denoise_device(method: Any, data: Any, model: Any, info: dict[str, Any]) -> torch.Tensor:
    """``method`` (an :class:`~dbench.methods.autoencoder.Autoencoder`) on a
    :class:`~dbench.device.DeviceFrame`: (H, W, 3) float32 on the frame's device; updates
    ``method._hidden`` (device tensors) when ``recurrent``. ``model``, ``info``: the ONNX model
    of the weights and its settings (``autoencoder._load``). Models are cached per device in
    ``method._device_nets``."""
    params = method.params
    spp = frame_spp(data, params["spp"])
    color, bufs = _buffers(data, info["features"], spp)
    h, w = color.shape[:2]
    device = color.device
    threads = params["threads"]
    if threads is not None and device.type != "cpu":
        raise DbenchInputError(f"threads: {threads!r} sets CPU threads (ONNX Runtime's on the "
                               f"host path, PyTorch's on a CPU device); the {device.type} "
                               "device path has none; leave it unset")
    hp, wp = h + (-h) % MULTIPLE, w + (-w) % MULTIPLE
    expect = [(1, e, hp >> l, wp >> l) for l, e in enumerate(info["enc_widths"])]
    hidden = _state_on(method._hidden if params["recurrent"] else None, device, expect, (h, w))
    emitter = getattr(data, "emitter", None)
    if emitter is not None:
        emitter = lt.check_tensor("emitter", emitter, 1, (h, w))
    key = str(device)
    net = method._device_nets.get(key)
    if net is None:
        net = method._device_nets[key] = build_net(model, info, device)
    prev_threads = torch.get_num_threads()
    if threads:
        torch.set_num_threads(int(threads))
    try:
        with torch.inference_mode(), lt.float32_precision():
            exposure = (lt.autoexposure(color) if info["autoexposure"]
                        else torch.ones((), dtype=torch.float64, device=device))
            x, a_eff = lt.encode_planar(color, bufs, info["features"], exposure, MULTIPLE)
            y, new_hidden = net(x[None], hidden)
            out = lt.decode_planar(y[0], a_eff, exposure)
            out = lt.keep_emitters(color, out, emitter)
    finally:
        if threads:
            torch.set_num_threads(prev_threads)
    if params["recurrent"]:
        method._hidden = list(new_hidden)
    return out


__all__ = ["build_net", "denoise_device"]
