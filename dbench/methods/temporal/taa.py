"""Temporal antialiasing (TAA) of a temporal denoiser's output: the last, optional step of BMFR's
pipeline (docs/methods/bmfr.md §1 step 6 and §6 ``taa``: off by default, α = 0.2 when on; [BMFR code]),
offered to SVGF and A-SVGF as well [dbench].

Per pixel p of the current output C (H, W, 3) and the previous TAA output H (H, W, 3):

    q      = p + motion(p)                        (the pixel's position in the previous frame)
    h      = bilinear H at q, over the taps inside the image, renormalised
    lo, hi = per YCoCg channel, the mean of the min (max) of C's 3×3 box and of its 5-pixel
             cross around p (taps inside the image; the [BMFR code] rule)
    out    = α C(p) + (1 − α) RGB(clamp(YCoCg(h), lo, hi))

and out = C(p) where there is no history, C(p) or the motion is not finite, floor(q) lies outside
[−1, W) × [−1, H) (the rule of the BMFR code), or no tap of q is inside the image with a finite
history value ([dbench]: a missing pixel's non-finite previous output is no tap, so it never
spreads to a pixel whose input is finite). The history
is clamped to the colours around p in the current frame, so what moved away (a disocclusion,
a light switched off) cannot ghost; what stays keeps averaging (a running mean of α).

[dbench] The BMFR code runs it on tone-mapped, gamma-encoded values in [0, 1]; dbench's outputs
are linear HDR radiance, and the pass runs on them as they are (YCoCg is linear, so the clamp
and the blend are the same operations). Motion vectors point from a pixel to its position in
the previous frame (docs/methods/temporal.md §3.1), planar (2, H, W).

* :func:`taa_reference` — the readable form (NumPy, float64 inside).
* :func:`taa_fast` — compiled (Numba, parallel over rows): one pass for each value's YCoCg and
  its row's 3-pixel extremes, then the fetch, clamp and blend, which read the box's and the
  cross's extremes from those rows; equal to the readable form within float32 rounding (tests).
"""
from __future__ import annotations

import math

import numpy as np

from ...data import check_buffer
from ...errors import DbenchInputError

#: the blend of the current frame [BMFR code]
TAA_ALPHA = 0.2
#: fast-math flags of the compiled pass: all but "no NaN / no Inf", which would drop the
#: finiteness tests of the motion and the colour
_FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}

try:  # Numba is a dependency; the NumPy reference still works without it
    from numba import njit, prange
    HAVE_NUMBA = True
except ImportError:  # pragma: no cover
    HAVE_NUMBA = False


def to_ycocg(rgb: np.ndarray) -> np.ndarray:
    """(…, 3) RGB -> YCoCg (Y = R/4 + G/2 + B/4, Co = (R − B)/2, Cg = −R/4 + G/2 − B/4)."""
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    return np.stack([0.25 * r + 0.5 * g + 0.25 * b, 0.5 * (r - b), -0.25 * r + 0.5 * g - 0.25 * b],
                    axis=-1)


def from_ycocg(ycc: np.ndarray) -> np.ndarray:
    """The inverse of :func:`to_ycocg`."""
    y, co, cg = ycc[..., 0], ycc[..., 1], ycc[..., 2]
    return np.stack([y + co - cg, y + cg, y - co - cg], axis=-1)


def _check(current, history, motion, alpha):
    current = check_buffer("current", current, (None, None, 3))
    h, w = current.shape[:2]
    if history is not None:
        history = check_buffer("history", history, (h, w, 3))
    if motion is not None:
        motion = check_buffer("motion", motion, (2, h, w))
    alpha = float(alpha)
    if not 0.0 < alpha <= 1.0:
        raise DbenchInputError(f"alpha: expected a number in (0, 1], got {alpha!r}")
    return current, history, motion, alpha


def taa_reference(current, history, motion, alpha: float = TAA_ALPHA) -> np.ndarray:
    """TAA of the module docstring, the readable form.

    Args:
        current: (H, W, 3) this frame's output; history: (H, W, 3) the previous TAA output, or
            None (first frame: the output is ``current``); motion: (2, H, W) motion vectors
            (x, y offsets to the previous frame), or None; alpha: the current frame's weight.

    Returns:
        (H, W, 3) float32.
    """
    current, history, motion, alpha = _check(current, history, motion, alpha)
    cur = np.asarray(current, np.float64)
    if history is None or motion is None or alpha == 1.0:
        return cur.astype(np.float32)
    h, w = cur.shape[:2]
    ycc = to_ycocg(cur)
    pad = np.pad(ycc, ((1, 1), (1, 1), (0, 0)), constant_values=np.nan)
    box = np.stack([pad[1 + dy:1 + dy + h, 1 + dx:1 + dx + w]
                    for dy in (-1, 0, 1) for dx in (-1, 0, 1)])
    cross = box[[1, 3, 4, 5, 7]]
    with np.errstate(invalid="ignore"):
        lo = 0.5 * (np.nanmin(box, 0) + np.nanmin(cross, 0))
        hi = 0.5 * (np.nanmax(box, 0) + np.nanmax(cross, 0))
    hist = np.asarray(history, np.float64)
    out = cur.copy()
    for y in range(h):
        for x in range(w):
            mx, my = float(motion[0, y, x]), float(motion[1, y, x])
            if not (math.isfinite(mx) and math.isfinite(my) and np.isfinite(cur[y, x]).all()):
                continue
            qx, qy = x + mx, y + my
            x0, y0 = math.floor(qx), math.floor(qy)
            if x0 < -1 or y0 < -1 or x0 >= w or y0 >= h:
                continue
            fx, fy = qx - x0, qy - y0
            acc = np.zeros(3)
            total = 0.0
            for ty, wy in ((y0, 1.0 - fy), (y0 + 1, fy)):
                for tx, wx in ((x0, 1.0 - fx), (x0 + 1, fx)):
                    # a non-finite history value (a missing pixel's previous output) is no
                    # tap: it would carry NaN into a pixel whose own input is finite
                    if 0 <= tx < w and 0 <= ty < h and np.isfinite(hist[ty, tx]).all():
                        acc += wx * wy * hist[ty, tx]
                        total += wx * wy
            if not total > 0.0:
                continue
            prev = np.clip(to_ycocg(acc / total), lo[y, x], hi[y, x])
            out[y, x] = alpha * cur[y, x] + (1.0 - alpha) * from_ycocg(prev)
    return out.astype(np.float32)


if HAVE_NUMBA:
    @njit(cache=True, inline="always")
    def _ycocg_nb(r, g, b):
        return 0.25 * r + 0.5 * g + 0.25 * b, 0.5 * (r - b), -0.25 * r + 0.5 * g - 0.25 * b

    @njit(cache=True, parallel=True, error_model="numpy")
    def _ranges_nb(cur, lo_v, hi_v, lo_h, hi_h):
        """Per value of YCoCg(cur): itself with NaN read as +Inf (``lo_v``, for minima) and
        −Inf (``hi_v``, for maxima), and the min (max) over its row's 3-pixel window inside
        the image (``lo_h``, ``hi_h``); the box's and the cross's extremes are then a few
        comparisons of these (:func:`_taa_nb`), not 9 taps each."""
        h, w = cur.shape[:2]
        for y in prange(h):
            for x in range(w):
                c = _ycocg_nb(np.float64(cur[y, x, 0]), np.float64(cur[y, x, 1]),
                              np.float64(cur[y, x, 2]))
                for k in range(3):
                    v = c[k]
                    ok = np.isfinite(v)
                    lo_v[y, x, k] = v if ok else np.inf
                    hi_v[y, x, k] = v if ok else -np.inf
            for x in range(w):
                for k in range(3):
                    lo = lo_v[y, x, k]
                    hi = hi_v[y, x, k]
                    if x > 0:
                        lo = min(lo, lo_v[y, x - 1, k])
                        hi = max(hi, hi_v[y, x - 1, k])
                    if x < w - 1:
                        lo = min(lo, lo_v[y, x + 1, k])
                        hi = max(hi, hi_v[y, x + 1, k])
                    lo_h[y, x, k] = lo
                    hi_h[y, x, k] = hi

    @njit(cache=True, inline="always")
    def _clamp_nb(v, lo_v, hi_v, lo_h, hi_h, up, y, down, x, k):
        """v clamped to channel k's range at (y, x): the means of the box's extremes (the three
        rows' 3-pixel ones) and of the cross's (the centre row's, the pixels above and below)."""
        blo = min(lo_h[up, x, k], lo_h[y, x, k], lo_h[down, x, k])
        bhi = max(hi_h[up, x, k], hi_h[y, x, k], hi_h[down, x, k])
        clo = min(lo_v[up, x, k], lo_h[y, x, k], lo_v[down, x, k])
        chi = max(hi_v[up, x, k], hi_h[y, x, k], hi_v[down, x, k])
        return min(max(v, 0.5 * (blo + clo)), 0.5 * (bhi + chi))

    @njit(cache=True, parallel=True, error_model="numpy", fastmath=_FASTMATH)
    def _taa_nb(cur, lo_v, hi_v, lo_h, hi_h, hist, motion, alpha, out):
        h, w = cur.shape[:2]
        for y in prange(h):
            up = max(y - 1, 0)  # rows outside the image repeat the centre row: no new extreme
            down = min(y + 1, h - 1)
            for x in range(w):
                c0 = np.float64(cur[y, x, 0])
                c1 = np.float64(cur[y, x, 1])
                c2 = np.float64(cur[y, x, 2])
                out[y, x, 0] = cur[y, x, 0]
                out[y, x, 1] = cur[y, x, 1]
                out[y, x, 2] = cur[y, x, 2]
                mx = np.float64(motion[0, y, x])
                my = np.float64(motion[1, y, x])
                if not (np.isfinite(mx) and np.isfinite(my) and np.isfinite(c0)
                        and np.isfinite(c1) and np.isfinite(c2)):
                    continue
                qx = x + mx
                qy = y + my
                x0 = int(math.floor(qx))
                y0 = int(math.floor(qy))
                if x0 < -1 or y0 < -1 or x0 >= w or y0 >= h:
                    continue
                fx = qx - x0
                fy = qy - y0
                a0 = 0.0
                a1 = 0.0
                a2 = 0.0
                total = 0.0
                for t in range(4):
                    tx = x0 + (t & 1)
                    ty = y0 + (t >> 1)
                    if tx < 0 or ty < 0 or tx >= w or ty >= h:
                        continue
                    if not (np.isfinite(hist[ty, tx, 0]) and np.isfinite(hist[ty, tx, 1])
                            and np.isfinite(hist[ty, tx, 2])):
                        continue  # a missing pixel's previous output: no tap (reference)
                    wt = (fx if t & 1 else 1.0 - fx) * (fy if t >> 1 else 1.0 - fy)
                    a0 += wt * hist[ty, tx, 0]
                    a1 += wt * hist[ty, tx, 1]
                    a2 += wt * hist[ty, tx, 2]
                    total += wt
                if not total > 0.0:
                    continue
                p = _ycocg_nb(a0 / total, a1 / total, a2 / total)
                yy = _clamp_nb(p[0], lo_v, hi_v, lo_h, hi_h, up, y, down, x, 0)
                co = _clamp_nb(p[1], lo_v, hi_v, lo_h, hi_h, up, y, down, x, 1)
                cg = _clamp_nb(p[2], lo_v, hi_v, lo_h, hi_h, up, y, down, x, 2)
                out[y, x, 0] = alpha * c0 + (1.0 - alpha) * (yy + co - cg)
                out[y, x, 1] = alpha * c1 + (1.0 - alpha) * (yy + cg)
                out[y, x, 2] = alpha * c2 + (1.0 - alpha) * (yy - co - cg)


def taa_fast(current, history, motion, alpha: float = TAA_ALPHA) -> np.ndarray:
    """Compiled :func:`taa_reference` (same arguments and result)."""
    current, history, motion, alpha = _check(current, history, motion, alpha)
    if not HAVE_NUMBA:  # pragma: no cover
        return taa_reference(current, history, motion, alpha)
    cur = np.ascontiguousarray(current, np.float32)
    if history is None or motion is None or alpha == 1.0:
        return cur.copy() if cur is current else cur
    out = np.empty_like(cur)
    # float32: the ranges of float32 colours (the clamp's bounds move by float32 rounding)
    lo_v, hi_v, lo_h, hi_h = (np.empty(cur.shape, np.float32) for _ in range(4))
    _ranges_nb(cur, lo_v, hi_v, lo_h, hi_h)
    _taa_nb(cur, lo_v, hi_v, lo_h, hi_h, np.ascontiguousarray(history, np.float32),
            np.ascontiguousarray(motion, np.float32), alpha, out)
    return out


def taa(backend: str, current, history, motion, alpha: float = TAA_ALPHA) -> np.ndarray:
    """:func:`taa_reference` for the ``reference`` backend, :func:`taa_fast` otherwise (the torch
    backend runs the compiled CPU pass: NumPy in and out)."""
    fn = taa_reference if backend == "reference" else taa_fast
    return fn(current, history, motion, alpha)


__all__ = ["TAA_ALPHA", "from_ycocg", "taa", "taa_fast", "taa_reference", "to_ycocg"]
