"""A floor on the per-pixel variance of the mean for the ProDen gate [dbench]: each value is
raised to the mean of its channel over the (2r + 1)² window around the pixel (the part of it
inside the image).

Why: the gate's t-test (spec/statistical.md §12) trusts each pixel's variance estimate, but at a
few samples per pixel that estimate is itself noisy, and for heavy-tailed radiance (fireflies,
caustics) it is low exactly where the rare bright samples were missed. There the test declares
a good denoiser's output "significantly different" from the noisy mean and hands the pixel back
to the noise: on ``fireflies`` at 256², 16 spp, ``oidn+gate`` had 2.2x plain OIDN's relMSE.
The window's mean variance is the local noise level, an estimate from (2r + 1)² pixels instead
of one; taking the larger of the two keeps the test conservative where the pixel's own estimate
is too low, and as the spp grow both vanish, so the gate still converges to the input.
r = 5 is the gate's own 11×11 footprint.

* :func:`floored_variance` — the readable reference (SciPy box filters, float64).
* :func:`column_sums` and :func:`floor_row` — the compiled form, fused into the gate's passes
  (:func:`dbench.methods.kernels.gate.proden_gate_stats`): one pass sums each column's window,
  and the gate's row pass completes the sums along x and takes the maximum, so the floored
  variance is never stored (tests: the pooled fast gate equals the reference within 1e-6).

A kernel imports no method and nothing of the harness.

Example:
    >>> import numpy as np
    >>> v = np.zeros((5, 5, 1)); v[2, 2] = 9.0
    >>> float(floored_variance(v, 1)[2, 1, 0])   # the 3x3 window holds one 9 among 9 values
    1.0
"""
from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit, prange

from ..checks import check_radius

#: Radius of the window: the gate's 11×11 Gaussian footprint (kernels/gate.py GATE_TAPS).
POOL_RADIUS = 5


def floored_variance(var: Any, radius: int = POOL_RADIUS) -> np.ndarray:
    """max(var, mean of var over the (2r + 1)² window inside the image), per channel.

    Args:
        var: (H, W, C) variance of the mean, finite and ≥ 0. radius: r ≥ 0 (0: ``var``).

    Returns:
        (H, W, C) float64.
    """
    from scipy.ndimage import uniform_filter

    var = np.asarray(var, np.float64)
    r = check_radius(radius)
    if r == 0:
        return var.copy()
    size = (2 * r + 1, 2 * r + 1, 1)
    total = uniform_filter(var, size, mode="constant")
    inside = uniform_filter(np.ones(var.shape[:2] + (1,)), size, mode="constant")
    return np.maximum(var, total / inside)


@njit(inline="always")
def linear_value(var, x, box_cox_half, y, i):  # pragma: no cover - compiled
    """The linear variance of one value: ``var`` or, for Box-Cox ½ statistics, var · max(x, 0)
    (x the noisy colour); 0 where it is not finite (kernels/gate.py linear_variance)."""
    v = var[y, i]
    if box_cox_half:
        xx = np.float64(x[y, i])
        v = v * (max(xx, 0.0) if np.isfinite(xx) else 0.0)
    return v if np.isfinite(v) else 0.0


@njit(parallel=True, cache=True)
def column_sums(var, x, box_cox_half, r, out):  # pragma: no cover - compiled
    """out[y, i] = Σ lin[y + j, i] over |j| ≤ r inside the image, (H, W·C) float64: the first
    half of the window sum, which the gate's row pass completes along x
    (:mod:`dbench.methods.kernels.gate`), so the floored variance is never stored."""
    h, wc = var.shape
    for row in prange(h):
        y = np.int64(row)
        o = out[y]
        for i in range(wc):
            o[i] = 0.0
        for yy in range(max(y - r, 0), min(y + r, h - 1) + 1):
            for i in range(wc):
                o[i] += linear_value(var, x, box_cox_half, yy, i)


@njit(inline="always")
def floor_row(lin_row, sums_row, y, h, r, c, out_row):  # pragma: no cover - compiled
    """One row of the floor from :func:`column_sums`: out = max(lin, Σ over |k| ≤ r columns of
    the column sums / the window's pixel count inside the image)."""
    wc = sums_row.shape[0]
    w = wc // c
    for i in range(wc):
        out_row[i] = sums_row[i]
    for k in range(1, r + 1):
        s = k * c
        for i in range(s, wc):
            out_row[i] += sums_row[i - s]
        for i in range(wc - s):
            out_row[i] += sums_row[i + s]
    rows_in = min(y + r, h - 1) - max(y - r, 0) + 1
    for xp in range(w):
        n = rows_in * (min(xp + r, w - 1) - max(xp - r, 0) + 1)
        for ch in range(c):
            i = xp * c + ch
            out_row[i] = max(lin_row[i], out_row[i] / n)


__all__ = ["POOL_RADIUS", "column_sums", "floor_row", "floored_variance", "linear_value"]
