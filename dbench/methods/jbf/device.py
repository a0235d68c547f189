"""``jbf`` on a device: the guide built there and the window as one Triton launch
(:mod:`dbench.methods.kernels.gpu`; docs/gpu.md §2). The ``jbf`` mode only; the illumination
mode runs on the host."""
from __future__ import annotations

from typing import Any

from ..kernels.gpu.bilateral import window_filter
from ..kernels.gpu.guide import E_CUT, color_planes, depth_or_hit, make_device_guide
from .params import GUIDE_OPTIONS

def jbf_device(frame: Any, params: dict) -> tuple[Any, dict]:
    """The JBF of a :class:`~dbench.device.DeviceFrame`: ((H, W, 3) float32 tensor, settings)."""
    import torch

    h, w = frame.shape
    opts = {k: params[k] for k in GUIDE_OPTIONS}
    guide = make_device_guide(frame.albedo, frame.normal, depth_or_hit(frame), frame.position,
                              shape=(h, w), emitter=frame.emitter, **opts)
    planes, scale = color_planes(frame.color)
    out = torch.empty((h, w, 3), dtype=torch.float32, device=planes.device)
    window_filter(guide.feat, guide.labels, planes, scale, out, radius=guide.radius,
                  inv_x=guide.inv_x, inv_y=guide.inv_y, disk=guide.disk, e_cut=E_CUT)
    return out, dict(mode="jbf", **guide.settings)
