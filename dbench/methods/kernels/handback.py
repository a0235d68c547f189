"""What the ProDen gate hands back [dbench]: the spec's gate (docs/methods/statistical.md §12) returns a
fraction 1 − α_gate of the whole residual r = hdr − den to each pixel whose neighbourhood
fails the t-test, which is exact on average but hands back the pixel's noise with it. The
Wiener hand-back splits r into its local mean and the rest:

    low  = G*r / G*1                       (G the gate's own Gaussian, zero padding; the
                                            local bias the t-test has just measured)
    high = r − low
    s²   = max(B(high²) − B(var), 0)        (B: mean over the 11×11 window inside the image;
                                            the energy of high beyond that of the noise)
    λ    = s² / (s² + var)                  (a Wiener gain per value; 1 where both are 0)
    out  = hdr + α_gate (den − hdr) − (α − α_gate)(1 − λ) · high
         = den + (1 − α_gate) (low + λ · high)           for α = 1 (the default)

Where the method is right, high is the noisy input's noise: its window energy is the noise's,
λ ≈ 0, and only the local mean goes back (its noise averaged over the window). Where the
method errs at the pixel scale (a blurred edge, a lost highlight) the energy exceeds the
noise's and λ → 1: the spec's hand-back. λ weighs that excess against the pixel's own
variance, not a floored one: with the window's mean variance instead (the gate's floor),
pixels beside bright, noisy ones (a lamp's reflection) lost the hand-back of a method's sharp
errors, and `statistical+gate` on `mirrors` at 4 spp rose from 0.074 to 0.120 relMSE (one
seed). The first form is the spec's output less the part of
the noise the spec hands back: with λ = 1 it is the spec's gate, and with α = 0 the input, as
in the spec (α_gate = α Φ(−k(t − t0)) ≤ α). As the variance vanishes σ_b → 0
(G*r → r) and λ → 1 wherever r ≠ 0, so the gate still converges to the input. var is the
linear variance of the mean (:func:`dbench.methods.kernels.variance_floor.linear_variance`).

Its effect on the verdicts is measured in results/learned.md.

* :func:`wiener_handback` — the readable form (SciPy box filters, float64), used by
  :func:`dbench.methods.kernels.gate_reference.proden_gate`.
* :func:`wiener_row` — one output row of the compiled form, fused into the gate's band pass
  (:mod:`dbench.methods.kernels.gate`); equal to the reference within 1e-6 (tests).

A kernel imports no method and nothing of the harness.
"""
from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit

from .variance_floor import window_mean

#: Radius of the window of the energies: the gate's 11×11 footprint.
WIENER_RADIUS = 5
#: The hand-back rules: the spec's (the whole residual) and the Wiener split above.
HANDBACKS = ("pixel", "wiener")


def wiener_handback(hdr: Any, den: Any, a_gate: Any, low: Any, var: Any, alpha: float = 1.0,
                    radius: int = WIENER_RADIUS) -> np.ndarray:
    """out = hdr + α_gate (den − hdr) − (α − α_gate)(1 − λ)·high of the module docstring.

    Args:
        hdr, den: (H, W, C) noisy input and method output; a_gate: (H, W, C) the gate's α_gate;
        low: (H, W, C) G*(hdr − den) / G*1; var: (H, W, C) linear variance of the mean;
        alpha: the gate's α.

    Returns:
        (H, W, C) float64.
    """
    hdr, den = np.asarray(hdr, np.float64), np.asarray(den, np.float64)
    var = np.asarray(var, np.float64)
    high = (hdr - den) - low
    noise = window_mean(var, radius)
    excess = np.maximum(window_mean(high * high, radius) - noise, 0.0)
    total = excess + var
    with np.errstate(invalid="ignore", divide="ignore"):
        lam = np.where(total > 0, excess / np.where(total > 0, total, 1.0), 1.0)
    a_gate = np.asarray(a_gate, np.float64)
    return hdr + a_gate * (den - hdr) - (alpha - a_gate) * (1.0 - lam) * high


@njit(inline="always")
def wiener_row(spec_row, c_row, lin_row, high_sums, noise_mean, rows_in, inv_cols, prefix,
               out_row):  # pragma: no cover - compiled
    """One output row of :func:`wiener_handback`, out = spec − (1 − λ)·c, from (W·C,)
    interleaved rows (C = 3): the spec's output hdr + α_gate (den − hdr), c = (α − α_gate) high,
    the linear variance of the row, the window's column sums of high² over its ``rows_in`` rows
    inside the image, and the window means of the variance (B(var):
    variance_floor.window_mean_row). B(high²) comes from differences of running sums of the
    column sums padded with R zero columns either side (``prefix``: ≥ (W + 2R + 1)·C scratch,
    R = WIENER_RADIUS); ``inv_cols`` (W·C,) is 1 / the window's columns inside the image (the
    column sums are left as they are: they slide on to the next row)."""
    wc = out_row.shape[0]
    c = 3
    pad = WIENER_RADIUS * c
    span = 2 * pad + c
    inv_rows = 1.0 / rows_in
    for k in range(pad + c):
        prefix[k] = 0.0
    for i in range(wc):
        prefix[pad + c + i] = prefix[pad + i] + high_sums[i]
    for k in range(wc + pad + c, wc + 2 * pad + c):
        prefix[k] = prefix[k - c]
    for i in range(wc):
        excess = max((prefix[i + span] - prefix[i]) * (inv_rows * inv_cols[i]) - noise_mean[i],
                     0.0)
        total = excess + lin_row[i]
        lam = excess / total if total > 0.0 else 1.0
        out_row[i] = spec_row[i] - (1.0 - lam) * c_row[i]


__all__ = ["HANDBACKS", "WIENER_RADIUS", "wiener_handback", "wiener_row"]
