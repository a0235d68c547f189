"""Variance boosts of short histories (docs/temporal.md §15, §18).

A history of few frames has a noisy variance estimate, so both SVGF authors' implementations
filter it harder than the estimate says. :func:`boost_spatial` and :func:`boost_all` take the
history length ``n`` (H, W) float32 after this frame's accumulation (A-SVGF's N' after its
temporal gradient) and return the variance boosted by ``mode`` (unchanged where it does not
apply):

* "svgf", Falcor's SVGFFilterMoments pass: the 7×7 spatial estimate of N < 4 frames times 4/N;
* "asvgf", Schied's A-SVGF code (q2vkpt's asvgf_temporal.comp): the standard deviation times
  max(1, 8/N), so every estimate's variance times max(1, 64/N²) (N is N' here);
* "gradient" [dbench]: each history by the reason it is short. Where A-SVGF's gradient has
  shortened it (``shortened``: N' at least half a frame below :func:`frame_count`) Schied's
  boost, which keeps a 1-spp firefly out of a history the gradient has just dropped; where the
  surface is new (a disocclusion) Falcor's, whose weaker boost does not widen the filter of the
  long histories beside it from frame to frame (docs/temporal.md §18). Without a gradient
  (SVGF, ``shortened`` None) it is "svgf".
"""
from __future__ import annotations

import numpy as np

#: a history is shortened by the gradient when N' is this many frames below the frame count
SHORTENED_BY = 0.5


def frame_count(hist_frames: np.ndarray, ok: np.ndarray, present: np.ndarray,
                n_max: float) -> np.ndarray:
    """(H, W) float32 frames since the surface appeared: ``accumulate``'s N without A-SVGF's
    gradient, min(N← + 1, n_max) where the reprojection succeeded, else 1; a pixel without a
    usable sample keeps N← (0 without history). ``hist_frames``: (H, W) reprojected count."""
    n = np.where(ok, np.minimum(hist_frames + np.float32(1.0), np.float32(n_max)),
                 np.float32(1.0))
    return np.where(present, n, np.where(ok, hist_frames, np.float32(0.0))).astype(np.float32)


def shortened_by_gradient(n: np.ndarray, frames: np.ndarray | None) -> np.ndarray | None:
    """(H, W) bool: the gradient took at least :data:`SHORTENED_BY` frames from the history
    (``n`` = N', ``frames`` from :func:`frame_count`); None without a frame count."""
    return None if frames is None else n < frames - np.float32(SHORTENED_BY)


def boost_spatial(mode, sv: np.ndarray, n: np.ndarray, shortened: np.ndarray | None
                  ) -> np.ndarray:
    """The 7×7 spatial estimate ``sv`` (H, W), used where N < 4, boosted: times 4/N for
    "svgf", and for "gradient" where the history is not ``shortened`` (Schied's boost follows
    there, :func:`boost_all`); unchanged otherwise."""
    if mode not in ("svgf", "gradient"):
        return sv
    falcor = sv * 4.0 / np.maximum(n, 1.0)
    if mode == "gradient" and shortened is not None:
        return np.where(shortened, sv, falcor).astype(np.float32)
    return falcor


def boost_all(mode, var: np.ndarray, n: np.ndarray, filled: np.ndarray,
              shortened: np.ndarray | None) -> np.ndarray:
    """Every filled pixel's variance ``var`` (H, W), temporal and spatial estimates alike,
    boosted: times max(1, 64/N²) for "asvgf", and for "gradient" where the history is
    ``shortened``; unchanged otherwise."""
    if mode == "asvgf":
        where = filled
    elif mode == "gradient" and shortened is not None:
        where = filled & shortened
    else:
        return var
    boost = np.maximum(1.0, 64.0 / np.square(np.maximum(n, 1.0)))
    return np.where(where, var * boost, var).astype(np.float32)
