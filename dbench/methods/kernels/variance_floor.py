"""A floor on the per-pixel variance of the mean for the ProDen gate [dbench]: each value is
raised to the mean of its channel over the (2r + 1)² window around the pixel (the part of it
inside the image).

Why: the gate's t-test (docs/methods/statistical.md §12) trusts each pixel's variance estimate, but at a
few samples per pixel that estimate is itself noisy, and for heavy-tailed radiance (fireflies,
caustics) it is low exactly where the rare bright samples were missed. There the test declares
a good denoiser's output "significantly different" from the noisy mean and hands the pixel back
to the noise: on ``fireflies`` at 256², 16 spp, ``oidn+gate`` had 2.2x plain OIDN's relMSE.
The window's mean variance is the local noise level, an estimate from (2r + 1)² pixels instead
of one; taking the larger of the two keeps the test conservative where the pixel's own estimate
is too low, and as the spp grow both vanish, so the gate still converges to the input.
r = 5 is the gate's own 11×11 footprint.

* :func:`floored_variance` — the readable reference (SciPy box filters, float64).
* :func:`advance_column_sums`, :func:`window_mean_row` and :func:`floor_row` — the compiled
  form, fused into the gate's band pass (:func:`dbench.methods.kernels.gate.proden_gate_stats`):
  the window's column sums slide down the rows, and each row completes them along x from a
  prefix sum and takes the maximum, so the floored variance is never stored (tests: the pooled
  fast gate equals the reference within 1e-6, whatever the rows per task).

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
from numba import njit

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
    var = np.asarray(var, np.float64)
    r = check_radius(radius)
    if r == 0:
        return var.copy()
    return np.maximum(var, window_mean(var, r))


def window_mean(x: Any, radius: int) -> np.ndarray:
    """Mean of each channel of (H, W, C) ``x`` over the (2r + 1)² window around each pixel,
    of the part of it inside the image (SciPy box filters); (H, W, C) float64."""
    from scipy.ndimage import uniform_filter

    x = np.asarray(x, np.float64)
    size = (2 * radius + 1, 2 * radius + 1, 1)
    total = uniform_filter(x, size, mode="constant")
    inside = uniform_filter(np.ones(x.shape[:2] + (1,)), size, mode="constant")
    return total / inside


@njit(inline="always")
def linear_value(var, x, box_cox_half, y, i):  # pragma: no cover - compiled
    """The linear variance of one value: ``var`` or, for Box-Cox ½ statistics, var · max(x, 0)
    (x the noisy colour); 0 where it is not finite (kernels/gate.py linear_variance)."""
    v = np.float64(var[y, i])
    if box_cox_half:
        xx = np.float64(x[y, i])
        v = v * (max(xx, 0.0) if np.isfinite(xx) else 0.0)
    return v if np.isfinite(v) else 0.0


@njit(inline="always")
def window_column_sums(var, x, box_cox_half, y, h, r, out):  # pragma: no cover - compiled
    """out[i] = Σ lin[yy, i] over the rows yy of [y − r, y + r] inside the image, (W·C,)
    float64, in row order: the first half of row y's window sums, which :func:`floor_row`
    completes along x."""
    wc = out.shape[0]
    for i in range(wc):
        out[i] = 0.0
    for yy in range(max(y - r, 0), min(y + r, h - 1) + 1):
        for i in range(wc):
            out[i] += linear_value(var, x, box_cox_half, yy, i)


#: Rows between fresh column sums in :func:`advance_column_sums`.
SUM_ANCHOR = 32


@njit(inline="always")
def _slide_column_sums(var, x, box_cox_half, y, h, r, sums):  # pragma: no cover - compiled
    """Row y − 1's window column sums -> row y's: add row y + r, remove row y − r − 1."""
    wc = sums.shape[0]
    if y + r <= h - 1:
        for i in range(wc):
            sums[i] += linear_value(var, x, box_cox_half, y + r, i)
    if y - r - 1 >= 0:
        for i in range(wc):
            sums[i] -= linear_value(var, x, box_cox_half, y - r - 1, i)


@njit(inline="always")
def advance_column_sums(var, x, box_cox_half, y, fresh, h, r, sums):  # pragma: no cover
    """Row y's window column sums (:func:`window_column_sums`) in ``sums``, which holds row
    y − 1's unless ``fresh``: the sums slide by one row (2 values read, not 2r + 1), and are
    summed afresh at every SUM_ANCHOR-th row, then slid from there. A row's sums are therefore
    the same operations whichever row a task starts at (deterministic whatever the threads),
    and a slide's rounding is carried over at most SUM_ANCHOR − 1 rows: relative to the
    window's sum, under SUM_ANCHOR ulp of the largest value that passed through it."""
    if fresh or y % SUM_ANCHOR == 0:
        start = y - y % SUM_ANCHOR
        window_column_sums(var, x, box_cox_half, start, h, r, sums)
        for z in range(start + 1, y + 1):
            _slide_column_sums(var, x, box_cox_half, z, h, r, sums)
    else:
        _slide_column_sums(var, x, box_cox_half, y, h, r, sums)


@njit(inline="always")
def window_mean_row(sums_row, rows_in, r, c, inv_cols, prefix, mean_row):  # pragma: no cover
    """One row of the window means: mean_row = Σ over the |k| ≤ r columns of
    :func:`window_column_sums` / the window's pixel count inside the image, (W·C,) values of C
    interleaved channels. The x-sums are differences of a running prefix sum of the row padded
    with r zero columns either side (``prefix``: (W + 2r + 1)·C scratch), and ``inv_cols``
    (W·C,) holds 1 / the window's column count inside the image, so each value costs O(1)
    whatever r, and the last loop has no bounds to clamp (it is vectorised)."""
    wc = sums_row.shape[0]
    pad = r * c
    for k in range(pad + c):  # prefix[k] = Σ of the padded row's values k − C, k − 2C, … ≥ 0
        prefix[k] = 0.0
    for i in range(wc):
        prefix[pad + c + i] = prefix[pad + i] + sums_row[i]
    for k in range(wc + pad + c, wc + 2 * pad + c):
        prefix[k] = prefix[k - c]
    inv_rows = 1.0 / rows_in
    span = 2 * pad + c  # the window: values i − rC … i + rC of the row are padded i … i + 2rC
    for i in range(wc):
        mean_row[i] = (prefix[i + span] - prefix[i]) * (inv_rows * inv_cols[i])


@njit(inline="always")
def floor_row(lin_row, sums_row, rows_in, r, c, inv_cols, prefix, mean_row):  # pragma: no cover
    """One row of the floor, in place: lin = max(lin, the window mean of
    :func:`window_mean_row`), which is left in ``mean_row`` (W·C,) for whoever needs the same
    window's mean again (the gate's Wiener hand-back, kernels/gate.py)."""
    window_mean_row(sums_row, rows_in, r, c, inv_cols, prefix, mean_row)
    for i in range(sums_row.shape[0]):
        lin_row[i] = max(lin_row[i], mean_row[i])


def linear_variance(stats: Any, color: np.ndarray) -> np.ndarray:
    """Variance of the linear mean for the ProDen gate, (H, W, 3) float64.

    Exact for the identity transform; otherwise the delta method Var(x̄) ≈ Var(ȳ)/g'(x̄)² with
    g'(x) = x^(λ−1) (Box-Cox) or (1 + x)^(λ−1) (Yeo-Johnson, x ≥ 0), an approximation
    [dbench]; 0 where g' is infinite or the colour is not finite. Box-Cox with λ = ½ (dbench's
    default statistics) is the product var · x, computed as such.
    """
    var = np.asarray(stats.var_mean, np.float64)
    transform = getattr(stats, "transform", "identity")
    if transform == "identity":
        return np.where(np.isfinite(var), var, 0.0)
    lam = float(stats.lam)
    x = np.where(np.isfinite(color), np.maximum(np.asarray(color, np.float64), 0.0), 0.0)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        if transform == "box-cox" and lam == 0.5:
            out = var * x
        else:
            deriv = x ** (lam - 1.0) if transform == "box-cox" else (1.0 + x) ** (lam - 1.0)
            out = var / (deriv * deriv)
    return np.where(np.isfinite(out), out, 0.0)


__all__ = ["POOL_RADIUS", "SUM_ANCHOR", "advance_column_sums", "floor_row", "floored_variance",
           "linear_value", "linear_variance", "window_column_sums", "window_mean", "window_mean_row"]
