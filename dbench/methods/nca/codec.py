"""State encoding of the NCA (docs/methods/nca.md §1, §3 colour scaling), NumPy only (no torch import),
shared by training and ONNX Runtime inference.

Colour encodings (an open choice of docs/methods/nca.md §7, recorded in the model's metadata):

* ``"log1p"`` (docs/methods/nca.md §3): RGB = log1p(color); output max(expm1(RGB), 0).
* ``"log1p_demodulated"``: RGB = log1p(color / a_eff) with a_eff = albedo where it exceeds 1e-3
  (per channel) and 1 elsewhere (docs/methods/svgf.md §2); output max(expm1(RGB), 0) · a_eff. The
  automaton then diffuses illumination, not texture.
"""
from __future__ import annotations

import numpy as np

from ..guards import log_demodulated  # noqa: F401 (part of this module's API)
from ..kernels.learned_input import ALBEDO_EPS  # a_eff's threshold, one source

ENCODINGS = ("log1p", "log1p_demodulated")


def sanitize(x: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Non-finite values -> 0 (treated as missing), then clipped to [lo, hi]."""
    return np.clip(np.where(np.isfinite(x), x, 0.0), lo, hi).astype(np.float32)


def effective_albedo(albedo: np.ndarray) -> np.ndarray:
    """a_eff = albedo where albedo > 1e-3 (per channel), else 1 (after sanitising)."""
    a = sanitize(albedo, 0.0, 1.0)
    return np.where(a > ALBEDO_EPS, a, 1.0).astype(np.float32)


def encode(color: np.ndarray, normal: np.ndarray, albedo: np.ndarray,
           encoding: str = "log1p", exposure: float = 1.0) -> np.ndarray:
    """(H, W, 3) buffers -> (9, H, W) initial state: encoded colour, normal, albedo.

    ``exposure`` multiplies the colour before the encoding (auto-exposure,
    :func:`dbench.methods.hdr_input.autoexposure`); :func:`decode` divides by it again.

    Non-finite or negative colour is 0; non-finite normal/albedo are 0; normal clipped to
    [-1, 1] and albedo to [0, 1]. Huge finite colour stays finite: the demodulated quotient is
    recomputed in float64 where float32 overflows (:func:`log_demodulated`, log1p ≤ ≈ 95).
    """
    if encoding not in ENCODINGS:
        raise ValueError(f"encoding: expected one of {ENCODINGS}, got {encoding!r}")
    c = sanitize(color, 0.0, np.inf)
    if exposure != 1.0:
        c = sanitize(c.astype(np.float64) * exposure, 0.0, np.finfo(np.float32).max)
    if encoding == "log1p_demodulated":
        rgb = log_demodulated(c, effective_albedo(albedo))
    else:
        rgb = np.log1p(c)
    s = np.concatenate([rgb, sanitize(normal, -1.0, 1.0), sanitize(albedo, 0.0, 1.0)], axis=-1)
    return np.ascontiguousarray(s.transpose(2, 0, 1), dtype=np.float32)


def decode(state_rgb: np.ndarray, albedo: np.ndarray | None = None,
           encoding: str = "log1p", exposure: float = 1.0) -> np.ndarray:
    """(3, H, W) final RGB state -> (H, W, 3) linear radiance (remodulated when the encoding is
    demodulated; ``albedo`` (H, W, 3) is then required), divided by ``exposure``."""
    x = np.minimum(state_rgb.transpose(1, 2, 0), 80.0)
    out = np.maximum(np.expm1(np.where(np.isfinite(x), x, 0.0)), 0.0)
    if encoding == "log1p_demodulated":
        out = out * effective_albedo(albedo)
    if exposure != 1.0:
        out = out / exposure
    return np.ascontiguousarray(out, dtype=np.float32)
