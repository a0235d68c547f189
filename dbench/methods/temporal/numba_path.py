"""Reprojection and accumulation compiled with Numba (parallel over rows), equal to
:mod:`.reference` within float32 rounding, and the single-thread switch for small images."""
from __future__ import annotations

import math
from contextlib import contextmanager
from typing import Iterator

import numpy as np

from ..guards import clamp_magnitude
from ..kernels.arrays import kernel_input
from .params import EPS_F, FALLBACK_KERNEL, N_MAX, SMALL_IMAGE, TAU_D, TAU_N


try:  # Numba is a dependency; the NumPy/Python reference still works without it
    import numba
    from numba import njit, prange
except ImportError:  # pragma: no cover
    numba = None


@contextmanager
def kernel_threads(n_pixels: int) -> Iterator[None]:
    """Run the Numba kernels of one frame on a single thread when the image is small."""
    if numba is None or n_pixels >= SMALL_IMAGE:
        yield
        return
    old = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        yield
    finally:
        numba.set_num_threads(old)


def out_array(out, shape, name: str) -> np.ndarray:
    """``out`` checked as a kernel's output (float32, C-contiguous, of ``shape``), or a new
    array when it is None. Why: a temporal method that writes each frame into the same arrays
    skips the page faults of fresh ones, about 6 ms per 18 MB at 720p on the 2-core machine."""
    if out is None:
        return np.empty(shape, np.float32)
    if (not isinstance(out, np.ndarray) or out.dtype != np.float32 or out.shape != tuple(shape)
            or not out.flags.c_contiguous):
        raise ValueError(f"{name}: expected a C-contiguous float32 array of shape {tuple(shape)}")
    return out


if numba is not None:
    @njit(cache=True, inline="always")
    def _valid_nb(qx, qy, h, w, prev_ok, prev_depth, prev_normal, n0, n1, n2, de, tau_d, tau_n):
        if qx < 0 or qy < 0 or qx >= w or qy >= h:
            return False
        if not prev_ok[qy, qx]:
            return False
        if abs(prev_depth[qy, qx] - de) > tau_d * de:
            return False
        dot = (prev_normal[0, qy, qx] * n0 + prev_normal[1, qy, qx] * n1
               + prev_normal[2, qy, qx] * n2)
        return dot >= tau_n

    @njit(cache=True, inline="always")
    def _taps_nb(y, x, motion, cur_hit, cur_normal, d_exp, prev_ok, prev_depth, prev_normal,
                 tau_d, tau_n, eps_f, kernel, h, w, idx, wt):
        """Pixel (y, x)'s reprojection taps: (count, status), with the flat indices of the
        previous pixels read in idx[x, :count] and their normalised weights in wt[x, :count]
        (bilinear, else the 3×3 fallback; docs/methods/temporal.md §3.3-3.5). The scratch rows are indexed, not
        sliced: a slice per pixel costs two atomic reference counts."""
        mx = motion[0, y, x]
        my = motion[1, y, x]
        if not cur_hit[y, x] or not (np.isfinite(mx) and np.isfinite(my)):
            return 0, 0
        n0 = cur_normal[0, y, x]
        n1 = cur_normal[1, y, x]
        n2 = cur_normal[2, y, x]
        de = d_exp[y, x]
        px = x + np.float64(mx)
        py = y + np.float64(my)
        x0 = int(math.floor(px))
        y0 = int(math.floor(py))
        wx = px - x0
        wy = py - y0
        f = 0.0
        count = 0
        for t in range(4):
            qx = x0 + (t & 1)
            qy = y0 + (t >> 1)
            bx = wx if (t & 1) else 1.0 - wx
            by = wy if (t >> 1) else 1.0 - wy
            b = bx * by
            if b > 0.0 and _valid_nb(qx, qy, h, w, prev_ok, prev_depth, prev_normal,
                                     n0, n1, n2, de, tau_d, tau_n):
                f += b
                idx[x, count] = qy * w + qx
                wt[x, count] = b
                count += 1
        if f > eps_f:
            for t in range(count):
                wt[x, t] /= f
            return count, 1
        cx = int(math.floor(px + 0.5))
        cy = int(math.floor(py + 0.5))
        g = 0.0
        count = 0
        for dy in range(-1, 2):
            for dx in range(-1, 2):
                if _valid_nb(cx + dx, cy + dy, h, w, prev_ok, prev_depth, prev_normal,
                             n0, n1, n2, de, tau_d, tau_n):
                    kk = kernel[dy + 1, dx + 1]
                    g += kk
                    idx[x, count] = (cy + dy) * w + cx + dx
                    wt[x, count] = kk
                    count += 1
        if g > 0.0:
            for t in range(count):
                wt[x, t] /= g
            return count, 2
        return 0, 0

    @njit(cache=True, parallel=True)
    def _reproject_nb(history, motion, cur_hit, cur_normal, d_exp, prev_ok, prev_depth,
                      prev_normal, tau_d, tau_n, eps_f, kernel, out, status):
        """Per row: every pixel's taps first (indices and normalised weights), then each
        history plane in turn gathered through them, so a row reads one plane at a time
        instead of all C planes for every pixel (30 streams of memory for C = 10)."""
        c, h, w = history.shape
        flat = history.reshape(c, h * w)
        bands = min(h, 64)  # tasks of whole rows, each with its own scratch
        for band in prange(bands):
            idx = np.empty((w, 9), np.int64)
            wt = np.empty((w, 9), np.float64)
            count = np.empty(w, np.int64)
            for y in range(band * h // bands, (band + 1) * h // bands):
                for x in range(w):
                    n, st = _taps_nb(y, x, motion, cur_hit, cur_normal, d_exp, prev_ok,
                                     prev_depth, prev_normal, tau_d, tau_n, eps_f, kernel, h, w,
                                     idx, wt)
                    count[x] = n
                    status[y, x] = st
                for k in range(c):
                    plane = flat[k]
                    row = out[k, y]
                    for x in range(w):
                        # the two common counts unrolled (one tap: integer motion; four:
                        # bilinear), the same sum in the same order as the loop
                        n = count[x]
                        if n == 1:
                            row[x] = wt[x, 0] * plane[idx[x, 0]]
                        elif n == 4:
                            row[x] = (((wt[x, 0] * plane[idx[x, 0]] + wt[x, 1] * plane[idx[x, 1]])
                                       + wt[x, 2] * plane[idx[x, 2]])
                                      + wt[x, 3] * plane[idx[x, 3]])
                        else:
                            acc = 0.0
                            for t in range(n):
                                acc += wt[x, t] * plane[idx[x, t]]
                            row[x] = acc


def reproject_fast(history, motion, cur_hit, cur_normal, d_exp, prev_ok, prev_depth,
                   prev_normal, tau_d=TAU_D, tau_n=TAU_N, eps_f=EPS_F, out=None):
    """Compiled (Numba, parallel over rows) :func:`reproject_reference`; equal to it within
    float32 rounding of the output (the weights are computed in float64 in both). ``out``: a
    (C, H, W) float32 C-contiguous array to write into, not overlapping ``history``
    (:func:`out_array`)."""
    history = np.ascontiguousarray(history, np.float32)
    out = out_array(out, history.shape, "out")
    status = np.empty(history.shape[1:], np.uint8)
    _reproject_nb(history, np.ascontiguousarray(motion, np.float32),
                  np.ascontiguousarray(cur_hit, np.bool_),
                  np.ascontiguousarray(cur_normal, np.float32),
                  np.ascontiguousarray(d_exp, np.float32), np.ascontiguousarray(prev_ok, np.bool_),
                  np.ascontiguousarray(prev_depth, np.float32),
                  np.ascontiguousarray(prev_normal, np.float32), float(tau_d), float(tau_n),
                  float(eps_f), FALLBACK_KERNEL, out, status)
    return out, status


if numba is not None:
    @njit(cache=True, parallel=True, fastmath=True, error_model="numpy")
    def _accumulate_nb(sample, history, n_hist, ok, sample_ok, alpha, alpha_min, n_max,
                       out, n_out, a_out):
        c, h, w = sample.shape
        has_alpha = alpha.shape[0] > 0
        for y in prange(h):
            for x in range(w):
                if ok[y, x]:
                    n = min(n_hist[y, x] + np.float32(1.0), n_max)
                    a = alpha[y, x] if has_alpha else max(alpha_min, np.float32(1.0) / n)
                else:
                    n = np.float32(1.0)
                    a = np.float32(1.0)
                if sample_ok[y, x]:
                    for k in range(c):
                        out[k, y, x] = a * sample[k, y, x] + (np.float32(1.0) - a) * history[k, y, x]
                    n_out[y, x] = n
                    a_out[y, x] = a
                else:
                    for k in range(c):
                        out[k, y, x] = history[k, y, x] if ok[y, x] else np.float32(0.0)
                    n_out[y, x] = n_hist[y, x] if ok[y, x] else np.float32(0.0)
                    a_out[y, x] = np.float32(0.0)


def accumulate_fast(sample, history, n_hist, ok, alpha_min=0.0, n_max=N_MAX, alpha=None,
                    sample_ok=None, out=None):
    """Compiled :func:`accumulate` (same arguments and results, one fused pass). ``out``:
    optional (accumulated (C, H, W), N (H, W)) float32 arrays to write into, either None
    (:func:`out_array`), e.g. planes of the buffer the method stores as its history."""
    sample = np.ascontiguousarray(sample, np.float32)
    h, w = sample.shape[1:]
    acc_out, n_given = (None, None) if out is None else out
    out = out_array(acc_out, sample.shape, "out[0]")
    n_out = out_array(n_given, (h, w), "out[1]")
    a_out = np.empty((h, w), np.float32)
    _accumulate_nb(sample, np.ascontiguousarray(history, np.float32),
                   np.ascontiguousarray(n_hist, np.float32), np.ascontiguousarray(ok, np.bool_),
                   np.ones((h, w), np.bool_) if sample_ok is None
                   else np.ascontiguousarray(sample_ok, np.bool_),
                   np.zeros((0, 0), np.float32) if alpha is None
                   else np.ascontiguousarray(alpha, np.float32),
                   np.float32(alpha_min), np.float32(n_max), out, n_out, a_out)
    return out, n_out, a_out


if numba is not None:
    @njit(cache=True, parallel=True, fastmath=False, error_model="numpy")
    def _count_over_nb(flat, limit):
        """How many finite values of ``flat`` have a magnitude above ``limit`` (NaN and ±Inf
        compare false, as in :func:`~dbench.methods.guards.clamp_magnitude`)."""
        n = flat.shape[0]
        chunks = 64
        step = (n + chunks - 1) // chunks
        counts = np.zeros(chunks, np.int64)
        for c in prange(chunks):
            k = 0
            for i in range(c * step, min(n, (c + 1) * step)):
                v = abs(flat[i])
                k += (v > limit) & (v < np.inf)  # branch-free, so the loop vectorises
            counts[c] = k
        return counts.sum()


def clamp_radiance(x: np.ndarray, limit: float) -> np.ndarray:
    """:func:`~dbench.methods.guards.clamp_magnitude` (``x`` itself when nothing exceeds
    ``limit``, a clamped copy otherwise; NaN and ±Inf kept) with the common case, nothing to
    clamp, decided in one compiled read of ``x`` instead of four NumPy passes (2.5 ms per 720p
    colour buffer). Equal to it bit for bit (tests)."""
    x = np.asarray(x)
    if numba is None or x.dtype not in (np.float32, np.float64) or not x.flags.c_contiguous:
        return clamp_magnitude(x, limit)
    # a read-only view (methods/kernels/arrays.py): one specialisation per dtype
    if _count_over_nb(kernel_input(x).reshape(-1), x.dtype.type(limit)) == 0:
        return x
    return clamp_magnitude(x, limit)
