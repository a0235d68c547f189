"""The joint bilateral filter's base weights ρ (docs/methods/jbf.md §1), shared by every method built on
them: constants (``params``), the guide built once per frame from the G-buffers (``guide``), the
readable float64 weights (``reference``), a float32 vector ``exp`` (``vexp``), the Numba sums
over a 2-D window (``numba2d``) and over (x, y, t) (``numba3d``), and the PyTorch sums
(``torch_path``). ``jbf`` normalises these sums; ``statistical`` multiplies the weights by its
Welch membership first (docs/methods/statistical.md §7).

Non-finite input policy: a colour pixel with a NaN/Inf channel is *missing* (no weight as a
neighbour; its own output is the filtered value of its valid neighbours, or 0), so NaN never
spreads; a pixel whose G-buffers (albedo, normal, position, depth) are not finite is *isolated*
(nobody's neighbour, no neighbours)."""
from __future__ import annotations

from .guide import (Guide, check_sigma, color_planes, image_shape, inverse_variance, make_guide,
                    temporal_factors, window_offsets)
from .numba2d import accumulate
from .numba3d import accumulate3d
from .params import (FEATURES, PLANE_MAX, SEED_SIGMA, SIGMA_CONVENTIONS, TEMPORAL_PROFILES,
                     WINDOWS)
from .reference import reference_weights, safe_divide, shift_slices
from .torch_path import accumulate_torch, torch_cuda_available

__all__ = ["FEATURES", "Guide", "PLANE_MAX", "SEED_SIGMA", "SIGMA_CONVENTIONS", "TEMPORAL_PROFILES",
           "WINDOWS", "accumulate", "accumulate3d", "accumulate_torch", "check_sigma",
           "color_planes", "image_shape", "inverse_variance", "make_guide", "reference_weights",
           "safe_divide", "shift_slices", "temporal_factors", "torch_cuda_available",
           "window_offsets"]
