"""ProDen's t-test gate, the readable reference (docs/methods/statistical.md §12): its defaults,
the Gaussian window and :func:`proden_gate` (SciPy 2-D correlation, float64), which the compiled
passes of :mod:`dbench.methods.kernels.gate` equal within 1e-6 · |den − hdr|
(tests/methods/test_gate.py). Shapes: ``hdr``, ``den``, ``var`` (H, W, 3).

Example:
    >>> import numpy as np
    >>> hdr = np.ones((8, 8, 3)); den = np.full((8, 8, 3), 2.0)
    >>> float(proden_gate(hdr, den, np.zeros_like(hdr))[0, 0, 0])   # no variance: keep the input
    1.0
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..checks import check_choice
from .handback import HANDBACKS, wiener_handback
from .variance_floor import floored_variance

#: Defaults of docs/methods/statistical.md §12.
GATE_K = 2.0
GATE_T0 = 4.2
GATE_TAPS = 11


def proden_gate_factor(t: Any, k: float = GATE_K, t0: float = GATE_T0) -> np.ndarray:
    """g(t) = ½(1 − erf(k(t − t0)/√2)) = Φ(−k(t − t0)): 0.5 at 4.2, 0.97725 at 3.2 (docs/methods/statistical.md §12)."""
    from scipy.special import erf

    return 0.5 * (1.0 - erf(k * (np.asarray(t, np.float64) - t0) / math.sqrt(2.0)))


def gate_sigma(var: np.ndarray) -> float:
    """σ_b = max(100 · sqrt(clamp(mean(var), 0, 1)), 1e-3) (docs/methods/statistical.md §12)."""
    return sigma_from_mean(float(np.mean(var)))


def sigma_from_mean(mean_var: float) -> float:
    """σ_b of :func:`gate_sigma` from the mean variance itself."""
    return max(100.0 * math.sqrt(min(max(mean_var, 0.0), 1.0)), 1e-3)


def gate_taps(sigma: float, taps: int = GATE_TAPS) -> np.ndarray:
    """The normalised 1-D Gaussian g (taps,) whose outer product is the spec's 2-D kernel."""
    ax = np.arange(-(taps // 2), taps // 2 + 1, dtype=np.float64)
    g = np.exp(-0.5 * (ax / sigma) ** 2)
    return g / g.sum()


def proden_gate(hdr: Any, den: Any, var: Any, *, alpha: float = 1.0, k: float = GATE_K,
                t0: float = GATE_T0, pool_radius: int = 0, handback: str = "pixel"
                ) -> np.ndarray:
    """ProDen t-test gate (docs/methods/statistical.md §12, without the ``proden_exact`` terms), the readable form.

    Args:
        hdr: (H, W, 3) noisy image; den: (H, W, 3) denoised image; var: (H, W, 3) per-pixel
            variance of the mean in linear space.

    Returns:
        (H, W, 3) float64 out = hdr + α_gate (den − hdr), α_gate = α·g(t) per channel with
        t = |G*(hdr + α(den − hdr)) − G*hdr| / (sqrt(G²*var) + 1e-6), G an 11×11 Gaussian with
        σ_b = max(100·sqrt(clamp(mean(var), 0, 1)), 1e-3), zero-padded borders; with
        ``pool_radius`` r > 0, the t-test's var is :func:`floored_variance` (var, r) [dbench]
        (σ_b still from the mean of var); with ``handback="wiener"`` [dbench] the residual
        handed back is split (:func:`~dbench.methods.kernels.handback.wiener_handback`, with
        the unfloored var).
    """
    from scipy.ndimage import correlate

    hdr = np.asarray(hdr, np.float64)
    den = np.asarray(den, np.float64)
    var = raw_var = np.asarray(var, np.float64)
    check_choice("handback", handback, HANDBACKS)
    g1 = gate_taps(gate_sigma(var))  # σ_b from the variance itself, floored or not
    if pool_radius:
        var = floored_variance(var, pool_radius)
    kern = np.outer(g1, g1)
    kern /= kern.sum()

    def blur(img, kk):
        return np.stack([correlate(img[..., c], kk, mode="constant") for c in range(img.shape[-1])],
                        axis=-1)

    mixed = hdr + alpha * (den - hdr)
    t = np.abs(blur(mixed, kern) - blur(hdr, kern)) / (np.sqrt(blur(var, kern * kern)) + 1e-6)
    a_gate = alpha * proden_gate_factor(t, k, t0)
    if handback == "pixel":
        return hdr + a_gate * (den - hdr)
    low = blur(hdr - den, kern) / blur(np.ones_like(hdr[..., :1]), kern)
    return wiener_handback(hdr, den, a_gate, low, raw_var, alpha)


__all__ = ["GATE_K", "GATE_T0", "GATE_TAPS", "gate_sigma", "gate_taps", "proden_gate",
           "proden_gate_factor", "sigma_from_mean"]
