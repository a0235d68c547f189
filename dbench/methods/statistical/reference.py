"""Welch-test statistical denoiser, readable NumPy reference (float64; docs/methods/statistical.md,
the "spec" of the section numbers): the pairwise test, the statistics as channel-first planes,
and the dense filter every fast path is tested against.

w_ij = ρ_ij m_ij v_j / Σ_k ρ_ik m_ik v_k, out_i = Σ_j w_ij L_j          (docs/methods/statistical.md §1, §8)

* ρ is the joint bilateral filter of docs/methods/jbf.md, built by
  :func:`dbench.methods.kernels.bilateral.guide.make_guide` and evaluated by the same code as the
  ``jbf`` method (:func:`~dbench.methods.kernels.bilateral.reference.reference_weights` here,
  the shared Numba kernel :func:`~dbench.methods.kernels.bilateral.numba2d.accumulate` or
  :func:`~dbench.methods.kernels.bilateral.torch_path.accumulate_torch` in the fast paths of
  :mod:`.fast`). Nothing is copied.
* m_ij = AND over the channels c of pass_c = (d² < γ_t² S) or (d == 0), with d = θ̂_i − θ̂_j and
  S = Var(θ̂_i) + Var(θ̂_j) of the transformed samples (docs/methods/statistical.md §5, §5.2, §6); m_ii = 1. The
  threshold γ_t is :func:`.params.resolve_threshold`'s (docs/methods/statistical.md §5.1).
* L is the linear noisy colour (Frame.color); v_j = 1 when L_j is finite (missing pixels get no
  weight, and their own output is the filtered value of their valid neighbours, or 0).
* A pixel whose θ̂, Var(θ̂) or n is not finite has no neighbours and is nobody's neighbour
  (docs/methods/statistical.md §5.2 "[dbench] fails unless it is the centre"); its output is its own colour.

Shapes: colour and statistics are (H, W, 3); the kernels use channel-first (3, H, W) planes.

Example:
    >>> welch_weight(0.0, 1.0).item(), welch_weight(1.0, 0.0).item()
    (0.5, 1.0)
    >>> welch_t(3.0, 4.0).item(), round(welch_t_from_weight(welch_weight(3.0, 4.0)).item(), 12)
    (1.5, 1.5)
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ...data import check_buffer
from ...errors import DbenchInputError
from ..kernels.bilateral.guide import Guide, color_planes
from ..kernels.bilateral.reference import reference_weights, shift_slices
from .params import G2_MAX, Threshold

__all__ = ["StatPlanes", "membership", "stat_planes", "statistical_reference", "welch_pass",
           "welch_t", "welch_t_from_weight", "welch_weight"]


# ---------------------------------------------------------------------------------------------
# The pairwise test (docs/methods/statistical.md §5)
# ---------------------------------------------------------------------------------------------

def welch_weight(d: Any, s: Any) -> np.ndarray:
    """Optimal symmetric pair weight w* = (2d² + S) / (2(d² + S)) (docs/methods/statistical.md §5), without NaN.

    d = 0 and S = 0 gives 0.5; S = 0 and d ≠ 0 gives 1; |d| = ∞ gives 1.
    """
    d = np.asarray(d, np.float64)
    s = np.asarray(s, np.float64)
    d2 = d * d
    num = 2.0 * d2 + s
    den = 2.0 * (d2 + s)
    with np.errstate(invalid="ignore", over="ignore"):
        w = np.divide(num, den, out=np.full(np.broadcast(d2, den).shape, 0.5), where=den > 0)
    return np.where(np.isinf(d2), 1.0, w)


def welch_t(d: Any, s: Any) -> np.ndarray:
    """Welch statistic t = |d| / sqrt(S); 0 when d = 0, ∞ when S = 0 and d ≠ 0."""
    d = np.abs(np.asarray(d, np.float64))
    s = np.asarray(s, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(s > 0, d / np.sqrt(np.where(s > 0, s, 1.0)), np.inf)
    return np.where(d == 0, 0.0, t)


def welch_t_from_weight(w: Any) -> np.ndarray:
    """t = sqrt(1/(2(1 − w*)) − 1) (docs/methods/statistical.md §5); w* = 1 gives ∞."""
    w = np.asarray(w, np.float64)
    with np.errstate(divide="ignore"):
        x = np.where(w < 1, 1.0 / (2.0 * (1.0 - np.minimum(w, 1.0))) - 1.0, np.inf)
    return np.sqrt(np.maximum(x, 0.0))


def welch_pass(d: Any, s: Any, g2: Any) -> np.ndarray:
    """Per-channel predicate pass = (d² < γ_t² S) or (d == 0) (docs/methods/statistical.md §5.2), float64, no NaN."""
    d = np.asarray(d, np.float64)
    return (d * d < np.asarray(g2, np.float64) * np.asarray(s, np.float64)) | (d == 0.0)


def membership(theta_i: Any, var_i: Any, theta_j: Any, var_j: Any, gamma_t: float,
               axis: int = -1) -> np.ndarray:
    """m_ij: every channel (along ``axis``) must pass the Welch test at threshold γ_t (docs/methods/statistical.md §6)."""
    g2 = min(float(gamma_t) ** 2, G2_MAX)
    d = np.asarray(theta_i, np.float64) - np.asarray(theta_j, np.float64)
    s = np.asarray(var_i, np.float64) + np.asarray(var_j, np.float64)
    return np.all(welch_pass(d, s, g2), axis=axis)


# ---------------------------------------------------------------------------------------------
# Inputs: the statistics as channel-first planes
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class StatPlanes:
    """Channel-first statistics for the kernels (docs/methods/statistical.md §2, §4).

    theta: (3, H, W) float64 θ̂; var: (3, H, W) float64 Var(θ̂); nint: (3, H, W) int32 n;
    bad: (H, W) bool pixels with non-finite statistics (values there are zeroed);
    transform, lam: as recorded in the SampleStats.
    """

    theta: np.ndarray
    var: np.ndarray
    nint: np.ndarray
    bad: np.ndarray
    transform: str
    lam: float


def stat_planes(stats: Any, shape: tuple[int, int] | None = None) -> StatPlanes:
    """Check a :class:`~dbench.data.SampleStats` (or any object with n, var_mean, theta) and
    return channel-first planes.

    Raises:
        DbenchInputError: wrong shape, negative variance or negative sample count.
    """
    if stats is None:
        raise DbenchInputError("stats: missing; expected SampleStats with arrays of shape "
                               f"{'(H, W, 3)' if shape is None else (*shape, 3)}")
    h, w = shape if shape is not None else np.asarray(stats.mean).shape[:2]
    theta = check_buffer("stats.theta", stats.theta, (h, w, 3), dtype=np.float64)
    var = check_buffer("stats.var_mean", stats.var_mean, (h, w, 3), dtype=np.float64)
    n = check_buffer("stats.n", np.broadcast_to(stats.n, (h, w, 3)), (h, w, 3), dtype=np.float64)
    with np.errstate(invalid="ignore"):
        if np.any(var < 0):
            raise DbenchInputError("stats.var_mean: negative values; expected Var(θ̂) ≥ 0")
        if np.any(n < 0):
            raise DbenchInputError("stats.n: negative sample counts")
    bad = ~(np.all(np.isfinite(theta), -1) & np.all(np.isfinite(var), -1)
            & np.all(np.isfinite(n), -1))
    if bad.any():
        theta = np.where(bad[..., None], 0.0, theta)
        var = np.where(bad[..., None], 0.0, var)
        n = np.where(bad[..., None], 0.0, n)
    nint = np.minimum(np.rint(n), 2 ** 30).astype(np.int32)
    return StatPlanes(np.ascontiguousarray(np.moveaxis(theta, -1, 0)),
                      np.ascontiguousarray(np.moveaxis(var, -1, 0)),
                      np.ascontiguousarray(np.moveaxis(nint, -1, 0)), bad,
                      str(getattr(stats, "transform", "unknown")),
                      float(getattr(stats, "lam", float("nan"))))


# ---------------------------------------------------------------------------------------------
# Reference implementation (dense NumPy, float64)
# ---------------------------------------------------------------------------------------------

def statistical_reference(color: Any, sp: StatPlanes, guide: Guide, threshold: Threshold, *,
                          membership_on: bool = True, return_weights: bool = False):
    """Readable statistical denoiser: loop over offsets, whole shifted images (docs/methods/statistical.md §8).

    For each offset o: ρ from
    :func:`~dbench.methods.kernels.bilateral.reference.reference_weights` (the JBF's own code),
    m from the per-channel Welch predicate, v from the colour's finiteness.

    Returns:
        (H, W, 3) float64; with ``return_weights`` also (O, H, W) normalised weights and the
        (O, H, W) bool memberships (True where the pair is in the image and passes).
    """
    guide = guide.isolate(sp.bad)
    h, w = guide.shape
    col, valid = color_planes(color, (h, w))
    theta = np.moveaxis(sp.theta, 0, -1)
    var = np.moveaxis(sp.var, 0, -1)
    nint = np.moveaxis(sp.nint, 0, -1).astype(np.int64)
    num = np.zeros((h, w, 3))
    den = np.zeros((h, w))
    stack, members = [], []
    for k in range(len(guide.dy)):
        dy, dx = int(guide.dy[k]), int(guide.dx[k])
        (ys, xs), (yn, xn) = shift_slices(dy, dx, h, w)
        rho = reference_weights(guide, k)
        m = np.zeros((h, w), bool)
        if dy == 0 and dx == 0:
            m[:] = True                                        # the centre always counts
        elif ys.start < ys.stop and xs.start < xs.stop and membership_on:
            d = theta[ys, xs] - theta[yn, xn]
            s = var[ys, xs] + var[yn, xn]
            g2 = threshold.g2_for(nint[ys, xs] + nint[yn, xn] - 2)
            m[ys, xs] = np.all(welch_pass(d, s, g2), axis=-1)
        elif ys.start < ys.stop and xs.start < xs.stop:
            m[ys, xs] = True
        wk = rho * m
        wk[ys, xs] *= valid[yn, xn]
        num[ys, xs] += wk[ys, xs, None] * col[yn, xn]
        den += wk
        if return_weights:
            stack.append(wk)
            members.append(m)
    out = np.divide(num, den[..., None], out=np.zeros_like(num), where=den[..., None] > 0)
    if return_weights:
        ws = np.stack(stack)
        return out, np.divide(ws, den, out=np.zeros_like(ws), where=den > 0), np.stack(members)
    return out
