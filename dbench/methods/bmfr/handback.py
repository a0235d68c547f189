"""BMFR's residual hand-back [dbench] (``handback="signed"``, the default, or ``"wiener"``;
docs/temporal.md §9, §17): the block fit y of the accumulated illumination z gets back the part
of z − y that is not noise (:mod:`dbench.methods.kernels.residual_handback`; ``"signed"`` also
weighs each pixel's residual below the fit against its own variance), before the second
accumulation.

The variance it weighs that residual against is the variance of z, per channel: the first
accumulation also accumulates z² with the same α, and the sum of its squared blend weights
S = Σ w² (S' = α² + (1 − α)² S←, 1 on a reset: 1/N for a running mean, α/(2 − α) in the EMA
limit), so

    var(z) = S · var_sample,   var_sample = max(E[z²] − E[z]², 0)

and, where the history holds fewer than 4 effective samples (1/S < 4), var_sample is this
frame's 7×7 spatial variance of the samples instead (as SVGF's §3 does below 4 frames: the
temporal moments of 1–3 samples are close to 0 and would hand the whole noisy z back).
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from ..kernels.residual_handback import (HANDBACK_RADIUS, pixel_window_variance,
                                         residual_handback_fast,
                                         residual_handback_reference, window_variance_reference)

#: The rules: hand back nothing (the BMFR paper's output), the Wiener split, or the Wiener split
#: with the signed rule below the fit (docs/temporal.md §17).
HANDBACKS = ("none", "wiener", "signed")
#: Below this many effective samples (1/S) the variance is the spatial one
#: (docs/methods/svgf.md §3).
MIN_TEMPORAL_SAMPLES = 4.0
#: History planes the hand-back adds: accumulated z² (3) and S (1).
EXTRA_PLANES = 4


def weight_sq(alpha: np.ndarray, weight_sq_hist: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """S = α² + (1 − α)² · S← where the history was reprojected (``ok``), α² elsewhere: α is
    the accumulation's (H, W) α as it returns it (1 on a reset, 0 where the sample was missing,
    so a missing sample keeps S←); float32 (H, W)."""
    prev = np.where(ok, weight_sq_hist, np.float32(0.0))
    return (alpha * alpha + (np.float32(1.0) - alpha) ** 2 * prev).astype(np.float32)


def illumination_variance(illum: np.ndarray, z_acc: np.ndarray, zz_acc: np.ndarray,
                          s: np.ndarray, fit: np.ndarray, present: np.ndarray) -> np.ndarray:
    """var(z) (3, H, W) float32 of the module docstring (readable form).

    Args:
        illum: (3, H, W) this frame's demodulated samples; z_acc, zz_acc: (3, H, W) accumulated
        z and z²; s: (H, W) Σ w²; fit: (H, W) bool, the pixels of the fit; present: (H, W)
        bool, this frame's sample is finite.
    """
    var = np.maximum(zz_acc - z_acc * z_acc, np.float32(0.0))
    short = fit & (s * np.float32(MIN_TEMPORAL_SAMPLES) > 1.0)
    if short.any():
        var = np.where(short, window_variance_reference(illum, fit & present), var)
    return (var * s).astype(np.float32)


def moments_reference(be: str, illum, z_acc, alpha, hist, n_hist, ok, present, fit,
                      alpha1, n_max, a1):
    """(z² accumulated (3, H, W), S (H, W), var(z) (3, H, W)) on a NumPy-facing backend:
    the accumulation of z² with the first accumulation's α, :func:`weight_sq` and
    :func:`illumination_variance`. ``hist``: the reprojected (4, H, W) planes [z², S]."""
    from ..temporal import accumulate_any

    zz_acc, _, _ = accumulate_any(be, illum * illum, hist[0:3], n_hist, ok, alpha1, n_max, a1,
                                  present)
    s = weight_sq(alpha, hist[3], ok)
    return zz_acc, s, illumination_variance(illum, z_acc, zz_acc, s, fit, present)


@njit(cache=True, parallel=True, fastmath=True)
def _moments_nb(illum, z_acc, alpha, hist, ok, present, fit, radius, min_samples,
                out_hist, var):  # pragma: no cover - compiled
    c_n, h, w = illum.shape
    for yy in prange(h):
        for x in range(w):
            a = alpha[yy, x]
            good = ok[yy, x]
            here = present[yy, x]
            s_prev = hist[3, yy, x] if good else np.float32(0.0)
            s = a * a + (np.float32(1.0) - a) * (np.float32(1.0) - a) * s_prev
            out_hist[3, yy, x] = s
            short = fit[yy, x] and s * min_samples > 1.0
            for c in range(c_n):
                # a missing sample has α = 0 and a reset history 1 − α = 0: both terms vanish,
                # but a NaN sample or a stale history value must not be multiplied by that 0
                sample = illum[c, yy, x] if here else np.float32(0.0)
                prev = hist[c, yy, x] if good else np.float32(0.0)
                zz = a * (sample * sample) + (np.float32(1.0) - a) * prev
                out_hist[c, yy, x] = zz
                zc = z_acc[c, yy, x]
                var[c, yy, x] = max(zz - zc * zc, np.float32(0.0)) * s
            if short:  # the spatial variance of this frame's samples (as SVGF's §3)
                for c in range(c_n):
                    var[c, yy, x] = np.float32(pixel_window_variance(
                        illum, c, yy, x, radius, fit, present)) * s


def moments_fast(illum, z_acc, alpha, hist, ok, present, fit, out_hist, var):
    """:func:`moments_reference` for the compiled backend in one pass: z² accumulated and S
    written into ``out_hist`` (4, H, W) (the history's staging planes), var(z) into ``var``
    (3, H, W) float32. Equal to the reference within float32 rounding (tests)."""
    _moments_nb(illum, z_acc, alpha, hist, ok, present, fit, HANDBACK_RADIUS,
                np.float32(MIN_TEMPORAL_SAMPLES), out_hist, var)
    return out_hist[0:3], out_hist[3], var


def handback(z_acc: np.ndarray, y_fit: np.ndarray, var: np.ndarray, fit: np.ndarray,
             fast: bool, out: np.ndarray | None = None, clamp: bool = False,
             signed: bool = True) -> np.ndarray:
    """y + low + λ·high on the fit pixels (3, H, W) float32, at least 0 everywhere with
    ``clamp``, λ of the signed rule with ``signed``: compiled when ``fast`` (into ``out`` when
    given), else the readable SciPy form."""
    if fast:
        return residual_handback_fast(z_acc, y_fit, var, fit, out=out, clamp=clamp,
                                      signed=signed)
    return residual_handback_reference(z_acc, y_fit, var, fit, clamp=clamp,
                                       signed=signed).astype(np.float32)


__all__ = ["EXTRA_PLANES", "HANDBACKS", "MIN_TEMPORAL_SAMPLES", "handback",
           "illumination_variance", "moments_fast", "moments_reference", "weight_sq"]
