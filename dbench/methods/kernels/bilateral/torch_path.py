"""PyTorch fast path of the base filter (CUDA when available): the same maths as
:func:`~.numba2d.accumulate`, a loop over the half window on whole shifted images."""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from .guide import Guide
from .reference import shift_slices


def accumulate_torch(guide: Guide, planes: np.ndarray, *, theta: np.ndarray | None = None,
                     var: np.ndarray | None = None, nint: np.ndarray | None = None,
                     g2: float | None = None, g2_table: np.ndarray | None = None,
                     device: Any = None, dtype: Any = None) -> np.ndarray:
    """PyTorch version of :func:`accumulate` for the JBF and the statistical test.

    Loops over the half window; per offset it works on whole shifted images (O(P·H·W) memory,
    no unfold). Weights in ``dtype`` (default float32; float64 for exact comparisons), the
    Welch test always in float64. ``device`` defaults to CUDA when available, else CPU.

    Returns:
        (P, H, W) float64 NumPy sums without the centre term.
    """
    import torch

    if device is None:
        device = "cuda" if torch.cuda.is_available() else "cpu"
    dtype = torch.float32 if dtype is None else dtype
    h, w = guide.shape
    tp = torch.as_tensor(np.asarray(planes), device=device).to(dtype)
    acc = torch.zeros_like(tp)
    # pre-scaled, centred features as in the Numba path: (F_i − F_j)² sums to the exponent
    scaled = [(f - float(np.mean(f))) * math.sqrt(0.5 * iv)
              for f, iv in zip(guide.features, guide.inv_var) if iv > 0]
    feats = torch.as_tensor(np.stack(scaled) if scaled else np.zeros((0, h, w)),
                            device=device).to(dtype)
    labels = torch.as_tensor(guide.labels, device=device)
    test = theta is not None
    if test:
        th = torch.as_tensor(np.asarray(theta, np.float64), device=device)
        va = torch.as_tensor(np.asarray(var, np.float64), device=device)
        if g2_table is not None:
            ni = torch.as_tensor(np.asarray(nint, np.int64), device=device)
            tab = torch.as_tensor(np.asarray(g2_table, np.float64), device=device)
    half = (guide.dy > 0) | ((guide.dy == 0) & (guide.dx > 0))
    order = np.lexsort((guide.dx[half], guide.dy[half]))
    dys, dxs, es64 = guide.dy[half][order], guide.dx[half][order], guide.spatial[half][order]
    for dy, dx, e in zip(dys.tolist(), dxs.tolist(), es64.tolist()):
        (ys, xs), (yn, xn) = shift_slices(dy, dx, h, w)
        if ys.start >= ys.stop or xs.start >= xs.stop:
            continue
        expo = ((feats[:, ys, xs] - feats[:, yn, xn]) ** 2).sum(0) + e
        wk = torch.exp(-expo) * (labels[ys, xs] == labels[yn, xn])
        if test:
            d = th[:, ys, xs] - th[:, yn, xn]
            s = va[:, ys, xs] + va[:, yn, xn]
            if g2_table is None:
                g = g2
            else:
                nu = (ni[:, ys, xs] + ni[:, yn, xn] - 2).clamp(0, tab.shape[0] - 1)
                g = tab[nu]
            ok = ((d * d < g * s) | (d == 0)).all(0)
            wk = wk * ok
        acc[:, ys, xs] += wk * tp[:, yn, xn]
        acc[:, yn, xn] += wk * tp[:, ys, xs]
    return acc.double().cpu().numpy()


def torch_cuda_available() -> bool:
    try:
        import torch
    except ImportError:  # pragma: no cover - torch is a dependency
        return False
    return bool(torch.cuda.is_available())
