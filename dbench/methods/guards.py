"""Input guards shared by the built-in methods: required buffers and the finite range of radiance.

``require_buffers(method, data)`` refuses a frame that lacks a buffer the method lists in
``needs`` (a :class:`~dbench.errors.DbenchInputError` naming the buffer and its expected shape),
instead of silently running a different filter. Methods with a documented fallback for a buffer
(sequence methods without ``motion``: no reprojection) pass the names they really require.

``clamp_magnitude(x, limit)`` clamps finite values to [−limit, limit] and leaves NaN and ±Inf
alone (those are "missing" samples for every method's non-finite policy, which must not turn
them into bright pixels). Methods that square colours in float32 (luminance moments, variances)
clamp their inputs to :data:`RADIANCE_MAX` first, so that a single huge but finite pixel cannot
overflow to Inf and then to NaN (Inf − Inf) across the whole image.

    >>> import numpy as np
    >>> clamp_magnitude(np.array([1.0, -3e38, np.inf, np.nan], np.float32), 4.0).tolist()
    [1.0, -4.0, inf, nan]
"""
from __future__ import annotations

from typing import Any, Iterable

import numpy as np

from ..data import FRAME_BUFFERS
from ..errors import DbenchInputError

#: Largest colour magnitude the float32 history methods (accumulate, svgf, asvgf, bmfr) keep:
#: after albedo demodulation (÷ a_eff ≥ 1e-3) a luminance is ≤ 1e18, its square ≤ 1e36 and a
#: sum of a few hundred such squares still below the float32 maximum 3.4e38. Real radiance
#: (the sun is ~1.6e9 W m⁻² sr⁻¹) is many orders of magnitude below.
RADIANCE_MAX = 1e15


def _expected_shape(name: str) -> str:
    if name == "stats":
        return "SampleStats of shape (H, W, 3)"
    return f"shape (H, W, {FRAME_BUFFERS.get(name, '*')})"


def require_buffers(method: Any, data: Any, names: Iterable[str] | None = None) -> None:
    """Raise DbenchInputError for the first (alphabetical) buffer of ``names`` (default:
    ``method.needs``) that ``data`` lacks (attribute missing or None)."""
    for name in sorted(method.needs if names is None else names):
        if getattr(data, name, None) is None:
            raise DbenchInputError(
                f"{name}: missing; {getattr(method, 'name', '') or type(method).__name__} "
                f"needs it (expected {_expected_shape(name)})")


def depth_or_hit(data: Any) -> np.ndarray | None:
    """``data.depth`` (H, W, 1) when present; else a stand-in that only serves the hit mask:
    1 where the shading normal is non-zero (a surface was hit), 0 where it is all zero (Mitsuba,
    OIDN and pbrt write zero normals where nothing is hit); None when neither buffer is there.
    Renders from files often lack depth, and a filter that needs depth only for the hit mask
    runs without it this way."""
    depth = getattr(data, "depth", None)
    if depth is not None:
        return depth
    normal = getattr(data, "normal", None)
    if normal is None:
        return None
    normal = np.asarray(normal)
    return np.any(normal != 0, axis=-1, keepdims=True).astype(np.float32)


def clamp_magnitude(x: np.ndarray, limit: float = RADIANCE_MAX) -> np.ndarray:
    """``x`` with finite values outside [−limit, limit] set to ±limit; NaN and ±Inf kept.

    Returns ``x`` itself (no copy) when nothing needs clamping, so ordinary inputs are untouched
    bit for bit.
    """
    x = np.asarray(x)
    with np.errstate(invalid="ignore"):
        big = np.abs(x) > limit
    big &= np.isfinite(x)
    if not big.any():
        return x
    out = np.array(x, copy=True)
    out[big] = np.copysign(limit, out[big])
    return out


__all__ = ["RADIANCE_MAX", "clamp_magnitude", "require_buffers", "log_demodulated"]


def log_demodulated(color: np.ndarray, a_eff: np.ndarray) -> np.ndarray:
    """log1p(color / a_eff) as float32 for finite colour ≥ 0 and a_eff in (1e-3, 1] (the
    learned models' input encoding).

    The float32 quotient overflows to Inf for colour near the float32 maximum (3e38 / 0.2);
    there the value is recomputed in float64 (log1p(3.4e38 / 1e-3) ≈ 95, finite), elsewhere it
    is the plain float32 expression, bit for bit.
    """
    color = np.asarray(color, np.float32)
    a_eff = np.broadcast_to(np.asarray(a_eff, np.float32), color.shape)
    with np.errstate(over="ignore"):
        q = color / a_eff
    out = np.log1p(q)
    big = np.isinf(q)
    if big.any():
        out[big] = np.log1p(color[big].astype(np.float64) / a_eff[big].astype(np.float64))
    return out.astype(np.float32, copy=False)
