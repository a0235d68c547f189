"""The PyTorch backend of the temporal machinery (CUDA when available, CPU tensors otherwise):
the same maths as :mod:`.reference`, vectorised; tensors in and out, plus the device and
conversion helpers the temporal methods' PyTorch paths share."""
from __future__ import annotations

from typing import Any

import numpy as np

from .params import BILINEAR, EPS_F, FALLBACK, FALLBACK_KERNEL, N_MAX, RESET, TAU_D, TAU_N


def torch_cuda_available() -> bool:
    """True when PyTorch is importable and sees a CUDA device."""
    from ..kernels.bilateral.torch_path import torch_cuda_available as available
    return available()


def torch_device(like: Any = None):
    """The device of tensor ``like``; else CUDA when available, else CPU."""
    import torch
    if isinstance(like, torch.Tensor):
        return like.device
    return torch.device("cuda" if torch.cuda.is_available() else "cpu")


def as_tensor(a: Any, device: Any = None, dtype: Any = None):
    """``a`` (ndarray or tensor) as a tensor on ``device`` (default: :func:`torch_device`);
    ``dtype`` None keeps float32/bool/integer types as they are (float64 arrays stay float64)."""
    import torch
    device = torch_device(a) if device is None else device
    if isinstance(a, torch.Tensor):
        return a.to(device=device, dtype=dtype or a.dtype)
    return torch.as_tensor(np.ascontiguousarray(a), device=device, dtype=dtype)


def to_numpy(t: Any) -> np.ndarray:
    """Tensor (any device) or array → NumPy array (no copy for CPU tensors)."""
    if isinstance(t, np.ndarray):
        return t
    return t.detach().cpu().numpy()


def reproject_torch(history, motion, cur_hit, cur_normal, d_exp, prev_ok, prev_depth,
                    prev_normal, tau_d=TAU_D, tau_n=TAU_N, eps_f=EPS_F, device=None):
    """Vectorised PyTorch :func:`reproject_reference` (docs/methods/temporal.md §3.3-3.5): the four bilinear taps
    and the nine fallback taps of every pixel are gathers with (H, W) index tensors and masks.

    Same arguments and shapes as :func:`reproject_reference` (arrays or tensors); the device is
    ``device``, else that of ``history`` if it is a tensor, else CUDA when available, else CPU.
    Positions, weights and the validity tests are float64 — as in the reference, so that
    ``floor`` and the ``τ`` comparisons decide identically — the blend is float32.

    Returns:
        (reprojected (C, H, W) float32 tensor, status (H, W) uint8 tensor), on that device.
    """
    import torch
    dev = torch_device(history) if device is None else device
    f64 = torch.float64
    hist = as_tensor(history, dev, torch.float32)
    c, h, w = hist.shape
    mot = as_tensor(motion, dev, f64)
    hit = as_tensor(cur_hit, dev, torch.bool)
    n_p = as_tensor(cur_normal, dev, f64)
    de = as_tensor(d_exp, dev, f64)
    p_ok = as_tensor(prev_ok, dev, torch.bool).reshape(-1)
    p_dep = as_tensor(prev_depth, dev, f64).reshape(-1)
    p_nrm = as_tensor(prev_normal, dev, f64).reshape(3, -1)
    hist_f = hist.reshape(c, -1)

    active = hit & torch.isfinite(mot).all(0)
    yy = torch.arange(h, device=dev, dtype=f64)[:, None]
    xx = torch.arange(w, device=dev, dtype=f64)[None, :]
    # inactive pixels get p← = p so that no NaN reaches floor/long()
    px = xx + torch.where(active, mot[0], 0.0)
    py = yy + torch.where(active, mot[1], 0.0)

    def tap(qx, qy):
        """(valid (H, W) bool, flat index (H, W) int64) of previous-frame taps (qx, qy)."""
        inside = (qx >= 0) & (qy >= 0) & (qx < w) & (qy < h) & active
        idx = torch.where(inside, qy * w + qx, 0)
        ok = inside & p_ok[idx]
        ok &= (p_dep[idx] - de).abs() <= tau_d * de
        ok &= (p_nrm[:, idx] * n_p).sum(0) >= tau_n
        return ok, idx

    x0f, y0f = torch.floor(px), torch.floor(py)
    wx, wy = px - x0f, py - y0f
    x0, y0 = x0f.long(), y0f.long()
    f = torch.zeros((h, w), dtype=f64, device=dev)
    acc = torch.zeros((c, h, w), dtype=torch.float32, device=dev)
    for t in range(4):  # the 2×2 bilinear footprint (§3.3)
        bx = wx if t & 1 else 1.0 - wx
        by = wy if t >> 1 else 1.0 - wy
        b = bx * by
        ok, idx = tap(x0 + (t & 1), y0 + (t >> 1))
        b = torch.where(ok & (b > 0), b, 0.0)
        f += b
        acc += b.float() * hist_f[:, idx]
    bil = f > eps_f
    out = torch.where(bil, acc / torch.where(bil, f, 1.0).float(), 0.0)

    # the normalised 3×3 fallback (§3.4), evaluated where the bilinear test failed
    need = active & ~bil
    cx, cy = torch.floor(px + 0.5).long(), torch.floor(py + 0.5).long()
    g = torch.zeros((h, w), dtype=f64, device=dev)
    acc = torch.zeros_like(acc)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            ok, idx = tap(cx + dx, cy + dy)
            k = torch.where(ok & need, float(FALLBACK_KERNEL[dy + 1, dx + 1]), 0.0)
            g += k
            acc += k.float() * hist_f[:, idx]
    fb = need & (g > 0)
    out = torch.where(fb, acc / torch.where(fb, g, 1.0).float(), out)
    status = torch.where(bil, BILINEAR, torch.where(fb, FALLBACK, RESET)).to(torch.uint8)
    return out, status


def accumulate_torch(sample, history, n_hist, ok, alpha_min: float = 0.0, n_max: float = N_MAX,
                     alpha=None, sample_ok=None, device=None):
    """PyTorch :func:`accumulate` (same arguments, arrays or tensors; same float32 arithmetic).

    Returns:
        (accumulated (C, H, W), N (H, W), α (H, W)) float32 tensors on the device of
        ``sample`` (a tensor) or ``device``, else CUDA when available, else CPU.
    """
    import torch
    dev = torch_device(sample) if device is None else device
    f32 = torch.float32
    s = as_tensor(sample, dev, f32)
    hst = as_tensor(history, dev, f32)
    nh = as_tensor(n_hist, dev, f32)
    ok = as_tensor(ok, dev, torch.bool)
    n = torch.where(ok, torch.clamp(nh + 1.0, max=float(n_max)), 1.0)
    if alpha is None:
        a = torch.clamp(1.0 / n, min=float(np.float32(alpha_min)))
    else:
        a = as_tensor(alpha, dev, f32)
    a = torch.where(ok, a, 1.0)
    if sample_ok is None:
        return a * s + (1.0 - a) * hst, n, a
    sok = as_tensor(sample_ok, dev, torch.bool)
    s = torch.where(sok, s, 0.0)
    out = torch.where(sok, a * s + (1.0 - a) * hst, torch.where(ok, hst, 0.0))
    n = torch.where(sok, n, torch.where(ok, nh, 0.0))
    a = torch.where(sok, a, 0.0)
    return out, n, a
