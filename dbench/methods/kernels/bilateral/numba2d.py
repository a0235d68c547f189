"""Numba fast path of the base filter over a 2-D window: Σ_{j ≠ i} W_ij · planes_j for every
pixel i, with W the base weight times the optional illumination-filter normal term and Welch
membership.

Precision and speed: features, weights and per-band sums are float32 (the vectorisable exp of
:mod:`.vexp`); the final sums and the division are float64; the statistical Welch test is
float64. Measured max relative difference of the JBF to the float64 reference ≈ 1e-6 (tests
assert 1e-5). Loop order: parallel over row bands, then rows, then window offsets, innermost the
pixels of a row (vectorised); the weight of a pair is symmetric, so only half of the window is
evaluated. 1280×720, r = 20 on 2 cores: ≈ 1-2 s (reference ≈ 40-60 s), see
the speed benchmark of the command line (``bench jbf``)."""
from __future__ import annotations

import math

import numba
import numpy as np
from numba import njit, prange

from ....errors import DbenchInputError
from ..arrays import kernel_input
from ..welch import row_welch, row_welch_table
from .guide import Guide
from .params import LABEL_SCALE, PLANE_MAX
from .vexp import F0, F1, F_CUT, exp32


@njit(inline="always", cache=True)
def row_weights(fsq, fdot, beta, horizon, y, yy, x0, x1, dx, e, w):
    """w[0:n] = base weights of the pairs (y, x) – (yy, x + dx), x in [x0, x1).

    The exponent is e + Σ_g Σ_q (F_i − F_j)² (pre-scaled features, groups of 4 planes) and, for
    the illumination filter, + β(1 − n_i·n_j) with the horizon step [n_i·n_j > 0].
    """
    row_exponent(fsq, y, yy, x0, x1, dx, e, w)
    row_exp(fdot, beta, horizon, y, yy, x0, x1, dx, w)


@njit(inline="always", cache=True)
def row_exponent(fsq, y, yy, x0, x1, dx, e, w):
    """w[0:n] = e + Σ_g Σ_q (F_i − F_j)², the feature part of the exponent."""
    n = x1 - x0
    for i in range(n):
        w[i] = e
    for g in range(fsq.shape[0]):
        a0 = fsq[g, 0, y, x0:x1]
        b0 = fsq[g, 0, yy, x0 + dx:x1 + dx]
        a1 = fsq[g, 1, y, x0:x1]
        b1 = fsq[g, 1, yy, x0 + dx:x1 + dx]
        a2 = fsq[g, 2, y, x0:x1]
        b2 = fsq[g, 2, yy, x0 + dx:x1 + dx]
        a3 = fsq[g, 3, y, x0:x1]
        b3 = fsq[g, 3, yy, x0 + dx:x1 + dx]
        for i in range(n):
            t0 = a0[i] - b0[i]
            t1 = a1[i] - b1[i]
            t2 = a2[i] - b2[i]
            t3 = a3[i] - b3[i]
            w[i] += (t0 * t0 + t1 * t1) + (t2 * t2 + t3 * t3)


@njit(inline="always", cache=True)
def row_exp(fdot, beta, horizon, y, yy, x0, x1, dx, w):
    """w ← exp(−w), with the illumination filter's normal term when ``fdot`` has planes."""
    n = x1 - x0
    if fdot.shape[0] > 0:
        a0 = fdot[0, y, x0:x1]
        b0 = fdot[0, yy, x0 + dx:x1 + dx]
        a1 = fdot[1, y, x0:x1]
        b1 = fdot[1, yy, x0 + dx:x1 + dx]
        a2 = fdot[2, y, x0:x1]
        b2 = fdot[2, yy, x0 + dx:x1 + dx]
        for i in range(n):
            dot = a0[i] * b0[i] + a1[i] * b1[i] + a2[i] * b2[i]
            v = exp32(-(w[i] + beta * (F1 - dot)))
            w[i] = v if (dot > F0 or not horizon) else F0
    else:
        for i in range(n):
            w[i] = exp32(-w[i])


@njit(parallel=True, cache=True)
def _accumulate_kernel(fsq, fdot, beta, horizon, planes, dys, dxs, es,
                       theta, var, nint, g2, table, test_mode, nbands, halo):
    """Σ_{j ≠ i} W_ij · planes[:, j] for every pixel i: (P, H, W) float64.

    W_ij = base weight × (Welch membership if test_mode > 0) is symmetric in (i, j), so only the
    half window (dy > 0, or dy = 0 and dx > 0) is evaluated and each pair is added to both
    pixels. Rows are split into ``nbands`` bands processed in parallel; each band owns a private
    float32 accumulator of its rows plus ``halo`` (= r) rows below, summed at the end in float64.
    Memory: P·(H + nbands·r)·W floats; no unfolded tensor.
    """
    H = fsq.shape[2]
    W = fsq.shape[3]
    P = planes.shape[0]
    B = (H + nbands - 1) // nbands
    acc = np.zeros((nbands, P, B + halo, W), np.float32)
    for b in prange(nbands):
        y0 = b * B
        y1 = min(H, y0 + B)
        w = np.empty(W, np.float32)
        for y in range(y0, y1):
            for o in range(dys.shape[0]):
                dy = dys[o]
                dx = dxs[o]
                yy = y + dy
                if yy >= H:
                    break  # offsets are sorted by dy
                x0 = max(0, -dx)
                x1 = min(W, W - dx)
                n = x1 - x0
                if n <= 0 or es[o] >= F_CUT:
                    continue  # no pair in the image / weight underflows to exactly 0
                row_exponent(fsq, y, yy, x0, x1, dx, es[o], w)
                row_exp(fdot, beta, horizon, y, yy, x0, x1, dx, w)
                if test_mode == 1:
                    row_welch(theta, var, g2, y, yy, x0, x1, dx, w)
                elif test_mode == 2:
                    row_welch_table(theta, var, nint, table, y, yy, x0, x1, dx, w)
                r0 = y - y0
                r1 = yy - y0
                for p in range(P):
                    pa = planes[p, y, x0:x1]
                    pb = planes[p, yy, x0 + dx:x1 + dx]
                    aa = acc[b, p, r0, x0:x1]
                    ab = acc[b, p, r1, x0 + dx:x1 + dx]
                    # two loops, not one: with a single store stream each, LLVM vectorises
                    # them (the fused loop ran 4x slower)
                    for i in range(n):
                        aa[i] += w[i] * pb[i]
                    for i in range(n):
                        ab[i] += w[i] * pa[i]
    out = np.zeros((P, H, W), np.float64)
    for y in prange(H):
        for b in range(nbands):
            r = y - b * B
            if 0 <= r < B + halo:
                for p in range(P):
                    for x in range(W):
                        out[p, y, x] += acc[b, p, r, x]
    return out


_EMPTY_F64 = kernel_input(np.zeros((3, 1, 1), np.float64))
_EMPTY_I32 = kernel_input(np.zeros((3, 1, 1), np.int32))
EMPTY_TABLE = kernel_input(np.zeros(1, np.float64))


def scaled_feature_groups(guide: Guide) -> np.ndarray:
    """(G, 4, H, W) float32 planes F with (F_i − F_j)² summing to the exponent of ρ.

    F_k = p_k·sqrt(½Σ⁻¹_kk) (centred per plane to keep float32 precision) plus the label plane
    16·label; zero planes pad the count to a multiple of 4.
    """
    h, w = guide.shape
    planes = []
    for f, iv in zip(guide.features, guide.inv_var):
        if iv == 0.0:
            continue
        centre = float(np.mean(f)) if f.size else 0.0
        planes.append((f - centre) * math.sqrt(0.5 * iv))
    if np.any(guide.labels != guide.labels.flat[0]):
        if guide.labels.max() >= 2 ** 24:
            raise DbenchInputError("too many isolated pixels (non-finite G-buffers) for the "
                                   "float32 label plane; clean the G-buffers first")
        planes.append(guide.labels * LABEL_SCALE)
    while len(planes) % 4:
        planes.append(np.zeros((h, w)))
    if not planes:
        return np.zeros((0, 4, h, w), np.float32)
    return np.ascontiguousarray(np.stack(planes).reshape(-1, 4, h, w), dtype=np.float32)


def half_window(guide: Guide, extra_exponent: float = 0.0):
    """Offsets with dy > 0 or (dy = 0, dx > 0), sorted by dy, and their float32 exponents."""
    half = (guide.dy > 0) | ((guide.dy == 0) & (guide.dx > 0))
    order = np.lexsort((guide.dx[half], guide.dy[half]))
    dys = np.ascontiguousarray(guide.dy[half][order])
    dxs = np.ascontiguousarray(guide.dx[half][order])
    es = (guide.spatial[half][order] + extra_exponent).astype(np.float32)
    return dys, dxs, es


def num_bands(h: int) -> int:
    return max(1, min(numba.get_num_threads(), h))


def accumulate(guide: Guide, planes: np.ndarray, *, dot_normal: np.ndarray | None = None,
               beta: float = 0.0, horizon: bool = False, extra_exponent: float = 0.0,
               theta: np.ndarray | None = None, var: np.ndarray | None = None,
               nint: np.ndarray | None = None, g2: float | None = None,
               g2_table: np.ndarray | None = None) -> np.ndarray:
    """Numba fast path: Σ_{j ≠ i, j in window} W_ij · planes_j for every pixel i.

    Args:
        guide: the base filter (features, labels, window).
        planes: (P, H, W) values to sum (premultiplied by each neighbour's validity).
        dot_normal: (3, H, W) normals for the illumination filter's β(1 − n·n') term, or None.
        beta, horizon: that term's β and whether to apply the horizon step [n_i·n_j > 0].
        extra_exponent: a constant added to every exponent (−ln C of the illumination filter).
        theta, var: (3, H, W) float64 statistics for the Welch membership test, or None.
        nint: (3, H, W) int32 sample counts, with ``g2_table`` (γ_t² indexed by ν) when n is not
            uniform; otherwise ``g2`` = γ_t², one value.

    Returns:
        (P, H, W) float64 sums without the centre term (the caller adds it).

    Weights are float32 (relative error ≈ 1e-7·exponent); the membership test is float64 and
    bit-identical to the reference; band sums are float32, the final sum float64.
    """
    h, w = guide.shape
    planes, scale = _scaled_planes(planes)
    fsq = scaled_feature_groups(guide)
    fdot = kernel_input(np.zeros((0, 1, 1), np.float32) if dot_normal is None else dot_normal,
                        np.float32)
    dys, dxs, es = half_window(guide, extra_exponent)
    # read-only inputs (arrays.py), empty or not: one specialisation of the kernel
    if theta is None:
        test_mode, th, va, ni, table, gg = 0, _EMPTY_F64, _EMPTY_F64, _EMPTY_I32, EMPTY_TABLE, 0.0
    else:
        th = kernel_input(theta, np.float64)
        va = kernel_input(var, np.float64)
        if g2_table is None:
            test_mode, ni, table, gg = 1, _EMPTY_I32, EMPTY_TABLE, float(g2)
        else:
            test_mode, gg = 2, 0.0
            ni = kernel_input(nint, np.int32)
            table = kernel_input(g2_table, np.float64)
    nbands = num_bands(h)
    sums = _accumulate_kernel(fsq, fdot, np.float32(beta), bool(horizon), planes, dys, dxs, es,
                              th, va, ni, np.float64(gg), table, int(test_mode), nbands,
                              int(guide.radius))
    if scale is not None:
        sums *= scale[:, None, None]
    return sums


def _scaled_planes(planes: np.ndarray, axis: int = 0) -> tuple[np.ndarray, np.ndarray | None]:
    """``planes`` as C-contiguous float32 for the kernels, and the per-plane factors (one per
    index along ``axis``, float64) to multiply their float64 sums by, or None.

    A plane whose largest finite |value| exceeds :data:`PLANE_MAX` (a demodulated colour near
    the float32 maximum: 3e38 / 1e-3 is Inf in float32; a block of 3e38 colours, whose float32
    sums overflow) is divided by a power of two (exact) first, so its float32 sums stay finite;
    other planes, i.e. every ordinary input, are passed unchanged bit for bit (None then).
    """
    arr = np.asarray(planes)
    # float32 is divided in float32 (exact for a power of two); anything else in float64, whose
    # finite values may lie beyond the float32 range
    arr = np.ascontiguousarray(arr, dtype=np.float32 if arr.dtype == np.float32 else np.float64)
    shape = arr.shape
    lead = int(np.prod(shape[:axis], dtype=np.int64))
    tail = int(np.prod(shape[axis + 1:], dtype=np.int64))
    peak = _finite_peaks(arr.reshape(lead, shape[axis], tail))
    if not np.any(peak > PLANE_MAX):
        return np.ascontiguousarray(arr, dtype=np.float32), None
    exps = np.where(peak > PLANE_MAX, np.ceil(np.log2(peak / PLANE_MAX)), 0.0)
    scale = np.exp2(exps)
    factor = scale.reshape((-1,) + (1,) * (arr.ndim - axis - 1)).astype(arr.dtype)
    return np.ascontiguousarray(arr / factor, dtype=np.float32), scale


@njit(parallel=True, cache=True)
def _finite_peaks(arr):
    """(P,) float64 largest finite |value| of arr[:, p, :] (0 where none): one pass, no
    temporary copy of a video's planes."""
    P = arr.shape[1]
    peak = np.zeros(P, np.float64)
    for p in prange(P):
        m = 0.0
        for a in range(arr.shape[0]):
            for i in range(arr.shape[2]):
                v = abs(np.float64(arr[a, p, i]))
                if v > m and v < np.inf:
                    m = v
        peak[p] = m
    return peak
