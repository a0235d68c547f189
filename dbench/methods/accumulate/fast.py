"""The accumulation step of ``accumulate`` fused into one compiled pass (Numba).

:func:`accumulate_frame` equals the readable chain the method runs on the ``reference`` backend
— planar conversion, finite-sample mask, luminance moments, :func:`dbench.methods.temporal.
accumulate`, the history stack and the interleaved output — within float32 rounding (tested in
tests/methods/test_accumulate.py). At 1280×720 the chain made ~10 full passes over 5-channel
float32 images; the kernel makes one (results/temporal.md, speed).
"""
from __future__ import annotations

import numpy as np

from ..kernels.arrays import kernel_input
from ..temporal.numba_path import out_array
from ..temporal.params import LUMA

try:
    import numba
except ImportError:  # pragma: no cover - numba is a dependency; the reference path remains
    numba = None

_L0, _L1, _L2 = (float(v) for v in LUMA)


def _kernel(color, hist, ok, alpha_min, n_max, out_hist, out_img, variance):
    h, w = color.shape[:2]
    for yy in numba.prange(h):
        y = np.int64(yy)  # prange indices are unsigned
        for x in range(w):
            r, g, b = color[y, x, 0], color[y, x, 1], color[y, x, 2]
            finite = np.isfinite(r) and np.isfinite(g) and np.isfinite(b)
            good = ok[y, x]
            n = min(hist[5, y, x] + np.float32(1.0), n_max) if good else np.float32(1.0)
            a = max(alpha_min, np.float32(1.0) / n) if good else np.float32(1.0)
            if finite:
                lum = np.float32(_L0) * r + np.float32(_L1) * g + np.float32(_L2) * b
                sample = (r, g, b, lum, lum * lum)
                for c in range(5):
                    out_hist[c, y, x] = a * sample[c] + (np.float32(1.0) - a) * hist[c, y, x]
                out_hist[5, y, x] = n
            else:
                for c in range(5):
                    out_hist[c, y, x] = hist[c, y, x] if good else np.float32(0.0)
                out_hist[5, y, x] = hist[5, y, x] if good else np.float32(0.0)
            if out_hist[5, y, x] > 0:
                for c in range(3):
                    out_img[y, x, c] = out_hist[c, y, x]
            else:  # an empty history: the (non-finite) input stays, nothing spreads
                out_img[y, x, 0], out_img[y, x, 1], out_img[y, x, 2] = r, g, b
            m1 = out_hist[3, y, x]
            variance[y, x] = max(np.float32(0.0), out_hist[4, y, x] - m1 * m1)


_kernel_nb = (numba.njit(parallel=True, cache=True, fastmath=False)(_kernel)
              if numba is not None else None)


def accumulate_frame(color: np.ndarray, hist: np.ndarray, ok: np.ndarray, alpha_min: float,
                     n_max: float, out_hist: np.ndarray | None = None
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One frame of ``accumulate``.

    Args:
        color: (H, W, 3) float32 noisy colour (non-finite pixels are missing samples).
        hist: (6, H, W) float32 reprojected history: colour (3), moments [l, l²] (2), N.
        ok: (H, W) bool, reprojection succeeded.
        alpha_min, n_max: α = max(alpha_min, 1/N), N = min(N← + 1, n_max).
        out_hist: an optional (6, H, W) float32 C-contiguous array to write the history into
            (a reused one: :meth:`~dbench.methods.temporal.History.staging`), not ``hist``.
    Returns:
        (history (6, H, W) float32 to store, output (H, W, 3) float32, variance (H, W) float32).
    """
    # read-only inputs (methods/kernels/arrays.py): one specialisation whoever calls
    color = kernel_input(color, np.float32)
    h, w = color.shape[:2]
    out_hist = out_array(out_hist, (6, h, w), "out_hist")
    out_img = np.empty((h, w, 3), np.float32)
    variance = np.empty((h, w), np.float32)
    _kernel_nb(color, kernel_input(hist, np.float32), kernel_input(ok, np.bool_),
               np.float32(alpha_min), np.float32(n_max), out_hist, out_img, variance)
    return out_hist, out_img, variance


__all__ = ["accumulate_frame"]
