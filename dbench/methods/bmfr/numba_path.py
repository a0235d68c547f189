"""BMFR compiled with Numba: one parallel loop over blocks, each block's augmented matrix held
column-major in a (M + 3, W) float64 scratch array so that every reflection is a run of
contiguous dot products. Same numbers as :mod:`dbench.methods.bmfr.reference` (the feature noise
is the same counter-based hash), proven equal by tests/methods/test_bmfr.py."""
from __future__ import annotations

import math

import numpy as np

from ...errors import DbenchInputError
from .params import (_GOLD, _M1, _M2, _MASK16, _S27, _S30, _S31, FEATURE_PRESETS, NORMAL_SOURCES,
                     RCOND, normal_column)
from .reference import block_origins


try:
    from numba import njit, prange
    HAVE_NUMBA = True
except ImportError:  # pragma: no cover
    HAVE_NUMBA = False


if HAVE_NUMBA:
    @njit(cache=True, fastmath=True, error_model="numpy")
    def _qr_solve_cm(M, rows, n, c, rcond, X):
        """In place on the column-major augmented matrix M (n + c, ≥rows): Householder on the
        first n columns over the first ``rows`` rows, then back substitution into X (n, c).
        Returns the number of columns zeroed by the safeguard."""
        kmax = min(n, rows)
        for k in range(kmax):
            v = M[k, k:rows]  # views starting at 0: the loops below vectorise
            norm2 = 0.0
            for r in range(rows - k):
                norm2 += v[r] * v[r]
            norm = math.sqrt(norm2)
            x0 = v[0]
            s = -1.0 if x0 >= 0 else 1.0
            # v = x − s‖x‖e1 stored in place of column k; ‖v‖² = ‖x‖² − x0² + v0²
            v0 = x0 - s * norm
            vv = norm2 - x0 * x0 + v0 * v0
            if vv <= 0.0:
                continue
            v[0] = v0
            for j in range(k + 1, n + c):
                col = M[j, k:rows]
                dot = 0.0
                for r in range(rows - k):
                    dot += v[r] * col[r]
                f = 2.0 * dot / vv
                for r in range(rows - k):
                    col[r] -= f * v[r]
            # column k itself becomes (s‖x‖, 0, …, 0)
            v[0] = s * norm
            for r in range(1, rows - k):
                v[r] = 0.0
        dmax = 0.0
        for k in range(n):
            d = abs(M[k, k]) if k < rows else 0.0
            if d > dmax:
                dmax = d
        dropped = 0
        for k in range(n - 1, -1, -1):
            d = abs(M[k, k]) if k < rows else 0.0
            if not d > rcond * dmax:
                dropped += 1
                for q in range(c):
                    X[k, q] = 0.0
                continue
            for q in range(c):
                acc = M[n + q, k]
                for j in range(k + 1, n):
                    acc -= M[j, k] * X[j, q]
                X[k, q] = acc / M[k, k]
        return dropped

    @njit(cache=True, parallel=True, error_model="numpy")
    def _lstsq_batch_nb(A, B, rcond, X, dropped):
        k_, m, n = A.shape
        c = B.shape[2]
        for b in prange(k_):
            M = np.empty((n + c, m), np.float64)
            for r in range(m):
                for j in range(n):
                    M[j, r] = A[b, r, j]
                for q in range(c):
                    M[n + q, r] = B[b, r, q]
            Xb = np.zeros((n, c), np.float64)
            dropped[b] = _qr_solve_cm(M, m, n, c, rcond, Xb)
            X[b] = Xb


def householder_lstsq_fast(A: np.ndarray, B: np.ndarray, rcond: float = RCOND):
    """Compiled :func:`~dbench.methods.bmfr.reference.householder_lstsq_reference` (blocks in
    parallel, each augmented matrix column-major): (X (K, n, c) float64, dropped (K,) int)."""
    X = np.zeros((A.shape[0], A.shape[2], B.shape[2]), np.float64)
    dropped = np.zeros(A.shape[0], np.int64)
    _lstsq_batch_nb(np.ascontiguousarray(A, np.float64), np.ascontiguousarray(B, np.float64),
            float(rcond), X, dropped)
    return X, dropped


if HAVE_NUMBA:
    @njit(cache=True, inline="always")
    def _hash64_nb(seed, index, group):
        z = seed * _GOLD + np.uint64(index) * _M1 + np.uint64(group) * _M2
        z = (z ^ (z >> _S30)) * _M1
        z = (z ^ (z >> _S27)) * _M2
        return z ^ (z >> _S31)


if HAVE_NUMBA:
    @njit(cache=True, parallel=True, fastmath=True, error_model="numpy")
    def _bmfr_fit_nb(z, src_a, src_b, kinds, axes, scaled, fit, recon, origins, block,
                     noise_amount, noise_seed, rcond, clamp, out, dropped):
        """``z``, ``out`` (C, H, W); ``src_a``, ``src_b`` flattened to (·, H·W) so that a
        feature column is one gather through the fit pixels' flat indices, its kind (constant,
        value, square: ``kinds``, :func:`feature_layout`) decided once per column, not per
        pixel. Pixels of a block that are not reconstructed keep ``z``."""
        c, h, w = z.shape
        m_ = kinds.shape[0]
        nb = origins.shape[0]
        seed = np.uint64(noise_seed)
        for b in prange(nb):
            y0 = origins[b, 0]
            x0 = origins[b, 1]
            ya, yb = max(y0, 0), min(y0 + block, h)
            xa, xb = max(x0, 0), min(x0 + block, w)
            # the fit rows' pixels, then the raw feature columns (contiguous rows of M)
            rows = 0
            anyrec = False
            for y in range(ya, yb):
                for x in range(xa, xb):
                    if recon[y, x]:
                        anyrec = True
                    if fit[y, x]:
                        rows += 1
            dropped[b] = 0
            if rows == 0 or not anyrec:
                for y in range(ya, yb):
                    for q in range(c):
                        out[q, y, xa:xb] = z[q, y, xa:xb]
                continue
            pix = np.empty(rows, np.int64)  # the fit pixels' flat indices y·W + x
            r = 0
            for y in range(ya, yb):
                for x in range(xa, xb):
                    if fit[y, x]:
                        pix[r] = y * w + x
                        r += 1
            M = np.empty((m_ + c, rows), np.float64)
            for j in range(m_):
                col = M[j]
                k = kinds[j]
                if k == 0:
                    col[:] = 1.0
                    continue
                plane = src_a[axes[j]] if k == 1 else src_b[axes[j]]
                if k == 3:
                    for r in range(rows):
                        v = np.float64(plane[pix[r]])
                        col[r] = v * v
                else:
                    for r in range(rows):
                        col[r] = np.float64(plane[pix[r]])
            # per-block scaling of the scaled columns to [0, 1]: f' = (f − min) / max(range, 1),
            # in place on the raw columns (the same numbers as scaling while reading them)
            scale = np.ones(m_)
            shift = np.zeros(m_)
            for j in range(m_):
                if scaled[j]:
                    col = M[j]
                    lo, hi = np.inf, -np.inf
                    for r in range(rows):
                        lo = min(lo, col[r])
                        hi = max(hi, col[r])
                    shift[j] = lo
                    scale[j] = 1.0 / max(hi - lo, 1.0)
                    sh, sc = shift[j], scale[j]
                    for r in range(rows):
                        col[r] = (col[r] - sh) * sc
            if noise_amount > 0:
                amp = 2.0 * noise_amount
                hashes = np.empty(rows, np.uint64)
                for g in range((m_ + 3) // 4):  # columns 1 … m_−1, four per hash
                    for r in range(rows):
                        hashes[r] = _hash64_nb(seed, pix[r], g)
                    for t in range(4):  # one column at a time: branch-free, vectorised
                        j = 4 * g + t
                        if j < 1 or j >= m_:
                            continue
                        col = M[j]
                        sh16 = np.uint64(16 * t)
                        for r in range(rows):
                            u = (np.float64((hashes[r] >> sh16) & _MASK16) + 0.5) \
                                * (1.0 / 65536.0)
                            col[r] += amp * (u - 0.5)
            zf = z.reshape(c, h * w)
            for q in range(c):
                col = M[m_ + q]
                zq = zf[q]
                for r in range(rows):
                    col[r] = zq[pix[r]]
            X = np.zeros((m_, c), np.float64)
            dropped[b] = _qr_solve_cm(M, rows, m_, c, rcond, X)
            # fold the per-block scaling into the coefficients: y = Σ_j f_j X'_j + b
            Xs = np.empty((m_, c), np.float64)
            b0 = np.zeros(c, np.float64)
            for q in range(c):
                for j in range(m_):
                    Xs[j, q] = scale[j] * X[j, q]
                    b0[q] -= shift[j] * scale[j] * X[j, q]
            # reconstruction one image row of the block at a time, feature by feature, so
            # that the loops over x read contiguous feature rows and vectorise (the same sum,
            # b + Σ_j f_j X_j in column order, as the reference)
            nx = xb - xa
            acc = np.empty((c, nx), np.float64)
            for y in range(ya, yb):
                for q in range(c):
                    for i in range(nx):
                        acc[q, i] = b0[q]
                for j in range(m_):
                    k = kinds[j]
                    if k == 0:
                        for q in range(c):
                            coef = Xs[j, q]
                            for i in range(nx):
                                acc[q, i] += coef
                        continue
                    start = y * w + xa
                    row = (src_a[axes[j], start:start + nx] if k == 1
                           else src_b[axes[j], start:start + nx])
                    square = k == 3
                    for q in range(c):
                        coef = Xs[j, q]
                        for i in range(nx):
                            f = np.float64(row[i])
                            if square:
                                f = f * f
                            acc[q, i] += f * coef
                # a select per channel row, not a branch per pixel: the loops vectorise
                # (2.5 ms of the 720p fit; the row views cost 3 reference counts per row)
                rec = recon[y, xa:xb]
                for q in range(c):
                    zrow = z[q, y, xa:xb]
                    orow = out[q, y, xa:xb]
                    for i in range(nx):
                        v = max(acc[q, i], 0.0) if clamp else acc[q, i]
                        orow[i] = np.float32(v) if rec[i] else zrow[i]


def bmfr_fit_fast(z, feats, scaled, fit, recon, block, offset, noise_amount=0.01, noise_seed=0,
                  rcond=RCOND, clamp=True, source=None, out=None):
    """Compiled :func:`bmfr_fit_reference` (same arguments and results; blocks in parallel).

    ``source=(normals, position, preset)`` (planar (3·k, H, W) stacked normals as
    :func:`~dbench.methods.bmfr.reference.feature_stack` takes them, (3, H, W)) lets the kernel read the
    feature columns directly instead of from the (M, H, W) stack ``feats`` (which may then be
    None): the same numbers without building the stack. ``out``: an optional (3, H, W) float32
    array (not ``z``) the result is written into, kept by the caller from frame to frame (a
    fresh 720p image costs its page faults, about 2 ms).
    """
    z = np.ascontiguousarray(z, np.float32)
    if out is None:
        out = np.empty_like(z)  # the blocks tile the image: the kernel writes every pixel
    elif out.shape != z.shape or out.dtype != np.float32 or np.may_share_memory(out, z):
        raise ValueError(f"out: expected a float32 {z.shape} array apart from z")
    h, w = z.shape[1:]
    if source is not None:
        normal, position, preset = source
        kinds, axes = feature_layout(preset)
        src_a = np.ascontiguousarray(normal, np.float32)
        src_b = np.ascontiguousarray(position, np.float32)
    else:
        src_a = np.ascontiguousarray(feats, np.float32)
        src_b = np.zeros((1, 1, 1), np.float32)
        kinds = np.ones(len(src_a), np.int64)
        axes = np.arange(len(src_a), dtype=np.int64)
    src_a = src_a.reshape(len(src_a), -1)
    src_b = src_b.reshape(len(src_b), -1)
    scaled = np.asarray(scaled, np.bool_)
    origins = block_origins(h, w, block, offset)
    dropped = np.zeros(len(origins), np.int64)
    if len(origins):
        _bmfr_fit_nb(z, src_a, src_b, kinds, axes, scaled,
                     np.ascontiguousarray(fit, np.bool_), np.ascontiguousarray(recon, np.bool_),
                     origins, int(block), float(noise_amount), int(noise_seed), float(rcond),
                     bool(clamp), out, dropped)
    return out, int(dropped.sum())


def feature_layout(preset: str) -> tuple[np.ndarray, np.ndarray]:
    """(kinds, axes) int64 of a preset's columns for the compiled fit: kind 0 constant,
    1 normal (axis: the channel of the stacked normals, :func:`normal_column`), 2 position,
    3 squared position (axis 0/1/2 = x/y/z)."""
    if preset not in FEATURE_PRESETS:
        raise DbenchInputError(f"features: expected one of {tuple(FEATURE_PRESETS)}, "
                               f"got {preset!r}")
    kinds, axes = [], []
    for name in FEATURE_PRESETS[preset]:
        if name == "1":
            kinds.append(0)
            axes.append(0)
        elif name[0] in NORMAL_SOURCES:
            kinds.append(1)
            axes.append(normal_column(preset, name))
        else:
            kinds.append(3 if name.endswith("2") else 2)
            axes.append("xyz".index(name[1]))
    return np.array(kinds, np.int64), np.array(axes, np.int64)
