"""BMFR, readable NumPy reference (docs/methods/bmfr.md): batched Householder least squares without
Q, the feature columns, the block grids and their offsets, the feature noise, and the per-block fit
and reconstruction. Shapes: planar images (C, H, W); features (M, H, W) raw (unscaled, noise-free);
least-squares batches A (K, m, n), B (K, m, c)."""
from __future__ import annotations

import numpy as np

from ...errors import DbenchInputError
from .params import (_GOLD, _M1, _M2, _MASK16, _S27, _S30, _S31, FEATURE_PRESETS, N_OFFSETS,
                     NORMAL_SOURCES, RCOND, normal_column)


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
    n = A.shape[2]
    if R.shape[1] < n:  # fewer rows than columns (a block's corner): zero rows change nothing,
        # and the columns they leave without a pivot are dropped by the safeguard below
        R = np.concatenate([R, np.zeros((R.shape[0], n - R.shape[1], R.shape[2]))], axis=1)
    k_, m, _ = R.shape
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


def feature_stack(normal: np.ndarray, position: np.ndarray, preset: str = "paper"
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Raw feature columns (M, H, W) float32 of a preset from planar normals (3·k, H, W) — the
    k normal buffers the preset reads, stacked in NORMAL_SOURCES' order (:func:`normal_sources`;
    just the shading normal for the spec's presets) — and position (3, H, W), and a (M,) bool
    mask of the position-derived columns that get per-block scaling (§2.1)."""
    if preset not in FEATURE_PRESETS:
        raise DbenchInputError(f"features: expected one of {tuple(FEATURE_PRESETS)}, "
                               f"got {preset!r}")
    cols, scaled = [], []
    for name in FEATURE_PRESETS[preset]:
        if name == "1":
            cols.append(np.ones(normal.shape[1:], np.float32))
        elif name[0] in NORMAL_SOURCES:
            cols.append(normal[normal_column(preset, name)])
        elif name.endswith("2"):
            p = position["xyz".index(name[1])]
            cols.append(p * p)
        else:
            cols.append(position["xyz".index(name[1])])
        scaled.append(name[0] == "p")
    return np.ascontiguousarray(np.stack(cols), np.float32), np.array(scaled, bool)


def grid_offsets(block: int, count: int = N_OFFSETS, seed: int = 0) -> np.ndarray:
    """``count`` distinct integer offsets (count, 2) as (x, y) in [−B/2, B/2)², the first (0, 0)
    (docs/methods/bmfr.md §3.1), from a seeded generator."""
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


def block_sample_mask(fit: np.ndarray, block: int, offset, samples: int, seed: int
                      ) -> np.ndarray:
    """(H, W) bool: ``samples`` pixels of ``fit`` drawn uniformly without replacement in every
    block of the grid with ``offset`` (x, y) (docs/methods/bmfr.md §3.1, the seed's 36 random coordinates per
    block); every fit pixel of a block that has no more than ``samples`` of them. The draw is the
    order of counter-based uniforms (:func:`uniform_hash`, column 63 so that it is independent of
    the feature noise), so it is reproducible and changes with ``seed`` (per frame)."""
    h, w = fit.shape
    ox, oy = int(offset[0]), int(offset[1])
    yy, xx = np.mgrid[0:h, 0:w]
    block_id = ((yy - oy) // block + 2) * (w // block + 8) + ((xx - ox) // block + 2)
    key = uniform_hash(seed, np.arange(h * w, dtype=np.uint64), 63).reshape(h, w)
    idx = np.flatnonzero(fit)
    order = idx[np.lexsort((key.ravel()[idx], block_id.ravel()[idx]))]
    ids = block_id.ravel()[order]
    first = np.r_[0, np.flatnonzero(np.diff(ids)) + 1]
    rank = np.arange(order.size) - np.repeat(first, np.diff(np.r_[first, order.size]))
    out = np.zeros(h * w, bool)
    out[order[rank < samples]] = True
    return out.reshape(h, w)
