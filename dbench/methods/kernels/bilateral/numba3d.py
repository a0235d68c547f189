"""Numba fast path of the base filter over (x, y, t): transient videos (docs/methods/jbf.md §1.4,
docs/methods/statistical.md §11.3). The spatial JBF weights replicated along time times a temporal factor
(:func:`~.guide.temporal_factors`, box or Gaussian), an optional float64 Welch test between bins,
half of the 3-D window evaluated, spatial weights computed once per row and reused by every bin,
bins outside the video (or not handed in) absent. A guide of the ``"xy"`` feature only is the
plain 3-D Gaussian of ``gauss3d``."""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from ....errors import DbenchInputError
from ..arrays import kernel_input
from ..welch import row_welch_pair, row_welch_pair_table
from .guide import Guide
from .numba2d import (EMPTY_TABLE, _scaled_planes, half_window, num_bands, row_exp,
                      row_exponent, scaled_feature_groups)
from .vexp import F0, F_CUT


@njit(parallel=True, cache=True)
def _accumulate3d_kernel(fsq, fdot, planes, dys, dxs, es, dt_first, tfac, nbr, active,
                         theta, var, nint, g2, table, test_mode, nbands, halo, sq_from):
    """Σ_{j ≠ i} W_ij · planes[j] over a 3D window for every voxel i of the bins in play.

    Voxel i = (bin k, row y, column x); j = (nbr[k, τ], y + dy, x + dx) for the spatial offsets
    (dys, dxs) of the half window (the centre (0, 0) first, then dy > 0 or dy = 0, dx > 0) and
    the temporal offsets τ = dt_first[o] − r_t .. r_t (all of them for a non-centre spatial
    offset, only τ > 0 for the centre). W_ij = ρ_spatial(y, x; o) · tfac[τ] · (Welch membership)
    is symmetric, so each pair is evaluated once and added to both voxels. The spatial base
    weights of a row are computed once per row for all offsets and reused by every bin.
    Planes p ≥ ``sq_from`` are summed with W_ij² instead of W_ij (variances of weighted means).

    Pairs with neither end ``active`` are skipped; sums into an inactive bin are not made
    (its output is not wanted). Row bands run in parallel, each with a private float32
    accumulator of its rows + ``halo`` rows for every bin, returned as (nbands, K, P, B + halo,
    W); :func:`_merge_bands3d` / :func:`_merge_normalise3d` merge them in float64.
    """
    K = planes.shape[0]
    P = planes.shape[1]
    H = planes.shape[2]
    W = planes.shape[3]
    O = dys.shape[0]
    NT = tfac.shape[0]
    B = (H + nbands - 1) // nbands
    acc = np.zeros((nbands, K, P, B + halo, W), np.float32)
    for b in prange(nbands):
        y0 = b * B
        y1 = min(H, y0 + B)
        rho = np.zeros((O, W), np.float32)
        live = np.zeros(O, np.bool_)
        w = np.empty(W, np.float32)
        for y in range(y0, y1):
            for o in range(O):
                dx = dxs[o]
                yy = y + dys[o]
                x0 = max(0, -dx)
                x1 = min(W, W - dx)
                live[o] = yy < H and x1 > x0 and es[o] < F_CUT
                if live[o]:
                    row_exponent(fsq, y, yy, x0, x1, dx, es[o], rho[o])
                    row_exp(fdot, F0, False, y, yy, x0, x1, dx, rho[o])
            r0 = y - y0
            for k in range(K):
                act_k = active[k]
                for o in range(O):
                    if not live[o]:
                        continue
                    dx = dxs[o]
                    yy = y + dys[o]
                    x0 = max(0, -dx)
                    x1 = min(W, W - dx)
                    n = x1 - x0
                    r1 = yy - y0
                    ro = rho[o]
                    for ti in range(dt_first[o], NT):
                        kk = nbr[k, ti]
                        if kk < 0:
                            continue
                        act_kk = active[kk]
                        if not (act_k or act_kk):
                            continue
                        f = tfac[ti]
                        if f <= F0:
                            continue
                        if test_mode == 1:
                            row_welch_pair(theta[k], var[k], theta[kk], var[kk], g2,
                                            y, yy, x0, x1, dx, ro, f, w)
                        else:
                            for i in range(n):
                                w[i] = ro[i] * f
                        if test_mode == 2:
                            row_welch_pair_table(theta[k], var[k], nint[k], theta[kk], var[kk],
                                                  nint[kk], table, y, yy, x0, x1, dx, w)
                        for p in range(P):
                            if p == sq_from:
                                for i in range(n):
                                    w[i] = w[i] * w[i]
                            if act_k:
                                pb = planes[kk, p, yy, x0 + dx:x1 + dx]
                                aa = acc[b, k, p, r0, x0:x1]
                                for i in range(n):
                                    aa[i] += w[i] * pb[i]
                            if act_kk:
                                pa = planes[k, p, y, x0:x1]
                                ab = acc[b, kk, p, r1, x0 + dx:x1 + dx]
                                for i in range(n):
                                    ab[i] += w[i] * pa[i]
    return acc


@njit(inline="always")
def add_band_rows(acc, k, y, band, s):  # pragma: no cover - compiled
    """s[p, x] += acc[b, k, p, y − b·band, x] for every band b holding row y (its own rows and
    its halo), in band order: the merge of :func:`_accumulate3d_kernel`'s accumulators for bin
    k and row y into the (P, W) float64 ``s``; ``band`` rows per band."""
    nbands = acc.shape[0]
    P = acc.shape[2]
    span = acc.shape[3]
    W = acc.shape[4]
    for bb in range(nbands):
        r = y - bb * band
        if 0 <= r < span:
            for p in range(P):
                for x in range(W):
                    s[p, x] += acc[bb, k, p, r, x]


@njit(parallel=True, cache=True)
def _merge_bands3d(acc, active, H):
    """Sum the band accumulators of :func:`_accumulate3d_kernel`: (K, P, H, W) float64."""
    nbands, K, P, BH, W = acc.shape
    B = (H + nbands - 1) // nbands
    out = np.zeros((K, P, H, W), np.float64)
    for y in prange(H):
        for k in range(K):
            if active[k]:
                add_band_rows(acc, k, y, B, out[k, :, y, :])
    return out


@njit(parallel=True, cache=True)
def _merge_normalise3d(acc, planes, active, bins, ratio, out):
    """Band sums + centre term, normalised by the last plane, written as a video.

    For every active bin k: out[y, x, bins[k], c] = (Σ_b acc[c] + planes[k, c]) / (Σ_b acc[P−1]
    + planes[k, P−1]) · ratio[c] in float64 (0 where the denominator is 0), c < P − 1, where
    ratio[c] = scale[c] / scale[P−1] undoes the planes' scaling (all 1 for ordinary inputs, an
    exact product); ``out`` is (H, W, T, P − 1) float32.
    """
    nbands, K, P, BH, W = acc.shape
    H = planes.shape[2]
    B = (H + nbands - 1) // nbands
    C = P - 1
    for y in prange(H):
        s = np.empty((P, W), np.float64)
        for k in range(K):
            if not active[k]:
                continue
            for p in range(P):
                for x in range(W):
                    s[p, x] = planes[k, p, y, x]
            add_band_rows(acc, k, y, B, s)
            t = bins[k]
            for x in range(W):
                d = s[C, x]
                for c in range(C):
                    out[y, x, t, c] = s[c, x] / d * ratio[c] if d > 0 else 0.0


_EMPTY_F64_4D = kernel_input(np.zeros((1, 3, 1, 1), np.float64))
_EMPTY_I32_4D = kernel_input(np.zeros((1, 3, 1, 1), np.int32))


def _half_window_3d(guide: Guide):
    """Spatial offsets for the 3D half window: the centre first, then the 2D half window."""
    dys, dxs, es = half_window(guide)
    dys = np.concatenate([[0], dys]).astype(np.int64)
    dxs = np.concatenate([[0], dxs]).astype(np.int64)
    es = np.concatenate([[0.0], es]).astype(np.float32)
    return dys, dxs, es


def accumulate3d(guide: Guide, planes: np.ndarray, tfac: np.ndarray, bins: np.ndarray,
                 active: np.ndarray | None = None, *, n_bins: int | None = None,
                 theta: np.ndarray | None = None, var: np.ndarray | None = None,
                 nint: np.ndarray | None = None, g2: float | None = None,
                 g2_table: np.ndarray | None = None,
                 normalise_into: np.ndarray | None = None,
                 squared_from: int | None = None, bands: bool = False):
    """Numba fast path in 3D: Σ_{j ≠ i} W_ij · planes_j over a (2r+1)² × (2r_t+1) window.

    The base weight is the JBF of ``guide`` replicated along time (its G-buffers are per pixel)
    times a temporal factor, W_ij = ρ_ij · tfac[τ] (docs/methods/jbf.md §1.4); with a guide of the
    ``"xy"`` feature only and no hit mask this is the plain 3D Gaussian of ``gauss3d`` when
    ``tfac`` is Gaussian. Bins outside the video get no weight.

    Args:
        guide: the spatial base filter (features, labels, window of radius r).
        planes: (K, P, H, W) values of the K bins in play (premultiplied by validity).
        tfac: (2r_t+1,) temporal factors of τ = −r_t..r_t.
        bins: (K,) increasing time indices of the planes' bins in the video; a neighbour bin that
            is not among them is absent (no weight), as are bins outside [0, n_bins).
        active: (K,) bool, the bins whose sums are wanted (default all); pairs between two
            inactive bins are skipped and inactive bins come back as 0.
        n_bins: T of the video (default bins[-1] + 1).
        theta, var: (K, 3, H, W) float64 statistics for the Welch test, or None (plain base
            filter); nint (K, 3, H, W) int32 with ``g2_table`` for non-uniform n, else ``g2``.
            A NaN θ fails every test, which makes that voxel nobody's neighbour.

        squared_from: planes from this index on are summed with the squared weight W_ij²
            (for the variance of a weighted mean, Σ W² Var); None: every plane with W_ij.
        normalise_into: optional (H, W, n_bins, P − 1) float32 video; the active bins are then
            written there as (sums + planes)[:P−1] / (sums + planes)[P−1] (the centre term
            added, 0 where the denominator is 0) and the video is returned instead of the sums.
        bands: return the kernel's band accumulators unmerged, for a caller that merges them
            in its own pass: (acc (nbands, K, P, rows + halo, W) float32, rows per band,
            scale (P,) float64); row y of band b is acc[b, :, :, y − b·rows] where
            0 ≤ y − b·rows < rows + halo, and the merged float64 sum of plane p is to be
            multiplied by scale[p] (1 for every ordinary plane, see below).

    Returns:
        (K, P, H, W) float64 sums without the centre term (the caller adds it),
        ``normalise_into``, or the bands.

    Precision as :func:`accumulate`: float32 weights and band sums, float64 Welch test and merge.
    A plane whose largest finite |value| exceeds
    :data:`~dbench.methods.kernels.bilateral.params.PLANE_MAX` (a block of colours near the
    float32 maximum, whose float32 sums would overflow to Inf) enters the kernel divided by a
    power of two (:func:`~.numba2d._scaled_planes`, exact) and its float64 sums are multiplied
    back; ordinary planes enter unchanged, so their results are bit for bit those without it.
    """
    planes = np.asarray(planes)
    if planes.ndim != 4 or planes.shape[2:] != guide.shape:
        raise DbenchInputError(f"planes: expected shape (K, P, {guide.shape[0]}, "
                               f"{guide.shape[1]}), got {planes.shape}")
    planes, scale = _scaled_planes(planes, axis=1)
    k_, p_, h, w = planes.shape
    factors = np.ones(p_, np.float64) if scale is None else scale
    bins = np.asarray(bins, np.int64)
    if bins.shape != (k_,) or (k_ > 1 and np.any(np.diff(bins) <= 0)) or (k_ and bins[0] < 0):
        raise DbenchInputError(f"bins: expected {k_} increasing indices ≥ 0, got {bins!r}")
    n_bins = int(bins[-1] + 1) if n_bins is None and k_ else int(n_bins or 0)
    active = (np.ones(k_, np.bool_) if active is None
              else np.ascontiguousarray(active, dtype=np.bool_))
    tfac = np.asarray(tfac, np.float64)
    r_t = (len(tfac) - 1) // 2
    lookup = np.full(max(n_bins, 1), -1, np.int64)
    lookup[bins] = np.arange(k_)
    tau = np.arange(-r_t, r_t + 1)
    tt = bins[:, None] + tau[None, :]
    nbr = np.where((tt >= 0) & (tt < n_bins), lookup[np.clip(tt, 0, max(n_bins - 1, 0))], -1)
    fsq = scaled_feature_groups(guide)
    dys, dxs, es = _half_window_3d(guide)
    dt_first = np.where((dys == 0) & (dxs == 0), r_t + 1, 0).astype(np.int64)
    if theta is None:
        test_mode, th, va, ni, table, gg = 0, _EMPTY_F64_4D, _EMPTY_F64_4D, _EMPTY_I32_4D, \
            EMPTY_TABLE, 0.0
    else:
        # read-only inputs (kernels/arrays.py), empty or not: one specialisation
        th = kernel_input(theta, np.float64)
        va = kernel_input(var, np.float64)
        if g2_table is None:
            test_mode, ni, table, gg = 1, _EMPTY_I32_4D, EMPTY_TABLE, float(g2)
        else:
            test_mode, gg = 2, 0.0
            ni = kernel_input(nint, np.int32)
            table = kernel_input(g2_table, np.float64)
    if normalise_into is not None:
        shape = (h, w, n_bins, planes.shape[1] - 1)
        if (normalise_into.shape != shape or normalise_into.dtype != np.float32
                or not normalise_into.flags.c_contiguous):
            raise DbenchInputError(f"normalise_into: expected a C-contiguous float32 array of "
                                   f"shape {shape}")
    nbands = num_bands(h)
    if k_ == 0:
        if bands:
            return np.zeros((nbands, 0) + planes.shape[1:2] + (1, w), np.float32), h, factors
        return np.zeros(planes.shape, np.float64) if normalise_into is None else normalise_into
    acc = _accumulate3d_kernel(fsq, np.zeros((0, 1, 1), np.float32), planes, dys, dxs, es,
                               dt_first, tfac.astype(np.float32), np.ascontiguousarray(nbr),
                               active, th, va, ni, np.float64(gg), table, int(test_mode),
                               nbands, int(guide.radius),
                               int(planes.shape[1] if squared_from is None else squared_from))
    if bands:
        return acc, (h + nbands - 1) // nbands, factors
    if normalise_into is None:
        sums = _merge_bands3d(acc, active, h)
        if scale is not None:
            sums *= scale[None, :, None, None]
        return sums
    _merge_normalise3d(acc, planes, active, bins, factors[:-1] / factors[-1], normalise_into)
    return normalise_into
