"""The learned models' input in one compiled pass (docs/methods/autoencoder.md §1, docs/methods/nca.md §1):
:func:`encode_planar` equals the NumPy encoders of the autoencoder
(:func:`dbench.methods.autoencoder.codec.encode` followed by ``pad_to_multiple``) and of the NCA
(:func:`dbench.methods.nca.codec.encode`) within 1e-6 relative (tests).

At 1280x720 the NumPy chains took 120-145 ms per frame (sanitising the buffers, the
channels-last concatenation and its transpose, the edge padding): more than a third of the
autoencoder's network time and as much as three NCA steps. This pass writes the planar
(C, H', W') array directly, a row per thread.

Channels: the colour, sanitised (non-finite or negative → 0), scaled by ``exposure`` (clipped
to the float32 maximum), then log1p(colour / a_eff) with a_eff = albedo where it exceeds 1e-3
and 1 elsewhere (``demodulate``), or log1p(colour); then the features in the given order:
``normal`` (3, clipped to [-1, 1]), ``albedo`` (3, clipped to [0, 1]), ``depth`` (1, divided by
the frame's largest finite depth) and ``level`` (1, a constant). Non-finite features are 0.
Rows and columns beyond H, W (padding to ``multiple``) repeat the last row and column.

A kernel imports no method and nothing of the harness.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from numba import njit, prange

from .arrays import kernel_input

#: a_eff's threshold (docs/methods/svgf.md §2) and the feature planes, as in the codecs of both models
ALBEDO_EPS = 1e-3
FEATURE_CHANNELS = {"normal": 3, "albedo": 3, "depth": 1, "level": 1}

#: feature codes of the compiled pass, in ``codec.FEATURE_ORDER`` names
_CODES = {"normal": 0, "albedo": 1, "depth": 2, "level": 3}
_F32_MAX = float(np.finfo(np.float32).max)


@njit(inline="always")
def _clean(v, lo, hi):  # pragma: no cover - compiled
    """codec.sanitize of one value: non-finite → 0, then clipped to [lo, hi]."""
    if not np.isfinite(v):
        return np.float32(0.0)
    return np.float32(min(max(v, lo), hi))


@njit(parallel=True, cache=True)
def _encode_nb(color, albedo, normal, depth, depth_scale, level, codes, exposure, demodulate,
               out, a_eff_out):  # pragma: no cover - compiled
    h, w = color.shape[0], color.shape[1]
    hp, wp = out.shape[1], out.shape[2]
    for row in prange(hp):
        y = np.int64(row)
        sy = min(y, h - 1)  # replicate padding: the last row and column repeat
        for x in range(wp):
            sx = min(x, w - 1)
            for k in range(3):
                c = _clean(color[sy, sx, k], np.float32(0.0), np.float32(np.inf))
                if exposure != 1.0:
                    c = _clean(np.float64(c) * exposure, 0.0, _F32_MAX)
                a = _clean(albedo[sy, sx, k], np.float32(0.0), np.float32(1.0))
                a_eff = a if (a > ALBEDO_EPS and demodulate) else np.float32(1.0)
                q = np.float32(c / a_eff)
                if np.isinf(q):  # the float32 quotient overflows: log1p in float64
                    v = np.float32(math.log1p(np.float64(c) / np.float64(a_eff)))
                else:
                    v = np.float32(np.log1p(q))
                out[k, y, x] = v
                if y < h and x < w:
                    a_eff_out[y, x, k] = a_eff
            ch = 3
            for f in range(codes.shape[0]):
                code = codes[f]
                if code == 0:
                    for k in range(3):
                        out[ch + k, y, x] = _clean(normal[sy, sx, k], np.float32(-1.0),
                                                   np.float32(1.0))
                    ch += 3
                elif code == 1:
                    for k in range(3):
                        out[ch + k, y, x] = _clean(albedo[sy, sx, k], np.float32(0.0),
                                                   np.float32(1.0))
                    ch += 3
                elif code == 2:
                    d = depth[sy, sx, 0]
                    d = max(d, np.float32(0.0)) if np.isfinite(d) else np.float32(0.0)
                    out[ch, y, x] = d / depth_scale if depth_scale > 0 else d
                    ch += 1
                else:
                    out[ch, y, x] = level
                    ch += 1


@njit(parallel=True, cache=True)
def _depth_max_nb(depth):  # pragma: no cover - compiled
    h = depth.shape[0]
    rows = np.zeros(h, np.float32)
    for y in prange(h):
        m = np.float32(0.0)
        for x in range(depth.shape[1]):
            d = depth[y, x, 0]
            if np.isfinite(d) and d > m:
                m = d
        rows[y] = m
    return rows.max() if h else np.float32(0.0)


def encode_planar(color: np.ndarray, buffers: dict, features: Sequence[str],
                  exposure: float = 1.0, multiple: int = 1, demodulate: bool = True
                  ) -> tuple[np.ndarray, np.ndarray]:
    """(x (C, H', W') float32, H' and W' the next multiples of ``multiple``; a_eff (H, W, 3),
    ones without ``demodulate``). ``color`` (H, W, 3); ``buffers`` holds (H, W, 3) ``albedo``
    and, as ``features`` ask, (H, W, 3) ``normal``, (H, W, 1) ``depth`` and a number ``level``
    (shapes checked by the caller)."""
    # read-only inputs (arrays.py): one specialisation of each kernel whoever calls
    color = kernel_input(color, np.float32)
    h, w = color.shape[:2]
    unknown = [f for f in features if f not in _CODES]
    if unknown:
        raise ValueError(f"unknown feature {unknown[0]!r}; valid: {tuple(_CODES)}")
    albedo = kernel_input(buffers["albedo"], np.float32)
    normal = kernel_input(buffers["normal"] if "normal" in features
                          else np.zeros((1, 1, 3), np.float32), np.float32)
    depth = kernel_input(buffers["depth"] if "depth" in features
                         else np.zeros((1, 1, 1), np.float32), np.float32)
    codes = np.array([_CODES[f] for f in features], np.int64)
    depth_scale = np.float32(_depth_max_nb(depth)) if "depth" in features else np.float32(0.0)
    channels = 3 + sum(FEATURE_CHANNELS[f] for f in features)
    hp, wp = h + (-h) % multiple, w + (-w) % multiple
    out = np.empty((channels, hp, wp), np.float32)
    a_eff = np.empty((h, w, 3), np.float32)
    level = np.float32(buffers.get("level", 0.0)) if "level" in features else np.float32(0.0)
    _encode_nb(color, albedo, normal, depth, depth_scale, level, codes, float(exposure),
               bool(demodulate), out, a_eff)
    return out, a_eff


@njit(parallel=True, cache=True)
def _decode_nb(state, albedo, demodulate, exposure, out):  # pragma: no cover - compiled
    h, w = out.shape[0], out.shape[1]
    scale = np.float32(exposure)
    for row in prange(h):
        y = np.int64(row)
        for x in range(w):
            for k in range(3):
                v = min(state[k, y, x], np.float32(80.0))
                if not np.isfinite(v):
                    v = np.float32(0.0)
                e = max(np.float32(np.expm1(v)), np.float32(0.0))
                if demodulate:
                    a = _clean(albedo[y, x, k], np.float32(0.0), np.float32(1.0))
                    e = e * (a if a > ALBEDO_EPS else np.float32(1.0))
                if exposure != 1.0:
                    e = e / scale
                out[y, x, k] = e


def decode_planar(state_rgb: np.ndarray, albedo: np.ndarray | None, demodulate: bool,
                  exposure: float = 1.0) -> np.ndarray:
    """(3, H', W') log-space RGB → (H, W, 3) float32 linear radiance, H and W the albedo's
    (or the state's without ``demodulate``): max(expm1(min(x, 80)), 0) with non-finite x as 0,
    times a_eff when ``demodulate``, divided by ``exposure``. Equals
    :func:`dbench.methods.nca.codec.decode` within 1e-6 relative (tests)."""
    state_rgb = kernel_input(state_rgb, np.float32)
    if demodulate:
        albedo = kernel_input(albedo, np.float32)
        h, w = albedo.shape[:2]
    else:
        albedo = kernel_input(np.zeros((1, 1, 3), np.float32))
        h, w = state_rgb.shape[1:]
    out = np.empty((h, w, 3), np.float32)
    _decode_nb(state_rgb, albedo, bool(demodulate), float(exposure), out)
    return out
