"""The base filter's guide built on the device from G-buffer tensors (docs/gpu.md §2): the
same checks and rules as :func:`dbench.methods.kernels.bilateral.guide.make_guide`, in PyTorch,
for :func:`.bilateral.window_filter`.

Differences in form, not in result: labels are int32 compared for equality in the kernel (the
Numba path encodes them as a feature plane 16·label), and an isolated pixel's label is
``LABEL_FIRST_ISOLATED`` plus its linear index (unique, as the host's running count is).

Shapes: G-buffers (H, W, 3) float32 tensors, depth (H, W, 1); outputs planar (K, H, W).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from ....errors import DbenchInputError
from ..bilateral.guide import check_sigma, inverse_variance, window_offsets
from ..bilateral.params import (EXP_CUTOFF, LABEL_BACKGROUND, LABEL_EMITTER, LABEL_FIRST_ISOLATED,
                                LABEL_HIT, PLANE_MAX)


@dataclass
class DeviceGuide:
    """feat (H, W, KP) float32 scaled features, zero-padded to KP = a power of two ≥ 2; labels
    (H, W) int32; the spatial inverse variances of x and y (0 switches them off); the window."""

    feat: Any
    labels: Any
    inv_x: float
    inv_y: float
    radius: int
    disk: bool
    settings: dict


def check_tensor(name: str, t: Any, h: int, w: int, c: int) -> Any:
    """``t`` as a contiguous float32 (h, w, c) tensor, or DbenchInputError naming ``name``."""
    import torch
    if t is None:
        raise DbenchInputError(f"{name}: missing; expected a tensor of shape ({h}, {w}, {c})")
    if t.ndim == 2 and c == 1:
        t = t[..., None]
    if tuple(t.shape) != (h, w, c):
        raise DbenchInputError(f"{name}: expected shape ({h}, {w}, {c}), got {tuple(t.shape)}")
    return t.to(torch.float32).contiguous()


def depth_or_hit(frame: Any):
    """The device form of :func:`dbench.methods.guards.depth_or_hit`: depth, else 1 where the
    normal is non-zero, else None."""
    import torch
    if frame.depth is not None:
        return frame.depth
    if frame.normal is None:
        return None
    return torch.any(frame.normal != 0, dim=-1, keepdim=True).to(torch.float32)


def make_device_guide(albedo, normal, depth, position, *, shape, radius: int = 20,
                      sigma=(10.0, 10.0, 0.02, 0.02, 0.02, 0.1, 0.1, 0.1),
                      sigma_convention: str = "variance", window: str = "square",
                      features=("xy", "albedo", "normal"), sigma_position: float = 0.01,
                      sigma_depth: float = 0.01, hit_mask: bool = True, emitter=None,
                      isolate=None) -> DeviceGuide:
    """:func:`~dbench.methods.kernels.bilateral.guide.make_guide` on tensors (parameters already
    checked by the method's constructor; ``isolate`` (H, W) bool marks further pixels to isolate,
    e.g. non-finite statistics)."""
    import torch

    h, w = shape
    features = (features,) if isinstance(features, str) else tuple(features)
    sigma = check_sigma(sigma)
    planes, inv = [], []
    for name, arr, first in (("albedo", albedo, 2), ("normal", normal, 5)):
        if name in features:
            t = check_tensor(name, arr, h, w, 3)
            planes += [t[..., c] for c in range(3)]
            inv += [inverse_variance(sigma[first + c], sigma_convention) for c in range(3)]
    if "position" in features:
        t = check_tensor("position", position, h, w, 3)
        planes += [t[..., c] for c in range(3)]
        inv += [inverse_variance(sigma_position, sigma_convention)] * 3
    d = None if depth is None else check_tensor("depth", depth, h, w, 1)[..., 0]
    if "depth" in features:
        if d is None:
            raise DbenchInputError(f"depth: missing; expected an array of shape ({h}, {w}, 1) "
                                   "because features include 'depth'")
        planes.append(d)
        inv.append(inverse_variance(sigma_depth, sigma_convention))
    dev = (planes[0] if planes else (d if d is not None else torch.zeros(1))).device
    feats = torch.stack(planes) if planes else torch.zeros((0, h, w), device=dev)
    bad = ~torch.isfinite(feats).all(0) if planes else torch.zeros((h, w), dtype=torch.bool,
                                                                    device=dev)
    if d is not None:
        bad |= ~torch.isfinite(d)
    if isolate is not None:
        bad |= isolate
    if hit_mask and d is not None:
        labels = torch.where(d > 0, LABEL_HIT, LABEL_BACKGROUND).to(torch.int32)
    else:
        labels = torch.full((h, w), LABEL_HIT, dtype=torch.int32, device=dev)
    if emitter is not None:
        seen = torch.nan_to_num(check_tensor("emitter", emitter, h, w, 1)[..., 0])
        labels = torch.where(seen >= 0.5, LABEL_EMITTER, labels).to(torch.int32)
    unique = LABEL_FIRST_ISOLATED + torch.arange(h * w, dtype=torch.int32,
                                                 device=dev).reshape(h, w)
    labels = torch.where(bad, unique, labels).contiguous()
    feats = torch.where(bad, 0.0, feats)
    # centred per plane (float32 precision of the differences), scaled by sqrt(½Σ⁻¹)
    scaled = [(feats[i] - feats[i].mean()) * math.sqrt(0.5 * iv)
              for i, iv in enumerate(inv) if iv > 0]
    # interleaved (H, W, KP), zero-padded to a power of two ≥ 2: one wide load per pixel
    kp = max(2, 1 << max(len(scaled) - 1, 0).bit_length())
    feat = torch.zeros((h, w, kp), device=dev)
    if scaled:
        feat[..., :len(scaled)] = torch.stack(scaled, -1)
    ix = iy = 0.0
    if "xy" in features:
        ix = inverse_variance(sigma[0], sigma_convention)
        iy = inverse_variance(sigma[1], sigma_convention)
    window_offsets(radius, window)  # validates radius and window as the host does
    settings = dict(radius=int(radius), sigma=sigma, sigma_convention=sigma_convention,
                    window=window, features=features, sigma_position=sigma_position,
                    sigma_depth=sigma_depth, hit_mask=bool(hit_mask))
    return DeviceGuide(feat.to(torch.float32).contiguous(), labels, ix, iy, int(radius),
                       window == "disk", settings)


def color_planes(color):
    """(H, W, 4) float32 planes (r·v, g·v, b·v, v) of an (H, W, 3) colour tensor, v = all
    channels finite, and the (4,) factors that keep huge planes finite in the float32 window sums:
    a plane whose largest finite |value| exceeds :data:`PLANE_MAX` is divided by a power of two
    (exact), as :func:`~dbench.methods.kernels.bilateral.numba2d.accumulate` does."""
    import torch
    c = color.to(torch.float32).permute(2, 0, 1)
    valid = torch.isfinite(c).all(0)
    col = torch.where(valid, c, 0.0)
    peak = col.abs().amax(dim=(1, 2))
    exps = torch.where(peak > PLANE_MAX, torch.ceil(torch.log2(peak.double() / PLANE_MAX)),
                       torch.zeros_like(peak, dtype=torch.float64))
    scale = torch.exp2(exps).to(torch.float32)
    planes = torch.cat([col / scale[:, None, None], valid[None].to(torch.float32)])
    return planes.permute(1, 2, 0).contiguous(), torch.cat([scale, scale.new_ones(1)]).contiguous()


#: Offsets whose spatial exponent reaches this give weight exactly 0 and are skipped.
E_CUT = EXP_CUTOFF

__all__ = ["DeviceGuide", "E_CUT", "check_tensor", "color_planes", "depth_or_hit",
           "make_device_guide"]
