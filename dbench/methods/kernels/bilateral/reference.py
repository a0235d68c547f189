"""The readable definition of the base weights ρ_ij·h_ij (NumPy, float64, whole shifted images),
on which the references of ``jbf`` and ``statistical`` build."""
from __future__ import annotations

import numpy as np

from .guide import Guide


def shift_slices(dy: int, dx: int, h: int, w: int):
    """Slices (centre, neighbour) such that ``a[centre]`` pairs pixel i with ``b[neighbour]`` = i + o.

    Only centres whose neighbour lies inside the image appear: out-of-image neighbours simply
    do not exist (no padding enters any sum, docs/methods/jbf.md §1.3).
    """
    ny = max(0, h - abs(dy))
    nx = max(0, w - abs(dx))
    y0, x0 = max(0, -dy), max(0, -dx)
    ys, xs = slice(y0, y0 + ny), slice(x0, x0 + nx)
    yn, xn = slice(y0 + dy, y0 + dy + ny), slice(x0 + dx, x0 + dx + nx)
    return (ys, xs), (yn, xn)


def reference_weights(guide: Guide, k: int) -> np.ndarray:
    """ρ_ij · h_ij for offset ``k`` of the guide, for every centre i: (H, W) float64.

    ρ_ij = exp(−½ Σ_k (p_j,k − p_i,k)² Σ⁻¹_kk) with the spatial part precomputed per offset
    (docs/methods/jbf.md §1.1); h_ij = [label_i == label_j]; 0 where j = i + o lies outside the image.
    """
    h, w = guide.shape
    dy, dx = int(guide.dy[k]), int(guide.dx[k])
    out = np.zeros((h, w))
    (ys, xs), (yn, xn) = shift_slices(dy, dx, h, w)
    if ys.start >= ys.stop or xs.start >= xs.stop:
        return out
    expo = np.full(out[ys, xs].shape, guide.spatial[k])
    for f, iv in zip(guide.features, guide.inv_var):
        if iv != 0.0:
            expo += 0.5 * (f[yn, xn] - f[ys, xs]) ** 2 * iv
    same = guide.labels[yn, xn] == guide.labels[ys, xs]
    out[ys, xs] = np.exp(-expo) * same
    return out


def safe_divide(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    out = np.divide(num, den, out=np.zeros_like(num), where=den > 0)
    return out
