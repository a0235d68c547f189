"""The readable JBF (docs/methods/jbf.md §1.1): a loop over the window offsets accumulating shifted whole
images in float64, on the shared base weights."""
from __future__ import annotations

from typing import Any

import numpy as np

from ..kernels.bilateral.guide import Guide, color_planes
from ..kernels.bilateral.reference import reference_weights, shift_slices


def jbf_reference(color: Any, guide: Guide, *, return_weights: bool = False):
    """Readable JBF: loop over offsets, accumulate shifted whole images (float64).

    out_i = Σ_j ρ_ij h_ij v_j L_j / Σ_j ρ_ij h_ij v_j with v_j = colour finite (docs/methods/jbf.md §1.1).

    Returns:
        (H, W, 3) float64; with ``return_weights`` also the (O, H, W) normalised weights w_ij
        per offset (guide.dy, guide.dx), for checks.
    """
    col, valid = color_planes(color, guide.shape)
    num = np.zeros(col.shape)
    den = np.zeros(guide.shape)
    stack = [] if return_weights else None
    for k in range(len(guide.dy)):
        (ys, xs), (yn, xn) = shift_slices(int(guide.dy[k]), int(guide.dx[k]), *guide.shape)
        wk = reference_weights(guide, k)
        wk[ys, xs] *= valid[yn, xn]
        num[ys, xs] += wk[ys, xs, None] * col[yn, xn]
        den += wk
        if stack is not None:
            stack.append(wk)
    out = np.divide(num, den[..., None], out=np.zeros_like(num), where=den[..., None] > 0)
    if return_weights:
        ws = np.stack(stack)
        return out, np.divide(ws, den, out=np.zeros_like(ws), where=den > 0)
    return out
