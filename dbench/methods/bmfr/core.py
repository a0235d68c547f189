"""BMFR functional core (spec/bmfr.md): features, block grids, stochastic regularisation,
batched Householder QR without Q, per-block fit and reconstruction.

Two implementations of everything, proven equal by tests/methods/test_bmfr.py:

* reference — NumPy, batched over blocks where that keeps it readable (``*_reference``);
* fast — Numba, one parallel loop over blocks, each block's augmented matrix held column-major
  in a (M + 3, W) float64 scratch array so that every reflection is a run of contiguous dot
  products (``*_fast``);
* torch — :mod:`dbench.methods.bmfr.torch_core`: every block of a grid in one (K, B², ·)
  batch, QR by ``torch.linalg.qr(mode="r")`` on [A | B] (CUDA when available, else CPU),
  reached through :func:`householder_lstsq` / :func:`bmfr_fit` with ``backend="torch"``.

Shapes: planar images (C, H, W); features (M, H, W) raw (unscaled, noise-free); least-squares
batches A (K, m, n), B (K, m, c).
"""
from __future__ import annotations

import math

import numpy as np

from ...errors import DbenchInputError

try:
    from numba import njit, prange
    HAVE_NUMBA = True
except ImportError:  # pragma: no cover
    HAVE_NUMBA = False

#: Feature presets (spec §2): names of the columns, constant first.
FEATURE_PRESETS = {
    "paper": ("1", "nx", "ny", "nz", "px", "py", "pz", "px2", "py2", "pz2"),
    "seed": ("1", "nx", "ny", "nz", "px", "py", "pz"),
    "normals": ("1", "nx", "ny", "nz"),
    "positions": ("1", "px", "py", "pz"),
}
RCOND = 1e-10      # rank safeguard |R_kk| < rcond · max |R_jj| (spec §5) [dbench]
N_OFFSETS = 16     # per-frame grid offsets, cycling [BMFR code]


# ---------------------------------------------------------------------------------------------
# Householder least squares (spec §5)


def householder_lstsq_reference(A: np.ndarray, B: np.ndarray, rcond: float = RCOND,
                                stable_sign: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """min ‖A X − B‖ for a batch by Householder reflections applied to [A | B], never forming Q.

    Args:
        A: (K, m, n), B: (K, m, c), any real dtype (computed in float64).
        rcond: columns whose |R_kk| < rcond · max_j |R_jj| get X_k = 0 (rank safeguard).
        stable_sign: s = −sign(x₀) (default, no cancellation); False: s = +1 as in the seed's
            appendix and the BMFR code (same solution in exact arithmetic).
    Returns:
        (X (K, n, c) float64, dropped (K,) int: columns zeroed by the safeguard).
    """
    R = np.concatenate([np.asarray(A, np.float64), np.asarray(B, np.float64)], axis=2)
    k_, m, _ = R.shape
    n = A.shape[2]
    for k in range(min(n, m)):
        x = R[:, k:, k]
        norm = np.sqrt((x * x).sum(1))
        s = np.where(x[:, 0] >= 0, -1.0, 1.0) if stable_sign else np.ones(k_)
        v = x.copy()
        v[:, 0] -= s * norm
        vv = (v * v).sum(1)
        safe = np.where(vv > 0, vv, 1.0)
        proj = np.einsum("km,kmj->kj", v, R[:, k:, k:])
        R[:, k:, k:] -= np.where(vv > 0, 2.0, 0.0)[:, None, None] * v[:, :, None] \
            * (proj / safe[:, None])[:, None, :]
    return _back_substitute(R[:, :n, :n], R[:, :n, n:], rcond)


def _back_substitute(Rt: np.ndarray, r: np.ndarray, rcond: float):
    k_, n, _ = Rt.shape
    diag = np.abs(np.diagonal(Rt, axis1=1, axis2=2))
    thr = rcond * diag.max(1, initial=0.0)
    keep = diag > thr[:, None]
    X = np.zeros(r.shape, np.float64)
    for k in range(n - 1, -1, -1):
        rhs = r[:, k, :] - np.einsum("kj,kjc->kc", Rt[:, k, k + 1:], X[:, k + 1:, :])
        X[:, k, :] = np.where(keep[:, k, None],
                              rhs / np.where(keep[:, k], Rt[:, k, k], 1.0)[:, None], 0.0)
    return X, (~keep).sum(1)


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


def householder_lstsq(A: np.ndarray, B: np.ndarray, rcond: float = RCOND,
                      backend: str = "numba", return_dropped: bool = False):
    """Solve min ‖A X − B‖ for batches A (K, m, n), B (K, m, c) by Householder QR without
    forming Q, R shared by the c right-hand sides (spec/bmfr.md §5) on ``backend`` ("numba",
    "torch" or "reference"). Returns X (K, n, c)
    float64 (and the per-batch count of columns zeroed by the rank safeguard when
    ``return_dropped``). 2-D inputs (m, n), (m, c) are treated as one batch.

    >>> import numpy as np
    >>> A = np.random.default_rng(0).random((4, 50, 3)); X = np.ones((4, 3, 2))
    >>> bool(np.allclose(householder_lstsq(A, A @ X), X))
    True
    """
    A = np.asarray(A)
    B = np.asarray(B)
    single = A.ndim == 2
    if single:
        A, B = A[None], B[None]
    if A.ndim != 3 or B.ndim != 3 or B.shape[:2] != A.shape[:2]:
        raise DbenchInputError(f"A, B: expected shapes (K, m, n) and (K, m, c) with the same K "
                               f"and m, got {A.shape} and {B.shape}")
    if backend == "torch":
        from ..temporal import to_numpy
        from .torch_core import householder_lstsq_torch
        X, dropped = (to_numpy(t) for t in householder_lstsq_torch(A, B, rcond))
    elif backend == "reference" or not HAVE_NUMBA:
        X, dropped = householder_lstsq_reference(A, B, rcond)
    elif backend == "numba":
        X = np.zeros((A.shape[0], A.shape[2], B.shape[2]), np.float64)
        dropped = np.zeros(A.shape[0], np.int64)
        _lstsq_batch_nb(np.ascontiguousarray(A, np.float64), np.ascontiguousarray(B, np.float64),
                        float(rcond), X, dropped)
    else:
        raise DbenchInputError(f"backend: expected 'numba', 'torch' or 'reference', "
                               f"got {backend!r}")
    if single:
        X, dropped = X[0], dropped[0]
    return (X, dropped) if return_dropped else X


# ---------------------------------------------------------------------------------------------
# features, grids, noise


def feature_stack(normal: np.ndarray, position: np.ndarray, preset: str = "paper"
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Raw feature columns (M, H, W) float32 of a preset from planar normal/position (3, H, W),
    and a (M,) bool mask of the position-derived columns that get per-block scaling (§2.1)."""
    if preset not in FEATURE_PRESETS:
        raise DbenchInputError(f"features: expected one of {tuple(FEATURE_PRESETS)}, "
                               f"got {preset!r}")
    cols, scaled = [], []
    for name in FEATURE_PRESETS[preset]:
        if name == "1":
            cols.append(np.ones(normal.shape[1:], np.float32))
        elif name[0] == "n":
            cols.append(normal["xyz".index(name[1])])
        elif name.endswith("2"):
            p = position["xyz".index(name[1])]
            cols.append(p * p)
        else:
            cols.append(position["xyz".index(name[1])])
        scaled.append(name[0] == "p")
    return np.ascontiguousarray(np.stack(cols), np.float32), np.array(scaled, bool)


def grid_offsets(block: int, count: int = N_OFFSETS, seed: int = 0) -> np.ndarray:
    """``count`` distinct integer offsets (count, 2) as (x, y) in [−B/2, B/2)², the first (0, 0)
    (spec §3.1), from a seeded generator."""
    rng = np.random.default_rng(seed)
    half = max(block // 2, 1)
    out = [(0, 0)]
    tries = 0
    while len(out) < count:
        o = tuple(int(v) for v in rng.integers(-half, half, 2))
        tries += 1
        if o not in out or tries > 100 * count:
            out.append(o)
    return np.array(out, np.int64)


def block_origins(h: int, w: int, block: int, offset) -> np.ndarray:
    """(nb, 2) int64 (y0, x0) of every block of the grid with ``offset`` (x, y) that
    intersects the image; blocks are [y0, y0 + B) × [x0, x0 + B) clipped to the image."""
    ox, oy = int(offset[0]), int(offset[1])
    ys = [oy + j * block for j in range(-2, h // block + 3) if oy + (j + 1) * block > 0
          and oy + j * block < h]
    xs = [ox + i * block for i in range(-2, w // block + 3) if ox + (i + 1) * block > 0
          and ox + i * block < w]
    return np.array([(y, x) for y in ys for x in xs], np.int64).reshape(-1, 2)


_GOLD = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
_INV53 = 1.0 / 9007199254740992.0


_MASK16 = np.uint64(0xFFFF)


def uniform_hash(seed: int, index: np.ndarray, column: int) -> np.ndarray:
    """Counter-based uniforms in (0, 1): one splitmix64 of (seed, pixel index, column // 4)
    gives four 16-bit uniforms, column % 4 picks one ((k + 0.5) / 65536). The compiled path
    computes the same numbers, so reference and fast fits see identical noise."""
    with np.errstate(over="ignore"):
        z = (np.uint64(seed) * _GOLD + np.asarray(index, np.uint64) * _M1
             + np.uint64(column // 4) * _M2)
        z = (z ^ (z >> _S30)) * _M1
        z = (z ^ (z >> _S27)) * _M2
        z = z ^ (z >> _S31)
    chunk = (z >> np.uint64(16 * (column % 4))) & _MASK16
    return (chunk.astype(np.float64) + 0.5) / 65536.0


if HAVE_NUMBA:
    @njit(cache=True, inline="always")
    def _hash64_nb(seed, index, group):
        z = seed * _GOLD + np.uint64(index) * _M1 + np.uint64(group) * _M2
        z = (z ^ (z >> _S30)) * _M1
        z = (z ^ (z >> _S27)) * _M2
        return z ^ (z >> _S31)


# ---------------------------------------------------------------------------------------------
# the per-block fit (spec §3-§5)


def bmfr_fit_reference(z: np.ndarray, feats: np.ndarray, scaled: np.ndarray, fit: np.ndarray,
                       recon: np.ndarray, block: int, offset, noise_amount: float = 0.01,
                       noise_seed: int = 0, rcond: float = RCOND, clamp: bool = True
                       ) -> tuple[np.ndarray, int]:
    """Fit every block of the grid with ``offset`` and reconstruct (readable reference).

    Args:
        z: (3, H, W) target (the accumulated demodulated colour Z').
        feats: (M, H, W) raw features, constant first; scaled (M,) bool position columns.
        fit: (H, W) bool pixels used in the fit; recon (H, W) bool pixels reconstructed.
        block, offset: block size B and grid offset (x, y).
        noise_amount: η of the U(−η, η) noise added to every feature column but the constant
            (noise-free features reconstruct); noise_seed: this frame's seed.
    Returns:
        (y (3, H, W) float32: fitted values at ``recon`` pixels, ``z`` elsewhere; number of
        columns zeroed by the rank safeguard over all blocks).
    """
    c, h, w = z.shape
    m_ = feats.shape[0]
    out = np.array(z, np.float32, copy=True)
    dropped = 0
    for y0, x0 in block_origins(h, w, block, offset):
        ys = slice(max(y0, 0), min(y0 + block, h))
        xs = slice(max(x0, 0), min(x0 + block, w))
        f_blk = feats[:, ys, xs].reshape(m_, -1).astype(np.float64)
        fit_blk = fit[ys, xs].ravel()
        rec_blk = recon[ys, xs].ravel()
        if not fit_blk.any() or not rec_blk.any():
            continue
        for j in np.flatnonzero(scaled):  # §2.1 per-block scaling over the fit pixels
            lo, hi = f_blk[j, fit_blk].min(), f_blk[j, fit_blk].max()
            f_blk[j] = (f_blk[j] - lo) / max(hi - lo, 1.0)
        yy, xx = np.mgrid[ys, xs]
        index = (yy * w + xx).ravel()[fit_blk]
        A = f_blk[:, fit_blk].T.copy()
        for j in range(1, m_):
            A[:, j] += noise_amount * (2.0 * uniform_hash(noise_seed, index, j) - 1.0)
        B = z[:, ys, xs].reshape(c, -1)[:, fit_blk].T.astype(np.float64)
        X, d = householder_lstsq_reference(A[None], B[None], rcond)
        dropped += int(d[0])
        yfit = (f_blk.T @ X[0]).T  # (3, npx)
        if clamp:
            yfit = np.maximum(yfit, 0.0)
        blk = out[:, ys, xs].reshape(c, -1)
        blk[:, rec_blk] = yfit[:, rec_blk]
        out[:, ys, xs] = blk.reshape(c, ys.stop - ys.start, xs.stop - xs.start)
    return out, dropped


if HAVE_NUMBA:
    @njit(cache=True, inline="always")
    def _feat(src_a, src_b, kinds, axes, j, y, x):
        """Feature column j at pixel (y, x): kind 0 → 1, 1 → src_a[axis], 2 → src_b[axis],
        3 → src_b[axis]² (so the fit can read normals/positions without a feature stack)."""
        k = kinds[j]
        if k == 0:
            return 1.0
        if k == 1:
            return np.float64(src_a[axes[j], y, x])
        v = np.float64(src_b[axes[j], y, x])
        return v * v if k == 3 else v

    @njit(cache=True, parallel=True, fastmath=True, error_model="numpy")
    def _bmfr_fit_nb(z, src_a, src_b, kinds, axes, scaled, fit, recon, origins, block,
                     noise_amount, noise_seed, rcond, clamp, out, dropped):
        c, h, w = z.shape
        m_ = kinds.shape[0]
        nb = origins.shape[0]
        seed = np.uint64(noise_seed)
        for b in prange(nb):
            y0 = origins[b, 0]
            x0 = origins[b, 1]
            ya, yb = max(y0, 0), min(y0 + block, h)
            xa, xb = max(x0, 0), min(x0 + block, w)
            lo = np.full(m_, np.inf)
            hi = np.full(m_, -np.inf)
            rows = 0
            anyrec = False
            for y in range(ya, yb):
                for x in range(xa, xb):
                    if recon[y, x]:
                        anyrec = True
                    if fit[y, x]:
                        rows += 1
                        for j in range(m_):
                            if scaled[j]:
                                f = _feat(src_a, src_b, kinds, axes, j, y, x)
                                if f < lo[j]:
                                    lo[j] = f
                                if f > hi[j]:
                                    hi[j] = f
            dropped[b] = 0
            if rows == 0 or not anyrec:
                continue
            scale = np.ones(m_)
            shift = np.zeros(m_)
            for j in range(m_):
                if scaled[j]:
                    shift[j] = lo[j]
                    scale[j] = 1.0 / max(hi[j] - lo[j], 1.0)
            # pixel list of the fit rows, then the matrix one column at a time (contiguous)
            py = np.empty(rows, np.int64)
            px = np.empty(rows, np.int64)
            r = 0
            for y in range(ya, yb):
                for x in range(xa, xb):
                    if fit[y, x]:
                        py[r] = y
                        px[r] = x
                        r += 1
            M = np.empty((m_ + c, rows), np.float64)
            for j in range(m_):
                col = M[j]
                sh, sc = shift[j], scale[j]
                for r in range(rows):
                    col[r] = (_feat(src_a, src_b, kinds, axes, j, py[r], px[r]) - sh) * sc
            if noise_amount > 0:
                amp = 2.0 * noise_amount
                for g in range((m_ + 2) // 4):  # columns 1 … m_−1, four per hash
                    for r in range(rows):
                        hsh = _hash64_nb(seed, py[r] * w + px[r], g)
                        for t in range(4):
                            j = 4 * g + t
                            if j >= 1 and j < m_:
                                u = (np.float64((hsh >> np.uint64(16 * t)) & _MASK16) + 0.5) \
                                    * (1.0 / 65536.0)
                                M[j, r] += amp * (u - 0.5)
            for q in range(c):
                col = M[m_ + q]
                for r in range(rows):
                    col[r] = z[q, py[r], px[r]]
            X = np.zeros((m_, c), np.float64)
            dropped[b] = _qr_solve_cm(M, rows, m_, c, rcond, X)
            # fold the per-block scaling into the coefficients: y = Σ_j f_j X'_j + b
            Xs = np.empty((m_, c), np.float64)
            b0 = np.zeros(c, np.float64)
            for q in range(c):
                for j in range(m_):
                    Xs[j, q] = scale[j] * X[j, q]
                    b0[q] -= shift[j] * scale[j] * X[j, q]
            for y in range(ya, yb):
                for x in range(xa, xb):
                    if not recon[y, x]:
                        continue
                    for q in range(c):
                        acc = b0[q]
                        for j in range(m_):
                            acc += _feat(src_a, src_b, kinds, axes, j, y, x) * Xs[j, q]
                        out[q, y, x] = max(acc, 0.0) if clamp else acc


def bmfr_fit_fast(z, feats, scaled, fit, recon, block, offset, noise_amount=0.01, noise_seed=0,
                  rcond=RCOND, clamp=True, source=None):
    """Compiled :func:`bmfr_fit_reference` (same arguments and results; blocks in parallel).

    ``source=(normal, position, preset)`` (planar (3, H, W) arrays) lets the kernel read the
    feature columns directly instead of from the (M, H, W) stack ``feats`` (which may then be
    None): the same numbers without building the stack.
    """
    z = np.ascontiguousarray(z, np.float32)
    out = z.copy()
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
    1 normal, 2 position, 3 squared position; axis 0/1/2 = x/y/z."""
    if preset not in FEATURE_PRESETS:
        raise DbenchInputError(f"features: expected one of {tuple(FEATURE_PRESETS)}, "
                               f"got {preset!r}")
    kinds, axes = [], []
    for name in FEATURE_PRESETS[preset]:
        if name == "1":
            kinds.append(0)
            axes.append(0)
        else:
            kinds.append(1 if name[0] == "n" else 3 if name.endswith("2") else 2)
            axes.append("xyz".index(name[1]))
    return np.array(kinds, np.int64), np.array(axes, np.int64)


def bmfr_fit(backend: str, *args, **kw):
    """Arguments of :func:`bmfr_fit_reference` on ``backend``; (y (3, H, W) float32 NumPy,
    dropped)."""
    if backend == "torch":
        from ..temporal import to_numpy
        from .torch_core import bmfr_fit_torch
        y, dropped = bmfr_fit_torch(*args, **kw)
        return to_numpy(y), dropped
    if backend == "reference" or not HAVE_NUMBA:
        return bmfr_fit_reference(*args, **kw)
    return bmfr_fit_fast(*args, **kw)
