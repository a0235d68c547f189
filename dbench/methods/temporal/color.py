"""Colour helpers on planar (3, H, W) images: Rec. 709 luminance, luminance moments [l, l²]
(docs/methods/temporal.md §2), planar/interleaved conversion, the variance from accumulated moments and
the mask of finite samples."""
from __future__ import annotations

import numpy as np

from .params import LUMA


def luminance(color: np.ndarray) -> np.ndarray:
    """Rec. 709 luminance of a planar (3, H, W) image: (H, W)."""
    return LUMA[0] * color[0] + LUMA[1] * color[1] + LUMA[2] * color[2]


def moments(color: np.ndarray) -> np.ndarray:
    """Luminance moments [l, l²] (2, H, W) of a planar (3, H, W) image (docs/methods/temporal.md §2)."""
    lum = luminance(color)
    return np.stack([lum, lum * lum])


def to_planar(image: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(np.transpose(image, (2, 0, 1)), dtype=np.float32)


def to_interleaved(image: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(np.transpose(image, (1, 2, 0)), dtype=np.float32)


def variance_from_moments(m: np.ndarray) -> np.ndarray:
    """Var = max(0, M'2 − M'1²) for (2, H, W) accumulated moments (docs/methods/temporal.md §2)."""
    return np.maximum(0.0, m[1] - m[0] * m[0]).astype(np.float32)


def sample_mask(color: np.ndarray) -> np.ndarray:
    """(H, W) bool: every channel of the planar (3, H, W) sample is finite."""
    return np.isfinite(color).all(0)
