"""Input encoding of the autoencoder (docs/methods/autoencoder.md §1) and the architecture constants,
NumPy only (no torch import), shared by training and ONNX Runtime inference."""
from __future__ import annotations

from typing import Sequence

import numpy as np

from ..guards import log_demodulated  # noqa: F401 (part of this module's API)
# a_eff's threshold and the feature planes, shared with the compiled encoder
from ..kernels.learned_input import ALBEDO_EPS, FEATURE_CHANNELS

#: Architecture constants shared with the ONNX builder (docs/methods/autoencoder.md §2).
LEVELS = 5
SLOPE = 0.1
#: Spatial sizes must be multiples of this (five 2x2 poolings).
MULTIPLE = 2 ** LEVELS
FEATURE_ORDER = ("normal", "albedo", "depth", "level")
#: FEATURE_CHANNELS["level"]: the input's noise level log2(spp)/10 as a constant plane
#: (:func:`dbench.methods.hdr_input.noise_level`), so one network serves every sample count.


def in_channels_for(features: Sequence[str]) -> int:
    """Input channels: 3 (demodulated log colour) plus the listed feature buffers."""
    return 3 + sum(FEATURE_CHANNELS[f] for f in features)


def effective_albedo(albedo: np.ndarray) -> np.ndarray:
    """a_eff = albedo where albedo > 1e-3 (per channel), else 1; (..., 3) -> (..., 3)."""
    return np.where(albedo > ALBEDO_EPS, albedo, 1.0).astype(np.float32)


def sanitize(name: str, x: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Non-finite values -> 0 (treated as missing), then clipped to [lo, hi]."""
    x = np.where(np.isfinite(x), x, 0.0)
    return np.clip(x, lo, hi).astype(np.float32)




def encode(color: np.ndarray, buffers: dict[str, np.ndarray],
           features: Sequence[str], exposure: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Network input (C, H, W) and a_eff (H, W, 3) from (H, W, 3) colour and feature buffers
    (``buffers["level"]`` a number when ``level`` is a feature). ``exposure`` multiplies the
    colour first (auto-exposure); :func:`decode` divides by it again.

    Non-finite or negative colour is treated as missing (0); non-finite features are 0.
    Huge finite colour (up to the float32 maximum) encodes to a finite log value (at most ≈ 95,
    see :func:`log_demodulated`); the decoder caps the network output at expm1(80).
    """
    color = sanitize("color", color, 0.0, np.inf)
    if exposure != 1.0:
        color = sanitize("color", color.astype(np.float64) * exposure, 0.0,
                         np.finfo(np.float32).max)
    albedo = sanitize("albedo", buffers["albedo"], 0.0, 1.0)
    a_eff = effective_albedo(albedo)
    chans = [log_demodulated(color, a_eff)]
    for f in features:
        if f == "normal":
            chans.append(sanitize("normal", buffers["normal"], -1.0, 1.0))
        elif f == "albedo":
            chans.append(albedo)
        elif f == "depth":
            d = np.where(np.isfinite(buffers["depth"]), buffers["depth"], 0.0)
            d = np.maximum(d, 0.0)
            dmax = float(d.max()) if d.size else 0.0
            chans.append((d / dmax if dmax > 0 else d).astype(np.float32))
        elif f == "level":
            chans.append(np.full(color.shape[:2] + (1,), float(buffers["level"]), np.float32))
        else:
            raise ValueError(f"unknown feature {f!r}; valid: {FEATURE_ORDER}")
    x = np.concatenate(chans, axis=-1).transpose(2, 0, 1)
    return np.ascontiguousarray(x, dtype=np.float32), a_eff


def decode(y: np.ndarray, a_eff: np.ndarray, exposure: float = 1.0) -> np.ndarray:
    """(3, H, W) network output -> (H, W, 3) linear radiance:
    max(expm1(y), 0) * a_eff / exposure."""
    lin = np.maximum(np.expm1(np.minimum(y.transpose(1, 2, 0), 80.0)), 0.0)
    out = lin * a_eff if exposure == 1.0 else lin * a_eff / exposure
    return np.ascontiguousarray(out, dtype=np.float32)


def pad_to_multiple(x: np.ndarray, multiple: int = MULTIPLE) -> tuple[np.ndarray, int, int]:
    """Replicate-pad a (C, H, W) array at the bottom/right to multiples of ``multiple``."""
    _, h, w = x.shape
    ph, pw = (-h) % multiple, (-w) % multiple
    if ph or pw:
        x = np.pad(x, ((0, 0), (0, ph), (0, pw)), mode="edge")
    return np.ascontiguousarray(x), h, w
