"""The fast JBF (the shared Numba kernel, or PyTorch with ``backend="torch"``) and the public entry
point :func:`joint_bilateral_filter` choosing between it and the reference.

Example:
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> color = rng.random((16, 16, 3)).astype(np.float32)
    >>> albedo = np.full((16, 16, 3), 0.5, np.float32)
    >>> normal = np.zeros((16, 16, 3), np.float32); normal[..., 2] = 1
    >>> out = joint_bilateral_filter(color, albedo, normal, radius=3)
    >>> out.shape, out.dtype
    ((16, 16, 3), dtype('float32'))
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..checks import check_choice
from ..kernels.bilateral.guide import Guide, color_planes, image_shape, make_guide
from ..kernels.bilateral.numba2d import accumulate
from ..kernels.bilateral.reference import safe_divide
from ..kernels.bilateral.torch_path import accumulate_torch
from .params import BACKENDS
from .reference import jbf_reference


def jbf_fast(color: Any, guide: Guide, *, backend: str = "numba") -> np.ndarray:
    """Fast JBF (Numba, or PyTorch with ``backend="torch"``): (H, W, 3) float32.

    Same result as :func:`jbf_reference` within float32 rounding (max relative difference
    ≈ 1e-6 measured; tests use 1e-5).
    """
    col, valid = color_planes(color, guide.shape)
    v = valid.astype(np.float64)
    planes = np.concatenate([np.moveaxis(col, -1, 0), v[None]], axis=0)
    if backend == "torch":
        sums = accumulate_torch(guide, planes)
    else:
        sums = accumulate(guide, planes)
    sums += planes  # centre pixel: ρ_ii = 1, weight v_i
    out = safe_divide(sums[:3], sums[3:4])
    return np.ascontiguousarray(np.moveaxis(out, 0, -1), dtype=np.float32)


def resolve_backend(backend: str, *, allow_torch: bool = True) -> str:
    check_choice("backend", backend, BACKENDS)
    if backend == "auto":
        return "numba"  # on a GPU the harness runs the device path instead (docs/gpu.md §3)
    return backend


def joint_bilateral_filter(color: Any, albedo: Any, normal: Any, depth: Any = None,
                           position: Any = None, *, backend: str = "numba",
                           **options: Any) -> np.ndarray:
    """Joint bilateral filter of docs/methods/jbf.md §1 on an (H, W, 3) image.

    Args:
        color: (H, W, 3) linear noisy radiance.
        albedo, normal: (H, W, 3) G-buffers; depth (H, W, 1) for the hit mask (None = all hit);
            position (H, W, 3) when ``features`` include ``"position"``.
        backend: ``"numba"`` (default), ``"torch"``, ``"auto"`` or ``"reference"`` (float64 NumPy).
        **options: :func:`make_guide` keywords (radius, sigma, sigma_convention, window,
            features, sigma_position, sigma_depth, hit_mask).

    Returns:
        (H, W, 3) float32.
    """
    backend = resolve_backend(backend, allow_torch=False)
    shape = image_shape(color)
    guide = make_guide(albedo, normal, depth, position, shape=shape, **options)
    if backend == "reference":
        return jbf_reference(color, guide).astype(np.float32)
    return jbf_fast(color, guide, backend=backend)
