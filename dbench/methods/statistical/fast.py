"""The fast statistical denoiser (docs/methods/statistical.md §8) on the JBF's shared kernels: the
Numba accumulation :func:`~dbench.methods.kernels.bilateral.numba2d.accumulate` or, with
``backend="torch"``, :func:`~dbench.methods.kernels.bilateral.torch_path.accumulate_torch`, each
with the Welch test inlined (:mod:`dbench.methods.kernels.welch`). Equal to
:func:`.reference.statistical_reference` within float32 rounding of the weights (relative
difference below 1e-5, tests/methods/test_statistical.py).

Shapes: colour (H, W, 3); statistics as :class:`.reference.StatPlanes`; output (H, W, 3) float32.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..kernels.bilateral.guide import Guide, color_planes
from ..kernels.bilateral.numba2d import accumulate
from ..kernels.bilateral.reference import safe_divide
from ..kernels.bilateral.torch_path import accumulate_torch
from .params import Threshold
from .reference import StatPlanes

__all__ = ["statistical_fast"]


def statistical_fast(color: Any, sp: StatPlanes, guide: Guide, threshold: Threshold, *,
                     backend: str = "numba", membership_on: bool = True, device: Any = None,
                     dtype: Any = None) -> np.ndarray:
    """Numba (default) or PyTorch statistical denoiser: (H, W, 3) float32.

    Uses the JBF's shared accumulation (float32 weights, float64 Welch test bit-identical to the
    reference, symmetric pairs, parallel row bands, O(H·W) memory). ``device``/``dtype`` apply to
    the PyTorch backend (default: CUDA if available, float32).
    """
    guide = guide.isolate(sp.bad)
    col, valid = color_planes(color, guide.shape)
    planes = np.concatenate([np.moveaxis(col, -1, 0), valid[None].astype(np.float64)], axis=0)
    test = {}
    if membership_on:
        test = dict(theta=sp.theta, var=sp.var)
        if threshold.table is None:
            test["g2"] = threshold.g2
        else:
            test.update(nint=sp.nint, g2_table=threshold.table)
    if backend == "torch":
        sums = accumulate_torch(guide, planes, device=device, dtype=dtype, **test)
    else:
        sums = accumulate(guide, planes, **test)
    sums += planes                                       # centre: ρ_ii = m_ii = 1, weight v_i
    out = safe_divide(sums[:3], sums[3:4])
    return np.ascontiguousarray(np.moveaxis(out, 0, -1), dtype=np.float32)
