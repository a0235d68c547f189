"""Temporal accumulation, luminance moments and reprojection (docs/methods/temporal.md).

Shared by ``accumulate``, ``svgf``/``asvgf`` and ``bmfr``. Functional core on planar float32
arrays — images are (C, H, W) here, so that every colour channel is one contiguous plane for the
compiled kernels — plus :class:`History`, the thin stateful wrapper a sequence method keeps.

Files: ``params.py`` (constants, status codes, backends), ``geometry.py`` (:class:`Geometry`),
``color.py`` (luminance, moments), ``reference.py``, ``numba_path.py`` and ``torch_path.py``
(reprojection and accumulation), ``dispatch.py`` (the backend choice) and ``history.py``
(:class:`History`, :class:`HistoryDenoiser`); this package exposes all of them.

Per frame (docs/methods/temporal.md §5): build the frame's :class:`Geometry` (:func:`frame_geometry`), reproject the
previous frame's history buffers (:func:`reproject`: 2×2 bilinear with validity §3.3, normalised
3×3 fallback §3.4, reset on disocclusion §3.5), then :func:`accumulate` the new sample
(§2: ``C' = α C + (1 − α) C'←``, ``N = min(N← + 1, N_max)``, ``α = max(α_min, 1/N)``) and its
luminance :func:`moments` ``[l, l²]`` (Rec. 709 luminance).

Validity of a previous-frame tap q for pixel p (docs/methods/temporal.md §3.2)::

    inside(q) and prev_ok(q) and hit(p)
    and |D←(q) − d_exp(p)| <= τ_d · d_exp(p)         τ_d = 0.05
    and n←(q) · n(p) >= τ_n                           τ_n = 0.9

``prev_ok`` is the previous hit mask and'ed with "history finite and not empty". ``d_exp`` is the
distance from the previous camera origin to this pixel's world position (:func:`expected_distance`);
without camera metadata it falls back to this frame's depth (exact for a static camera).

Backends (``backend=``): ``"numba"`` (compiled, parallel over rows), ``"reference"`` (readable
per-pixel NumPy, float64), ``"torch"`` (vectorised PyTorch: index-tensor gathers and masks, on
the device of the inputs or CUDA when available, :func:`reproject_torch`,
:func:`accumulate_torch`) and ``"auto"`` (numba; on a GPU the methods' device paths run instead,
docs/gpu.md; :func:`resolve_backend`). The torch functions take and return tensors; the
NumPy-facing dispatchers (:func:`reproject`, :func:`accumulate_any`) convert at their boundary, and
:class:`History` keeps its state as NumPy arrays for every backend.

Non-finite policy: a pixel whose colour sample is non-finite is *missing*: it keeps its
reprojected history (the history length is not incremented), or becomes an empty history
(value 0, N = 0) that later frames and spatial filters ignore. Non-finite depth, normal or
position make a pixel "no hit" (its history is reset every frame). Non-finite motion means "no
previous position" (reset). Nothing non-finite is ever read from another pixel.

Example:
    >>> import numpy as np
    >>> h = np.arange(12, dtype=np.float32).reshape(1, 3, 4)          # (C, H, W)
    >>> geo = Geometry.flat(3, 4, motion=(1.0, 0.0))                   # everything moved 1 px
    >>> out, status = reproject(h, geo, geo, np.ones((3, 4), bool))
    >>> out[0, :, :3].tolist() == h[0, :, 1:].tolist(), status[:, 3].tolist()  # 3×3 fallback
    (True, [2, 2, 2])
"""
from __future__ import annotations

from .color import luminance, moments, sample_mask, to_interleaved, to_planar, variance_from_moments
from .dispatch import accumulate_any, reproject, resolve_backend
from .geometry import NORMAL_BUFFERS, Geometry, expected_distance, feature_normal, frame_geometry
from .history import History, HistoryDenoiser
from .numba_path import accumulate_fast, clamp_radiance, kernel_threads, reproject_fast
from .params import (BACKENDS, BILINEAR, EPS_F, FALLBACK, FALLBACK_KERNEL, LUMA, N_MAX, RESET,
                     SMALL_IMAGE, TAU_D, TAU_N)
from .reference import accumulate, reproject_reference
from .taa import TAA_ALPHA, taa, taa_fast, taa_reference
from .torch_path import (accumulate_torch, as_tensor, reproject_torch, to_numpy,
                         torch_cuda_available, torch_device)

__all__ = ["BACKENDS", "BILINEAR", "EPS_F", "FALLBACK", "FALLBACK_KERNEL", "Geometry", "History",
           "TAA_ALPHA", "taa", "taa_fast", "taa_reference",
           "NORMAL_BUFFERS", "feature_normal",
           "HistoryDenoiser", "LUMA", "N_MAX", "RESET", "SMALL_IMAGE", "TAU_D", "TAU_N",
           "accumulate", "accumulate_any", "accumulate_fast", "accumulate_torch", "as_tensor",
           "clamp_radiance",
           "expected_distance", "frame_geometry", "kernel_threads", "luminance", "moments",
           "reproject", "reproject_fast", "reproject_reference", "reproject_torch",
           "resolve_backend", "sample_mask", "to_interleaved", "to_numpy", "to_planar",
           "torch_cuda_available", "torch_device", "variance_from_moments"]
