"""``statistical``: the Welch-test statistical denoiser (spec/statistical.md, Sakai et al. 2024).

The joint bilateral filter of ``jbf`` (shared code) gives the base weights ρ; a neighbour is a
member only if every colour channel passes Welch's test on the skew-corrected means θ̂ of the
transformed samples (Frame.stats); the normalised weights are applied to the linear noisy
colour (Frame.color). See :mod:`dbench.methods.statistical.core` for the maths and the policies
(non-finite pixels, zero variance, out-of-image neighbours).

Parameters (``get("statistical", **params)``; every value is checked, a bad one raises
DbenchInputError naming it; the resolved values land in ``last_settings`` after each call):
    radius (20), alpha (0.005: γ_t = t_{1−α/2, n_i+n_j−2}), gamma (None; wins over alpha:
    γ_t² = 1/(2γ) − 1), sigma ((10, 10, 0.02 ×3, 0.1 ×3)), sigma_convention ("variance" | "sd"),
    window ("square" | "disk"), backend ("auto": PyTorch on CUDA, else Numba | "numba" |
    "torch" | "reference"), hit_mask (True), membership (True; False = plain JBF, the
    ablation), gate (False; True applies the ProDen t-test gate of spec §12 on top),
    gate_alpha (1.0).
The sample transform (identity / Box-Cox / Yeo-Johnson and λ) is a property of the statistics
(SampleStats.transform, .lam) and is recorded, not chosen here.

Example:
    >>> import numpy as np
    >>> from dbench.data import Frame, SampleStats
    >>> from dbench.registry import get
    >>> h = w = 8; ones = np.ones((h, w, 3), np.float32)
    >>> st = SampleStats(n=np.full((h, w, 3), 16.0), mean=np.ones((h, w, 3)),
    ...                  var_mean=np.zeros((h, w, 3)), m3=np.zeros((h, w, 3)), transform="identity")
    >>> f = Frame(color=ones, albedo=ones, normal=ones, depth=ones[..., :1], stats=st)
    >>> m = get("statistical", radius=2, backend="numba")
    >>> bool(np.allclose(m.denoise(f), 1.0)), m.last_settings["nu"]
    (True, 30)
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from ...errors import DbenchInputError
from ...registry import Denoiser, register
from ..jbf.core import (SEED_SIGMA, SIGMA_CONVENTIONS, WINDOWS, check_choice, check_radius,
                        check_sigma, make_guide)
from .core import (BACKENDS, DEFAULT_ALPHA, StatPlanes, Threshold, _check_alpha, _g2_from_gamma,
                   gamma_from_gamma_t, gamma_t_from_gamma, membership, proden_gate,
                   proden_gate_factor, resolve_backend, resolve_threshold, stat_planes,
                   statistical_fast, statistical_filter, statistical_reference, student_gamma_t,
                   welch_pass, welch_t, welch_t_from_weight, welch_weight)

__all__ = ["Statistical", "StatPlanes", "Threshold", "gamma_from_gamma_t", "gamma_t_from_gamma",
           "linear_variance", "membership", "proden_gate", "proden_gate_factor",
           "resolve_threshold", "stat_planes", "statistical_fast", "statistical_filter",
           "statistical_reference", "student_gamma_t", "welch_pass", "welch_t",
           "welch_t_from_weight", "welch_weight"]


def linear_variance(stats: Any, color: np.ndarray) -> np.ndarray:
    """Variance of the linear mean for the ProDen gate, (H, W, 3) float64.

    Exact for the identity transform; otherwise the delta method Var(x̄) ≈ Var(ȳ)/g'(x̄)² with
    g'(x) = x^(λ−1) (Box-Cox) or (1 + x)^(λ−1) (Yeo-Johnson, x ≥ 0), an approximation
    [dbench]; 0 where g' is infinite or the colour is not finite.
    """
    var = np.asarray(stats.var_mean, np.float64)
    transform = getattr(stats, "transform", "identity")
    if transform == "identity":
        return np.where(np.isfinite(var), var, 0.0)
    lam = float(stats.lam)
    x = np.where(np.isfinite(color), np.maximum(np.asarray(color, np.float64), 0.0), 0.0)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        deriv = x ** (lam - 1.0) if transform == "box-cox" else (1.0 + x) ** (lam - 1.0)
        out = var / (deriv * deriv)
    return np.where(np.isfinite(out), out, 0.0)


@register("statistical")
class Statistical(Denoiser):
    """Welch-test statistical denoiser with the JBF as base filter (spec/statistical.md)."""

    kinds = {"steady"}
    needs = {"color", "albedo", "normal", "depth", "stats"}
    defaults: dict[str, Any] = dict(
        radius=20, alpha=DEFAULT_ALPHA, gamma=None, sigma=SEED_SIGMA,
        sigma_convention="variance", window="square", backend="auto", hit_mask=True,
        membership=True, gate=False, gate_alpha=1.0)

    def __init__(self, **params: Any) -> None:
        super().__init__(**params)
        p = self.params
        check_radius(p["radius"])
        if p["gamma"] is None:
            _check_alpha(p["alpha"])
        else:
            _g2_from_gamma(p["gamma"])
        check_sigma(p["sigma"])
        check_choice("sigma_convention", p["sigma_convention"], SIGMA_CONVENTIONS)
        check_choice("window", p["window"], WINDOWS)
        check_choice("backend", p["backend"], BACKENDS)
        for name in ("hit_mask", "membership", "gate"):
            if not isinstance(p[name], (bool, np.bool_)):
                raise DbenchInputError(f"{name}: expected True or False, got {p[name]!r}")
        try:
            ga = float(p["gate_alpha"])
        except (TypeError, ValueError):
            ga = math.nan
        if not (0.0 <= ga <= 1.0):
            raise DbenchInputError(f"gate_alpha: expected a number in [0, 1], got {p['gate_alpha']!r}")
        #: Resolved settings of the last call: γ_t, ν, transform, λ, backend, base filter.
        self.last_settings: dict[str, Any] = {}

    def denoise(self, data: Any) -> np.ndarray:
        if getattr(data, "kind", None) != "steady":
            raise DbenchInputError(f"statistical: expected a steady Frame, got "
                                   f"{getattr(data, 'kind', type(data).__name__)} data")
        p = self.params
        out, info = statistical_filter(
            data.color, data.stats, data.albedo, data.normal, data.depth,
            radius=p["radius"], alpha=p["alpha"], gamma=p["gamma"], sigma=p["sigma"],
            sigma_convention=p["sigma_convention"], window=p["window"], hit_mask=p["hit_mask"],
            membership_on=p["membership"], backend=p["backend"], return_info=True)
        if p["gate"]:
            var = linear_variance(data.stats, data.color)
            hdr = np.where(np.isfinite(data.color), data.color, out)
            out = proden_gate(hdr, out, var, alpha=float(p["gate_alpha"])).astype(np.float32)
        info.update(gate=bool(p["gate"]), gate_alpha=float(p["gate_alpha"]))
        self.last_settings = info
        return out
