"""PyTorch backend of the SVGF / A-SVGF core (docs/methods/svgf.md): the same filters as
:mod:`dbench.methods.svgf.reference`, vectorised over whole images.

Every function takes NumPy arrays or tensors and returns float32 (bool for masks) tensors on the
device of its first tensor argument, else CUDA when available, else CPU
(:func:`dbench.methods.temporal.torch_device`). The NumPy-facing dispatchers of ``dispatch``
(``atrous``, ``spatial_variance``, …) convert at their boundary. Neighbourhoods are slices of
one zero-padded stack of planes per offset (no unfold: O(planes·H·W) memory), so a tap outside
the image reads ``tap = 0`` and gets weight 0 exactly as in the reference.

Arithmetic: float32 with the exact ``exp`` (the Numba path uses a polynomial ``exp``, the
reference float64); positions, depth gradients and the A-SVGF gradient values are float64 like
the reference. Tests (tests/methods/test_svgf.py, test_asvgf.py) bound the difference to the
reference by rtol 1e-4 / atol 1e-5 per kernel.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ...errors import DbenchInputError
from ..temporal import LUMA, as_tensor, torch_device
from .params import ALBEDO_FLOOR, EPS_VAR, EPS_Z, G3, H1, SPATIAL_RADIUS
from .reference import emission_planar


def _dev(*arrays: Any, device: Any = None):
    if device is not None:
        return device
    import torch
    for a in arrays:
        if isinstance(a, torch.Tensor):
            return a.device
    return torch_device()


def _f32(a, dev):
    import torch
    return as_tensor(a, dev, torch.float32)


def luminance_t(c):
    """Rec. 709 luminance (H, W) of a planar (3, H, W) tensor."""
    return float(LUMA[0]) * c[0] + float(LUMA[1]) * c[1] + float(LUMA[2]) * c[2]


def _padded(planes, pad: int):
    """(P, H + 2·pad, W + 2·pad) zero-padded copy of a (P, H, W) stack."""
    import torch.nn.functional as F
    return F.pad(planes, (pad, pad, pad, pad))


def prepare_torch(color, albedo, emission, hit, device=None,
                  albedo_floor: float = ALBEDO_FLOOR) -> dict:
    """:func:`~dbench.methods.svgf.reference.prepare_reference` on tensors: interleaved (H, W, 3)
    colour and albedo in, planar ``illum``, ``a_eff``, ``emission`` (3, H, W), ``moments``
    (2, H, W), ``lum_raw`` (H, W) float32 and bool ``present``, ``emitter`` (H, W) out. The
    emission buffer is validated in NumPy (errors name it) before it is moved."""
    import torch
    dev = _dev(color, device=device)
    c = _f32(color, dev).permute(2, 0, 1)
    h, w = c.shape[1:]
    present = torch.isfinite(c).all(0)
    a = _f32(albedo, dev).permute(2, 0, 1)
    a_eff = torch.where(torch.isfinite(a), a.clamp(min=float(albedo_floor), max=1.0), 1.0)
    e = _f32(emission_planar(emission, h, w) if emission is not None
             else np.zeros((3, h, w), np.float32), dev)
    illum = torch.where(present, (c - e) / a_eff, 0.0)
    lum = luminance_t(illum)
    c0 = torch.where(present, c, 0.0)
    lum_raw = torch.where(present, luminance_t(c0), float("nan"))
    hit_t = as_tensor(hit, dev, torch.bool)
    return {"illum": illum.contiguous(), "a_eff": a_eff.contiguous(), "emission": e,
            "present": present, "emitter": hit_t & (e.amax(0) > 0),
            "moments": torch.stack([lum, lum * lum]), "lum_raw": lum_raw}


def remodulate_torch(illum, a_eff, emission, device=None):
    """(H, W, 3) float32 tensor a_eff · I + E from planar (3, H, W) inputs."""
    dev = _dev(illum, device=device)
    return (_f32(illum, dev) * _f32(a_eff, dev) + _f32(emission, dev)).permute(1, 2, 0)


def depth_gradient_torch(z, hit, device=None):
    """:func:`~dbench.methods.svgf.reference.depth_gradient_reference` (smaller one-sided
    difference, one-sided at borders and next to pixels without hit, 0 without hit): (gx, gy)
    float32 tensors."""
    import torch
    dev = _dev(z, hit, device=device)
    z = as_tensor(z, dev, torch.float64)
    hit = as_tensor(hit, dev, torch.bool)
    out = []
    for dim in (1, 0):  # x then y
        n = z.shape[dim]
        fwd = torch.zeros_like(z)
        hp = torch.zeros_like(hit)
        lo, hi = [slice(None)] * 2, [slice(None)] * 2
        lo[dim], hi[dim] = slice(0, n - 1), slice(1, n)
        fwd[tuple(lo)] = z[tuple(hi)] - z[tuple(lo)]
        hp[tuple(lo)] = hit[tuple(hi)]
        bwd = torch.zeros_like(z)
        hm = torch.zeros_like(hit)
        bwd[tuple(hi)] = fwd[tuple(lo)]
        hm[tuple(hi)] = hit[tuple(lo)]
        both = torch.where(fwd.abs() <= bwd.abs(), fwd, bwd)
        g = torch.where(hp & hm, both, torch.where(hp, fwd, torch.where(hm, bwd, 0.0)))
        out.append(torch.where(hit, g, 0.0).float())
    return out[0], out[1]


def blur3_torch(var):
    """g₃ₓ₃(Var) (H, W): separable (1, 2, 1)/4 blur with edge replication."""
    import torch.nn.functional as F
    v = F.pad(var[None, None], (1, 1, 1, 1), mode="replicate")[0, 0]
    v = float(G3[0]) * v[:, :-2] + float(G3[1]) * v[:, 1:-1] + float(G3[2]) * v[:, 2:]
    return float(G3[0]) * v[:-2] + float(G3[1]) * v[1:-1] + float(G3[2]) * v[2:]


def atrous_torch(color, var, z, gx, gy, normal, tap, centre, hit, step, sigma_z=1.0,
                 sigma_n=128.0, sigma_l=4.0, eps_z=EPS_Z, eps_var=EPS_VAR, use_lum=True,
                 lum_kernel="laplacian", device=None):
    """One à-trous iteration (docs/methods/svgf.md §5) — arguments and shapes of
    :func:`~dbench.methods.svgf.reference.atrous_reference`. Returns (colour (3, H, W),
    variance (H, W)) float32 tensors."""
    import torch
    dev = _dev(color, var, device=device)
    c = _f32(color, dev)
    v = _f32(var, dev)
    z = _f32(z, dev)
    n = _f32(normal, dev)
    gx, gy = _f32(gx, dev), _f32(gy, dev)
    h, w = z.shape
    lum = luminance_t(c)
    if use_lum:
        inv_sl = 1.0 / (sigma_l * torch.sqrt(blur3_torch(v).clamp(min=0.0) + eps_var))
    else:
        inv_sl = torch.zeros_like(z)
    hitf = _f32(hit, dev)
    cen = _f32(centre, dev) * float(H1[2] * H1[2])
    sw = cen.clone()
    sc = cen * c
    sv = cen * cen * v
    pad = 2 * step
    # planes read at the taps: normal 0-2, z 3, lum 4, tap 5, colour 6-8, variance 9
    q_all = _padded(torch.cat([n, z[None], lum[None], _f32(tap, dev)[None], c, v[None]]), pad)
    for oy in range(-2, 3):
        for ox in range(-2, 3):
            if ox == 0 and oy == 0:
                continue
            dy, dx = oy * step, ox * step
            q = q_all[:, pad + dy:pad + dy + h, pad + dx:pad + dx + w]
            wn = (n * q[0:3]).sum(0).clamp(min=0.0) ** sigma_n
            wz = (z - q[3]).abs() / (sigma_z * (gx * dx + gy * dy).abs() + eps_z)
            wl = (lum - q[4]).abs() * inv_sl
            if lum_kernel == "gaussian":
                wl = wl * wl
            wt = float(H1[ox + 2] * H1[oy + 2]) * wn * torch.exp(-(wz + wl)) * q[5] * hitf
            sw += wt
            sc += wt * q[6:9]
            sv += wt * wt * q[9]
    good = sw > 0
    safe = torch.where(good, sw, 1.0)
    return torch.where(good, sc / safe, 0.0), torch.where(good, sv / (safe * safe), 0.0)


def spatial_variance_torch(mom, z, gx, gy, normal, tap, hit, select=None, sigma_z=1.0,
                           sigma_n=128.0, eps_z=EPS_Z, radius=SPATIAL_RADIUS, device=None):
    """Spatial variance (docs/methods/svgf.md §4) of
    :func:`~dbench.methods.svgf.reference.spatial_variance_reference` over the (2r+1)² window, 0 where ``select`` (H, W) is False: (H, W) float32 tensor. The
    window sums are float64 (m₂ − m₁² cancels)."""
    import torch
    dev = _dev(mom, z, device=device)
    f64 = torch.float64
    m = as_tensor(mom, dev, f64)
    z = _f32(z, dev)
    n = _f32(normal, dev)
    gx, gy = _f32(gx, dev), _f32(gy, dev)
    h, w = z.shape
    hitf = _f32(hit, dev)
    sw = torch.ones((h, w), dtype=f64, device=dev)
    s1, s2 = m[0].clone(), m[1].clone()
    q_all = _padded(torch.cat([n, z[None], _f32(tap, dev)[None], m.float()]), radius)
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            if dx == 0 and dy == 0:
                continue
            q = q_all[:, radius + dy:radius + dy + h, radius + dx:radius + dx + w]
            wn = (n * q[0:3]).sum(0).clamp(min=0.0) ** sigma_n
            wz = torch.exp(-(z - q[3]).abs() / (sigma_z * (gx * dx + gy * dy).abs() + eps_z))
            wt = (wn * wz * q[4] * hitf).double()
            sw += wt
            s1 += wt * q[5].double()
            s2 += wt * q[6].double()
    m1, m2 = s1 / sw, s2 / sw
    out = (m2 - m1 * m1).clamp(min=0.0).float()
    if select is not None:
        out = torch.where(as_tensor(select, dev, torch.bool), out, 0.0)
    return out


# ---------------------------------------------------------------------------------------------
# A-SVGF temporal gradients (docs/methods/svgf.md §6)


def stratum_gradients_torch(l_prev, l_grad, prev_hit, prev_depth, prev_normal, size=3,
                            device=None) -> dict:
    """Per-stratum gradients of
    :func:`~dbench.methods.svgf.reference.stratum_gradients_reference` on tensors: the argmax of each size×size block (ties: first in row-major order, as ``np.argmax``).
    Returns ``delta``, ``norm``, ``g``, ``depth`` (hs, ws) float32, ``has`` bool,
    ``normal`` (3, hs, ws) float32."""
    import torch
    dev = _dev(l_prev, device=device)
    f64 = torch.float64
    lp_img = as_tensor(l_prev, dev, f64)
    lg_img = as_tensor(l_grad, dev, f64)
    h, w = lp_img.shape
    hs, ws = -(-h // size), -(-w // size)
    usable = as_tensor(prev_hit, dev, torch.bool) & torch.isfinite(lp_img) & torch.isfinite(lg_img)
    pad = torch.full((hs * size, ws * size), -torch.inf, dtype=f64, device=dev)
    pad[:h, :w] = torch.where(usable, lp_img, -torch.inf)
    blocks = pad.reshape(hs, size, ws, size).permute(0, 2, 1, 3).reshape(hs, ws, size * size)
    k = torch.argmax(blocks, dim=-1)
    has = torch.isfinite(torch.gather(blocks, -1, k[..., None])[..., 0])
    qy = (torch.arange(hs, device=dev)[:, None] * size + k // size).clamp(max=h - 1)
    qx = (torch.arange(ws, device=dev)[None, :] * size + k % size).clamp(max=w - 1)
    lp = torch.where(has, lp_img[qy, qx], 0.0)
    lg = torch.where(has, lg_img[qy, qx], 0.0)
    d = torch.maximum(lp, lg)
    g = torch.where(d > 0, ((lg - lp).abs() / torch.where(d > 0, d, 1.0)) ** 2, 0.0)
    depth = _f32(prev_depth, dev)
    normal = _f32(prev_normal, dev)
    return {"delta": (lg - lp).float(), "norm": d.float(),
            "g": torch.nan_to_num(g, nan=0.0).clamp(0.0, 1.0).float(), "has": has,
            "depth": torch.where(has, depth[qy, qx], 0.0),
            "normal": torch.where(has, normal[:, qy, qx], 0.0)}


def adaptive_history_torch(low, motion, hit, n_hist, n_max=256.0, mode="seed", alpha0=0.2,
                           size=3, device=None):
    """:func:`~dbench.methods.svgf.reference.adaptive_history_reference` on tensors: G gathered at
    round(p + motion) from the stratum image ``low`` (hs, ws), N' and α (docs/methods/svgf.md §6.1). Returns
    three (H, W) float32 tensors."""
    import torch
    dev = _dev(low, motion, device=device)
    f64 = torch.float64
    hit = as_tensor(hit, dev, torch.bool)
    h, w = hit.shape
    hs, ws = -(-h // size), -(-w // size)
    low = as_tensor(low, dev, f64)
    if tuple(low.shape) != (hs, ws):
        raise DbenchInputError(f"gradient strata: expected shape ({hs}, {ws}), "
                               f"got {tuple(low.shape)}")
    low = torch.nan_to_num(low, nan=0.0, posinf=0.0, neginf=0.0).clamp(0.0, 1.0)
    mot = as_tensor(motion, dev, f64)
    qx = torch.floor(torch.arange(w, device=dev, dtype=f64)[None, :] + mot[0] + 0.5)
    qy = torch.floor(torch.arange(h, device=dev, dtype=f64)[:, None] + mot[1] + 0.5)
    ok = hit & (qx >= 0) & (qy >= 0) & (qx < w) & (qy < h)  # False for NaN motion
    sy = torch.where(ok, qy, 0.0).long() // size
    sx = torch.where(ok, qx, 0.0).long() // size
    g = torch.where(ok, low[sy, sx], 0.0)
    n_new = torch.clamp(as_tensor(n_hist, dev, f64) * (1.0 - g) ** 10 + 1.0, max=float(n_max))
    a = (1.0 - g) / n_new + g
    if mode == "paper":
        a = torch.maximum((1.0 - g) * alpha0 + g, 1.0 / n_new)
    return g.float(), n_new.float(), a.float()


__all__ = ["adaptive_history_torch", "atrous_torch", "blur3_torch", "depth_gradient_torch",
           "luminance_t", "prepare_torch", "remodulate_torch", "spatial_variance_torch",
           "stratum_gradients_torch"]
