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
from ..temporal.device import DeviceHistory, camera_origin, sequence_buffers

#: the history's planes: colour (3), moments (2), N
PLANES = 6


def accumulate_device(method: Any, frame: Any):
    """One frame of ``accumulate`` (the instance ``method``, whose device history this keeps in
    ``method._device_history``) on a :class:`~dbench.device.DeviceFrame`: (H, W, 3) tensor."""
    import torch

    p = method.params
    h, w, b = sequence_buffers(frame, ("color", "depth", "normal", "position", "motion"))
    color, depth, normal, position, motion = (b["color"], b["depth"], b["normal"],
                                              b["position"], b["motion"])
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
