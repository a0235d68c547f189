"""Dataset types handed from the renderer to the denoisers.

Plain dataclasses around NumPy arrays, constructible directly so that methods and tests can
run on synthetic data. Shapes use (H, W, C) with row 0 at the top; C = 3 for colour buffers.

Buffer names (used in code, files and reports): ``color``, ``albedo``, ``normal``, ``depth``,
``position``, ``stats``, ``reference``.

Example:
    >>> import numpy as np
    >>> f = Frame(color=np.zeros((4, 5, 3), np.float32))
    >>> f.shape
    (4, 5)
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from .errors import DbenchInputError

#: Buffers a Frame may carry, with their channel count.
FRAME_BUFFERS: dict[str, int] = {
    "color": 3,
    "albedo": 3,
    "normal": 3,
    "depth": 1,
    "position": 3,
    "reference": 3,
}
#: Every name a method may list in ``needs``.
BUFFER_NAMES = tuple(FRAME_BUFFERS) + ("stats",)


def check_buffer(name: str, array: Any, shape: tuple[int | None, ...], *, dtype=np.float32,
                 finite: bool = False) -> np.ndarray:
    """Validate one buffer and return it as a C-contiguous array of ``dtype``.

    ``shape`` may hold ``None`` for a free dimension. The error names the buffer and the
    expected shape, so a caller never has to guess which input was wrong.
    """
    if array is None:
        raise DbenchInputError(f"{name}: missing; expected an array of shape {_fmt(shape)}")
    arr = np.asarray(array)
    if arr.dtype == object or not (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
        raise DbenchInputError(f"{name}: expected a numeric array of shape {_fmt(shape)}, "
                               f"got dtype {arr.dtype}")
    if arr.ndim != len(shape) or any(e is not None and e != s for e, s in zip(shape, arr.shape)):
        raise DbenchInputError(f"{name}: expected shape {_fmt(shape)}, got {tuple(arr.shape)}")
    if any(s == 0 for s in arr.shape):
        raise DbenchInputError(f"{name}: empty array of shape {tuple(arr.shape)}; "
                               f"expected {_fmt(shape)} with every dimension > 0")
    arr = np.ascontiguousarray(arr, dtype=dtype)
    if finite and not np.all(np.isfinite(arr)):
        raise DbenchInputError(f"{name}: contains NaN or Inf; expected finite values")
    return arr


def _fmt(shape: tuple[int | None, ...]) -> str:
    return "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"


@dataclass
class SampleStats:
    """Per-pixel, per-channel statistics of the transformed samples (spec/statistical.md §4).

    Attributes:
        n: (H, W, C) sample count per pixel and channel.
        mean: (H, W, C) mean μ of the transformed samples.
        var_mean: (H, W, C) variance of the mean σ²/n (σ² unbiased; 0 where σ² is zero or n < 2).
        m3: (H, W, C) biased third central moment of the transformed samples.
        transform: ``"identity"``, ``"box-cox"`` or ``"yeo-johnson"``.
        lam: λ of the transform (ignored by ``identity``).
        diagnostics: counters such as ``n_clamped``, ``n_nonfinite``.
    """

    n: np.ndarray
    mean: np.ndarray
    var_mean: np.ndarray
    m3: np.ndarray
    transform: str = "box-cox"
    lam: float = 0.5
    diagnostics: dict[str, int] = field(default_factory=dict)

    def __post_init__(self) -> None:
        mean = np.asarray(self.mean)
        if mean.ndim < 1:
            raise DbenchInputError("stats.mean: expected an array, (H, W, C) for images or "
                                   f"(H, W, T, C) for transient data, got {tuple(mean.shape)}")
        shape = tuple(mean.shape)
        self.mean = check_buffer("stats.mean", mean, shape, dtype=np.float64)
        self.n = check_buffer("stats.n", np.broadcast_to(np.asarray(self.n), shape)
                              if np.ndim(self.n) == 0 else self.n, shape, dtype=np.float64)
        self.var_mean = check_buffer("stats.var_mean", self.var_mean, shape, dtype=np.float64)
        self.m3 = check_buffer("stats.m3", self.m3, shape, dtype=np.float64)

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(self.mean.shape)

    @property
    def theta(self) -> np.ndarray:
        """Skew-corrected mean θ̂ = μ + M3 / (6 σ² n), with the correction 0 where σ² = 0.

        σ² n = var_mean · n², so the correction is M3 / (6 var_mean n²) (spec §4).
        """
        denom = 6.0 * self.var_mean * self.n * self.n
        corr = np.divide(self.m3, denom, out=np.zeros_like(self.m3), where=denom > 0)
        return self.mean + corr


@dataclass
class Frame:
    """One steady image and the buffers rendered with it.

    Attributes:
        color: (H, W, 3) float32 linear noisy radiance (the mean of the samples).
        albedo: (H, W, 3) float32 or None.
        normal: (H, W, 3) float32 world-space shading normal (0 where nothing is hit) or None.
        depth: (H, W, 1) float32 distance along the camera ray (0 where nothing is hit) or None.
        position: (H, W, 3) float32 world position or None.
        stats: SampleStats of the same samples as ``color`` or None.
        reference: (H, W, 3) float32 high-spp image or None.
        meta: scene, spp, seed, render timings and other settings.
    """

    color: np.ndarray
    albedo: np.ndarray | None = None
    normal: np.ndarray | None = None
    depth: np.ndarray | None = None
    position: np.ndarray | None = None
    stats: SampleStats | None = None
    reference: np.ndarray | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    kind = "steady"

    def __post_init__(self) -> None:
        color = np.asarray(self.color) if self.color is not None else None
        if color is None or color.ndim != 3:
            raise DbenchInputError("color: expected shape (H, W, 3), got "
                                   f"{None if color is None else tuple(color.shape)}")
        h, w = color.shape[:2]
        for name, channels in FRAME_BUFFERS.items():
            value = getattr(self, name)
            if value is None:
                continue
            value = np.asarray(value)
            if name == "depth" and value.ndim == 2:
                value = value[..., None]
            setattr(self, name, check_buffer(name, value, (h, w, channels)))
        if self.stats is not None and self.stats.shape != (h, w, 3):
            raise DbenchInputError(f"stats: expected shape (H, W, 3) = ({h}, {w}, 3), "
                                   f"got {self.stats.shape}")

    @property
    def shape(self) -> tuple[int, int]:
        return tuple(self.color.shape[:2])

    def has(self, buffer: str) -> bool:
        return getattr(self, buffer, None) is not None

    def with_buffers(self, **buffers: Any) -> "Frame":
        """A copy with some buffers replaced (validated again)."""
        return replace(self, **buffers)
