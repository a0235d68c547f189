"""Lights in a denoiser's output: :func:`keep_emitters` hands the pixels that a
frame's ``emitter`` buffer marks as covered by an emitter (the fraction of the pixel's
footprint whose primary ray sees a light, directly or in smooth mirrors,
:mod:`dbench.datasets.emitter`) back to the input.

A light seen directly or in a smooth mirror is not Monte Carlo noise: its interior is exact at
any spp, and its edge pixels carry coverage noise that no image-space filter removes without
blurring the edge. Used by ``nca``, ``autoencoder`` and the ``NAME+gate`` wrapper.

A kernel imports no method and nothing of the harness.

Example:
    >>> import numpy as np
    >>> color = np.full((1, 2, 3), 5.0, np.float32); out = np.zeros((1, 2, 3), np.float32)
    >>> keep_emitters(color, out, np.array([[[1.0], [0.5]]], np.float32))[0, :, 0].tolist()
    [5.0, 2.5]
"""
from __future__ import annotations

import numpy as np

from ...errors import DbenchInputError


def keep_emitters(color: np.ndarray, out: np.ndarray, emitter: np.ndarray | None
                  ) -> np.ndarray:
    """out + e (color − out), e the (H, W, 1) emitter coverage in [0, 1] (non-finite: 0): a
    light seen directly is not Monte Carlo noise, so its pixels keep the input, and a learned
    model's output counts only for the part of a pixel that sees a surface. Without it the
    NCA's log-space steps darkened the lamp of ``cornell`` (RMSE over all pixels 2.7x the noisy
    input's at 4 spp), and the autoencoder's consistency stage, whose relMSE loss weighs a
    bright pixel's error like a dark one's relative error, left it 1.4x the input's RMSE over
    all pixels at 256 spp (results/learned.md). Non-finite input colour keeps the output."""
    if emitter is None:
        return out
    h, w = out.shape[:2]
    e = np.asarray(emitter, np.float32)
    if e.shape != (h, w, 1):
        raise DbenchInputError(f"emitter: expected shape ({h}, {w}, 1), got {e.shape}")
    e = e[..., 0]
    ys, xs = np.nonzero(np.isfinite(e) & (e > 0))  # lights cover few pixels: touch only those
    if ys.size == 0:
        return out
    cov = np.minimum(e[ys, xs], 1.0)[:, None]
    o = out[ys, xs]
    c = np.asarray(color, np.float32)[ys, xs]
    target = np.where(np.isfinite(c), c, o)
    out = np.array(out, np.float32, copy=True)
    # full coverage: the input, exactly
    out[ys, xs] = np.where(cov >= 1, target, o + cov * (target - o))
    return out


__all__ = ["keep_emitters"]
