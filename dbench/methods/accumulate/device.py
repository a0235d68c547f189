"""``accumulate`` on a device (docs/temporal.md; the method's maths in its package docstring):
per frame one reprojection launch (the frame's geometry, the previous history's 6 planes
reprojected) and one accumulation launch (:mod:`dbench.methods.kernels.gpu.temporal`), plus one
TAA launch when ``taa`` is on. The history (two alternating (11, H, W) buffers) stays on the
device between frames (:class:`~dbench.methods.temporal.device.DeviceHistory`).

Shapes: the frame's buffers (H, W, C) float32 tensors; the output (H, W, 3) float32 on the same
device. ``last`` holds ``variance`` (H, W), ``n`` (H, W) and ``status`` (H, W) uint8 tensors,
valid until the next call.
"""
from __future__ import annotations

from typing import Any

from ..kernels.gpu.runtime import cdiv
from ..kernels.gpu.temporal import BASE, accumulate_kernel, block_for
from ..temporal.device import DeviceHistory, camera_origin, device_buffer

#: the history's planes: colour (3), moments (2), N
PLANES = 6


def accumulate_device(method: Any, frame: Any):
    """One frame of ``accumulate`` (the instance ``method``, whose device history this keeps in
    ``method._device_history``) on a :class:`~dbench.device.DeviceFrame`: (H, W, 3) tensor."""
    import torch

    from ...errors import DbenchInputError

    p = method.params
    color = frame.buffers.get("color")
    if color is None or color.dim() != 3 or color.shape[2] != 3:
        raise DbenchInputError("color: expected shape (H, W, 3), got "
                               f"{None if color is None else tuple(color.shape)}")
    h, w = int(color.shape[0]), int(color.shape[1])
    color = device_buffer(frame, "color", h, w, 3)
    depth = device_buffer(frame, "depth", h, w, 1)
    normal = device_buffer(frame, "normal", h, w, 3)
    position = device_buffer(frame, "position", h, w, 3)
    motion = device_buffer(frame, "motion", h, w, 2, required=False)
    origin = camera_origin(frame.meta)

    hist = getattr(method, "_device_history", None)
    if hist is None:
        hist = method._device_history = DeviceHistory(PLANES, p["tau_d"], p["tau_n"])
    flag = hist.taa_flag(bool(p["taa"]), color.device)
    _, new, fetched, status, _ = hist.reproject(depth, normal, position, motion, PLANES,
                                                "accumulate", flag)
    out = torch.empty((h, w, 3), dtype=torch.float32, device=color.device)
    var = hist.work("variance", (h, w))
    blk = block_for(h * w, color.device)
    accumulate_kernel[(cdiv(h * w, blk),)](color, fetched, status, new, out, var,
                                           float(p["alpha_min"]), float(p["n_max"]), h, w,
                                           BLOCK=blk)
    hist.commit(origin, "accumulate")
    method.last = {"variance": var, "n": new[BASE + 5], "status": status}
    if p["taa"]:
        out = hist.taa(out, motion, float(p["taa_alpha"]), flag)
    return out


__all__ = ["accumulate_device"]
