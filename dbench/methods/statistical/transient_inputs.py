"""Inputs of the spatio-temporal statistical denoiser (docs/methods/statistical.md §11.1, §11.3):
the per-voxel statistics θ̂, Var(θ̂), n of the bins in play (:class:`VideoStats`,
:func:`video_stats` for the readable reference, :func:`prepare_video` for the kernel in one parallel
pass), the non-empty bins and the bins their temporal window reaches.

Shapes: colour and statistics (H, W, T, 3); kernel layout (K, 3, H, W) for the K bins in play.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np
from numba import njit, prange

from ...data import check_buffer
from ...errors import DbenchInputError
from ..kernels.arrays import kernel_input

__all__ = ["VideoStats", "video_stats", "nonempty_bins", "prepare_video", "bins_in_play",
           "video_shape"]



@dataclass(frozen=True)
class VideoStats:
    """Per-voxel statistics of some bins (docs/methods/statistical.md §11.1).

    theta, var: θ̂ and Var(θ̂), float64; nint: int32 n (None when not needed); bad: voxels with
    non-finite statistics; bins: (K,) time indices; transform, lam: as recorded in the
    SampleStats. Layouts: (K, 3, H, W) / bad (K, H, W) for the kernel (:func:`prepare_video`,
    θ̂ NaN and Var 0 at bad voxels, so that every test with them fails), or (H, W, K, 3) / bad
    (H, W, K) for the reference (``video_stats(..., channel_first=False)``, θ̂ = Var = n = 0 at
    bad voxels).
    """

    theta: np.ndarray
    var: np.ndarray
    nint: np.ndarray
    bad: np.ndarray
    bins: np.ndarray
    transform: str
    lam: float


def video_shape(color: Any) -> tuple[int, int, int]:
    arr = np.asarray(color) if color is not None else None
    if arr is None or arr.ndim != 4 or arr.shape[3] != 3 or 0 in arr.shape:
        raise DbenchInputError(f"color: expected shape (H, W, T, 3), got "
                               f"{None if arr is None else tuple(arr.shape)}")
    return arr.shape[0], arr.shape[1], arr.shape[2]


def video_stats(stats: Any, shape: tuple[int, int, int], bins: Sequence[int] | None = None,
                channel_first: bool = True) -> VideoStats:
    """Check (H, W, T, 3) SampleStats and return θ̂, Var(θ̂), n of the chosen ``bins``.

    θ̂ = μ + M3/(6σ²n) (docs/methods/statistical.md §4, correction 0 where σ² = 0), computed for those bins only.
    With ``channel_first`` the arrays are (K, 3, H, W) (the kernel's layout), else (H, W, K, 3).

    Raises:
        DbenchInputError: missing statistics, wrong shape, negative variance or count.
    """
    h, w, t = shape
    if stats is None:
        raise DbenchInputError(f"stats: missing; expected SampleStats with arrays of shape "
                               f"({h}, {w}, {t}, 3)")
    full = (h, w, t, 3)
    idx = np.arange(t) if bins is None else np.asarray(bins, np.int64)
    everything = idx.size == t

    def pick(name, arr):
        a = check_buffer(name, np.broadcast_to(arr, full) if np.ndim(arr) == 0 else arr, full,
                         dtype=np.float64)
        return a if everything else a[:, :, idx]

    mean = pick("stats.mean", stats.mean)
    var = pick("stats.var_mean", stats.var_mean)
    n = pick("stats.n", stats.n)
    m3 = pick("stats.m3", stats.m3)
    with np.errstate(invalid="ignore"):
        if np.any(var < 0):
            raise DbenchInputError("stats.var_mean: negative values; expected Var(θ̂) ≥ 0")
        if np.any(n < 0):
            raise DbenchInputError("stats.n: negative sample counts")
    with np.errstate(invalid="ignore", over="ignore"):
        denom = 6.0 * var * n * n
        theta = mean + np.divide(m3, denom, out=np.zeros_like(m3), where=denom > 0)
    bad = ~(np.all(np.isfinite(theta), -1) & np.all(np.isfinite(var), -1)
            & np.all(np.isfinite(n), -1))
    if bad.any():
        theta = np.where(bad[..., None], 0.0, theta)
        var = np.where(bad[..., None], 0.0, var)
        n = np.where(bad[..., None], 0.0, n)
    nint = np.minimum(np.rint(n), 2 ** 30).astype(np.int32)
    if channel_first:
        def cf(a):
            return np.ascontiguousarray(np.transpose(a, (2, 3, 0, 1)))
        theta, var, nint, bad = cf(theta), cf(var), cf(nint), np.ascontiguousarray(
            np.transpose(bad, (2, 0, 1)))
    return VideoStats(theta, var, nint, bad, idx, str(getattr(stats, "transform", "unknown")),
                      float(getattr(stats, "lam", float("nan"))))


def nonempty_bins(color: Any) -> np.ndarray:
    """(T,) bool: bins of an (H, W, T, 3) video holding any value other than exactly 0
    (NaN counts as non-empty)."""
    return np.asarray(np.any(np.asarray(color) != 0, axis=(0, 1, 3)))


@njit(parallel=True, cache=True)
def _prepare_video(color, mean, var, n, m3, idx, want_stats, want_nint, planes, theta, vout,
                   nint, bad, flags):
    """One parallel pass over the (H, W, T, 3) inputs for the bins ``idx`` (kernel layout).

    planes[k] = (colour·v, v) with v = colour finite, followed, when ``planes`` has more than 4
    planes, by the shrinkage planes of :func:`dbench.methods.statistical.shrink.shrink_layout`
    (7: θ̄·v, V̄·v, v; 6: V̄·v, v; θ̄, V̄ channel means, 0 at bad voxels); with ``want_stats``
    θ̂ = μ + M3/(6σ²n)
    (the same float64 expression as :func:`video_stats`), NaN at voxels with non-finite
    statistics (``bad``), and Var(θ̂) (0 there); with ``want_nint`` the rounded counts.
    flags[y] = (negative variance seen, negative n seen, min n, max n over good voxels).
    """
    H = color.shape[0]
    W = color.shape[1]
    K = idx.shape[0]
    P = planes.shape[1]
    for y in prange(H):
        neg_v = 0
        neg_n = 0
        lo = 1 << 30
        hi = -1
        for x in range(W):
            for k in range(K):
                t = idx[k]
                ok = True
                for c in range(3):
                    if not np.isfinite(color[y, x, t, c]):
                        ok = False
                for c in range(3):
                    planes[k, c, y, x] = color[y, x, t, c] if ok else np.float32(0.0)
                planes[k, 3, y, x] = np.float32(1.0) if ok else np.float32(0.0)
                if not want_stats:
                    continue
                good = True
                for c in range(3):
                    v = var[y, x, t, c]
                    nn = n[y, x, t, c]
                    if v < 0:
                        neg_v = 1
                    if nn < 0:
                        neg_n = 1
                    denom = 6.0 * v * nn * nn
                    th = mean[y, x, t, c]
                    if denom > 0:
                        th = th + m3[y, x, t, c] / denom
                    theta[k, c, y, x] = th
                    vout[k, c, y, x] = v
                    if not (np.isfinite(th) and np.isfinite(v) and np.isfinite(nn)):
                        good = False
                bad[k, y, x] = not good
                if not good:
                    for c in range(3):
                        theta[k, c, y, x] = np.nan
                        vout[k, c, y, x] = 0.0
                for c in range(3):
                    ni = 0
                    if good:
                        ni = np.int32(np.rint(min(n[y, x, t, c], 1073741824.0)))
                        lo = min(lo, ni)
                        hi = max(hi, ni)
                    if want_nint:
                        nint[k, c, y, x] = ni
                if P > 4:
                    vv = planes[k, 3, y, x]
                    th_bar = 0.0
                    var_bar = 0.0
                    if good:
                        th_bar = (theta[k, 0, y, x] + theta[k, 1, y, x] + theta[k, 2, y, x]) / 3.0
                        var_bar = (vout[k, 0, y, x] + vout[k, 1, y, x] + vout[k, 2, y, x]) / 3.0
                    if P == 7:
                        planes[k, 4, y, x] = th_bar * vv
                    planes[k, P - 2, y, x] = var_bar * vv
                    planes[k, P - 1, y, x] = vv
        flags[y, 0] = neg_v
        flags[y, 1] = neg_n
        flags[y, 2] = lo
        flags[y, 3] = hi


def prepare_video(color: Any, stats: Any, bins: np.ndarray, *, want_stats: bool = True,
                  want_nint: bool = False, n_planes: int = 4):
    """Kernel inputs for the ``bins`` of a video in one parallel pass (:func:`_prepare_video`).

    ``n_planes``: 4 (colour·v, v), or 6 / 7 with the shrinkage planes
    (:func:`dbench.methods.statistical.shrink.shrink_layout`; needs ``want_stats``).

    Returns:
        planes (K, n_planes, H, W) float32 and, with ``want_stats``, a
        :class:`VideoStats` whose θ̂ is NaN at bad voxels (its ``nint`` None unless
        ``want_nint``), plus (min n, max n) over the good voxels ((−1, −1) if none).
    """
    h, w, t = video_shape(color)
    col = check_buffer("color", color, (h, w, t, 3), dtype=np.float32)
    idx = np.ascontiguousarray(bins, dtype=np.int64)
    k = idx.size
    full = (h, w, t, 3)
    if n_planes not in (4, 6, 7) or (n_planes > 4 and not want_stats):
        raise ValueError(f"n_planes: expected 4, or 6 / 7 with want_stats, got {n_planes}")
    planes = np.empty((k, n_planes, h, w), np.float32)
    flags = np.zeros((h, 4), np.int64)
    if want_stats:
        if stats is None:
            raise DbenchInputError(f"stats: missing; expected SampleStats with arrays of shape "
                                   f"{full}")
        arrs = [check_buffer(name, np.broadcast_to(a, full) if np.ndim(a) == 0 else a, full,
                             dtype=np.float64)
                for name, a in (("stats.mean", stats.mean), ("stats.var_mean", stats.var_mean),
                                ("stats.n", stats.n), ("stats.m3", stats.m3))]
        theta = np.empty((k, 3, h, w), np.float64)
        vout = np.empty((k, 3, h, w), np.float64)
        bad = np.empty((k, h, w), np.bool_)
        nint = np.empty((k, 3, h, w) if want_nint else (1, 3, 1, 1), np.int32)
    else:
        arrs = [np.zeros((1, 1, 1, 3))] * 4
        theta = vout = np.zeros((1, 3, 1, 1))
        bad = np.zeros((1, 1, 1), np.bool_)
        nint = np.zeros((1, 3, 1, 1), np.int32)
    # read-only inputs (methods/kernels/arrays.py): one specialisation whoever calls
    _prepare_video(kernel_input(col), *map(kernel_input, arrs), idx, bool(want_stats),
                   bool(want_nint), planes, theta, vout,
                   nint, bad, flags)
    if not want_stats:
        return planes, None, (-1, -1)
    if flags[:, 0].any():
        raise DbenchInputError("stats.var_mean: negative values; expected Var(θ̂) ≥ 0")
    if flags[:, 1].any():
        raise DbenchInputError("stats.n: negative sample counts")
    lo, hi = int(flags[:, 2].min()), int(flags[:, 3].max())
    vs = VideoStats(theta, vout, nint if want_nint else None, bad, idx,
                    str(getattr(stats, "transform", "unknown")),
                    float(getattr(stats, "lam", float("nan"))))
    return planes, vs, ((lo, hi) if hi >= 0 else (-1, -1))


def bins_in_play(keep: np.ndarray, radius_t: int) -> np.ndarray:
    """(T,) bool: the kept bins dilated by r_t (the bins the kept ones see as neighbours)."""
    keep = np.asarray(keep, bool)
    out = keep.copy()
    for k in range(1, min(int(radius_t), len(keep)) + 1):
        out[k:] |= keep[:-k]
        out[:-k] |= keep[k:]
    return out
