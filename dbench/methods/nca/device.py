"""The NCA on a device (``NCADenoiser.denoise_device``, :mod:`dbench.device`): the host pipeline
of :func:`dbench.methods.nca.nca_denoise` with every step a PyTorch operation on the frame's
device.

Pipeline (shapes for an H x W frame):

    color, normal, albedo (H, W, 3) tensors
      --auto-exposure, encoding (kernels/learned_torch.py)--> state (1, 9, H, W)
      --the PyTorch automaton (model.py, the shipped W, b and gate), `iterations` steps-->
    RGB state (3, H, W) --max(expm1(.), 0) · a_eff / exposure, keep_emitters--> (H, W, 3)

The automaton runs its fast path (:class:`~dbench.methods.nca.model.FoldedNCA`: per step one
3x3 convolution with the folded perception · W weights, the ONNX graph's form, export.py)
instead of the 39 perception channels: the same map (tests), a quarter of the memory traffic.
The step count, the noise level and γ come from the frame's metadata and the parameters, host
values; nothing is read back from the device. Convolutions run in IEEE float32
(:func:`~dbench.methods.kernels.learned_torch.float32_precision`).

Agreement with the host path (ONNX Runtime), stated and measured in
tests/methods/test_nca_device.py: |device − host| ≤ 2e-6 + 2e-5 |host| (measured on the CPU over
32x48 frames at 1-1024 spp: max abs 7.7e-7, max relative 7.5e-6; on an H200 at 1280x720:
7.8e-7 and 7.5e-6, 3.0 ms per frame against the host path's 114 ms). The input policy is the
host's (module docstring of :mod:`dbench.methods.nca`); a non-finite state decodes as 0, as
on the host.
"""
from __future__ import annotations

from typing import Any

import numpy as np
import torch

from ...errors import DbenchInputError
from ..kernels import learned_torch as lt
from ..kernels.hdr_input import noise_level


def build_net(info: dict[str, Any], device: torch.device) -> torch.nn.Module:
    """The folded automaton with the weights, the gate and the settings of a model's ``info``
    (``nca._model_info``: W, b and the gate read from its metadata), in eval mode on
    ``device``."""
    from .model import NCA, FoldedNCA

    gate = info["noise_gate"]
    nca = NCA(info["update_channels"], info["activation"], noise_gate=gate is not None,
              gate_init=gate or (0.0, 0.0), gate_max=info["gate_max"])
    with torch.no_grad():
        nca.W.copy_(torch.from_numpy(info["W"]))
        nca.b.copy_(torch.from_numpy(info["b"]))
    net = FoldedNCA(nca).to(device).eval()
    net.requires_grad_(False)
    return net


def denoise_device(method: Any, data: Any, info: dict[str, Any], spp: float | None,
                   iterations: Any) -> torch.Tensor:
    """``method`` (an :class:`~dbench.methods.nca.NCADenoiser`) on a
    :class:`~dbench.device.DeviceFrame`: (H, W, 3) float32 on the frame's device. ``info``:
    the model's settings and weights (``nca._model_info``); ``spp``: the frame's sample count
    (None: 1 spp); ``iterations``: the step count to run (checked here). Models are cached per
    device in ``method._device_nets``."""
    params = method.params
    color = lt.check_tensor("color", getattr(data, "color", None), 3)
    hw = tuple(color.shape[:2])
    for name in ("normal", "albedo"):
        if getattr(data, name, None) is None:
            raise DbenchInputError(f"{name}: missing; nca needs an (H, W, 3) {name} buffer")
    normal = lt.check_tensor("normal", data.normal, 3, hw)
    albedo = lt.check_tensor("albedo", data.albedo, 3, hw)
    threads = params["threads"]
    if threads is not None and color.device.type != "cpu":
        raise DbenchInputError(f"threads: {threads!r} sets CPU threads (ONNX Runtime's on the "
                               f"host path, PyTorch's on a CPU device); the {color.device.type} "
                               "device path has none; leave it unset")
    k = iterations
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 0:
        raise DbenchInputError(f"iterations: expected an integer >= 0, got {k!r}")
    key = str(color.device)
    net = method._device_nets.get(key)
    if net is None:
        net = method._device_nets[key] = build_net(info, color.device)
    demodulate = info["encoding"] == "log1p_demodulated"
    level = 0.0 if spp is None else noise_level(spp)
    prev_threads = torch.get_num_threads()
    if threads:
        torch.set_num_threads(int(threads))
    try:
        with torch.inference_mode(), lt.float32_precision():
            exposure = (lt.autoexposure(color) if info["autoexposure"]
                        else torch.ones((), dtype=torch.float64, device=color.device))
            state, a_eff = lt.encode_planar(color, {"albedo": albedo, "normal": normal},
                                            ("normal", "albedo"), exposure,
                                            demodulate=demodulate)
            rgb = net(state[None], int(k), level)[0, :3]
            out = lt.decode_planar(rgb, a_eff if demodulate else None, exposure)
            emitter = getattr(data, "emitter", None)
            if emitter is not None:
                emitter = lt.check_tensor("emitter", emitter, 1, hw)
            return lt.keep_emitters(color, out, emitter)
    finally:
        if threads:
            torch.set_num_threads(prev_threads)


__all__ = ["build_net", "denoise_device"]
