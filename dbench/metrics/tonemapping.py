"""Tone mapping for the LDR metrics (docs/metrics.md §1): T(x) = srgb_encode(clip(x·2^EV, 0, 1))."""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..errors import DbenchInputError
#: Linear-segment threshold of the sRGB transfer function (IEC 61966-2-1).
SRGB_THRESHOLD = 0.0031308
#: The same threshold in encoded values (12.92 · SRGB_THRESHOLD, rounded as in the standard).
SRGB_THRESHOLD_ENCODED = 0.04045
#: One-line statement of the tone mapping, printed by reports next to the LDR metrics.
TONEMAP_DEFINITION = ("tone map T(x) = sRGB(clip(x·2^EV, 0, 1)), EV = 0 unless the scene sets it; "
                      "sRGB(y) = 12.92·y for y <= 0.0031308, else 1.055·y^(1/2.4) − 0.055")


def _as_float64(name: str, x: Any) -> np.ndarray:
    arr = np.asarray(x)
    if arr.dtype == object or np.iscomplexobj(arr) or not (
            np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
        raise DbenchInputError(f"{name}: expected a real numeric array, got dtype {arr.dtype}")
    return arr.astype(np.float64, copy=False)


#: The exposures (stops) whose scale 2^EV is a finite, non-zero float64: above, Python's power
#: overflows (an internal error after every method ran); below, it rounds to 0 and every
#: tone-mapped pixel is black, so the LDR metrics of every method read as perfect.
EV_RANGE = (-1074, 1023)


def check_ev(ev: Any) -> float:
    """Return ``ev`` as a float; DbenchInputError unless it is a real number in
    :data:`EV_RANGE` (so finite)."""
    valid = (f"ev: expected a finite number (exposure in stops) in [{EV_RANGE[0]}, "
             f"{EV_RANGE[1]}], got {ev!r}")
    try:
        value = float(ev)
    except (TypeError, ValueError, OverflowError):
        raise DbenchInputError(valid) from None
    if not (math.isfinite(value) and EV_RANGE[0] <= value <= EV_RANGE[1]):
        raise DbenchInputError(valid)
    return value


def srgb_encode(y: Any) -> np.ndarray:
    """sRGB transfer function (linear -> display-encoded), element-wise, float64.

    Args:
        y: array of any shape, linear values, normally in [0, 1] (values outside are not clipped:
            negative values follow the linear segment, values above 1 the power segment).

    Returns:
        float64 array of the same shape.
    """
    y = _as_float64("y", y)
    with np.errstate(invalid="ignore"):
        # 1.055 p − 0.055 written as 1 + 1.055 (p − 1), so that 1 maps to exactly 1.
        power = 1.0 + 1.055 * (np.power(np.maximum(y, SRGB_THRESHOLD), 1.0 / 2.4) - 1.0)
    return np.where(y <= SRGB_THRESHOLD, 12.92 * y, power)


def srgb_decode(s: Any) -> np.ndarray:
    """Inverse of :func:`srgb_encode` (display-encoded -> linear), element-wise, float64."""
    s = _as_float64("s", s)
    with np.errstate(invalid="ignore"):
        power = np.power((np.maximum(s, SRGB_THRESHOLD_ENCODED) + 0.055) / 1.055, 2.4)
    return np.where(s <= SRGB_THRESHOLD_ENCODED, s / 12.92, power)


def tonemap(x: Any, ev: float = 0.0) -> np.ndarray:
    """Tone-map linear HDR values to sRGB-encoded values in [0, 1] (docs/metrics.md §1).

    ``y = clip(x · 2^ev, 0, 1)``, then :func:`srgb_encode`.

    Args:
        x: array of any shape (typically (H, W, C)), linear radiance.
        ev: exposure in stops (finite).

    Returns:
        float64 array of the shape of ``x``, values in [0, 1] (NaN where ``x`` is NaN).
    """
    ev = check_ev(ev)
    x = _as_float64("x", x)
    scaled = x * (2.0 ** ev) if ev != 0.0 else x
    return srgb_encode(np.clip(scaled, 0.0, 1.0))
