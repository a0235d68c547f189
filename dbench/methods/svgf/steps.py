"""The per-frame steps of SVGF that other sequence methods reuse (``bmfr``), built on
:mod:`.dispatch` (docs/methods/svgf.md, the "spec" of the section numbers): the optional
``emission`` buffer of the primary hits, read and clamped like the colour
(:func:`emission_buffer`), that emission accumulated like the colour (:func:`accumulate_emission`),
and A-SVGF's temporal gradient with its adaptive history (:func:`gradient_history`, docs/methods/svgf.md §6).

Layout: planar images as in :mod:`.reference`, colour (3, H, W), scalars (H, W); the ``emission``
buffer (H, W, 3) as the frame holds it.
"""
from __future__ import annotations

import numpy as np

from ...data import check_buffer
from .. import temporal as T
from ..guards import RADIANCE_MAX
from . import dispatch as C
from .params import ALPHA0_PAPER

__all__ = ["accumulate_emission", "emission_buffer", "gradient_history"]


def emission_buffer(data, h: int, w: int) -> np.ndarray | None:
    """The optional ``emission`` buffer, checked and clamped to ±RADIANCE_MAX like the colour."""
    emission = getattr(data, "emission", None)
    if emission is None:
        return None
    return T.clamp_radiance(check_buffer("emission", emission, (h, w, 3)), RADIANCE_MAX)


def accumulate_emission(backend: str, prep: dict, history: np.ndarray, n_hist, ok, alpha_min,
                        n_max, alpha, present, out: np.ndarray | None = None) -> np.ndarray:
    """(3, H, W) float32 emission of the primary hits accumulated like the colour (the same
    reprojection, history length and α); 0 where the pixel has no emission history. ``out``:
    an optional (3, H, W) array for the compiled kernel to write into."""
    acc, _, _ = T.accumulate_any(backend, prep["emission"], history, n_hist, ok, alpha_min,
                                 n_max, alpha, present, out=None if out is None else (out, None))
    return acc


def gradient_history(data, geo, prev, prev_lum, hist_n, n_max: float, iterations: int = 3,
                     mode: str = "seed", sigma_z: float = 1.0, sigma_n: float = 128.0,
                     backend: str = "numba") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A-SVGF's temporal gradient and adaptive history (docs/methods/svgf.md §6) for any
    reprojecting method: G per 3×3 stratum of the previous frame from the frame's ``gradient``
    buffer (the re-shaded samples) against ``prev_lum`` (previous raw luminance, (H, W)),
    filtered by ``iterations`` à-trous passes, fetched at full resolution through the motion
    vectors; ``N' = min(N(1 − G)^10 + 1, n_max)``, α = mix(1/N', 1, G). ``mode``
    (params.GRADIENT_MODES): ``"seed"`` G is the filtered (δ/Δ)² of the strata; ``"filtered"``
    G = (|δ̂| / Δ̂)² of the separately filtered δ and Δ, so that strata whose re-shaded path
    re-traced exactly (δ = 0) dilute those whose path diverged before the ratio is taken
    (docs/temporal.md §14); ``"filtered_abs"`` the same with |δ| filtered instead of δ, so that
    a pixel lit by two lights that trade places keeps its gradient (per-sample δ of either sign
    does not cancel); ``"paper"`` λ = |δ̂| / Δ̂ and the paper's α.

    Args: ``geo``/``prev``: this and the previous frame's Geometry; ``hist_n`` (H, W) the
    reprojected history length. Returns (G, N', α), each (H, W) float32; G = 0 without a
    previous frame or motion.
    """
    h, w = geo.shape
    low = np.zeros((-(-h // 3), -(-w // 3)), np.float32)  # no gradient without history
    motion = geo.motion if geo.motion is not None else np.full((2, h, w), np.nan, np.float32)
    if (prev_lum is not None and prev is not None and prev.shape == geo.shape
            and geo.motion is not None):
        grad = T.clamp_radiance(check_buffer("gradient", getattr(data, "gradient", None),
                                             (h, w, 3)), RADIANCE_MAX)
        l_grad = grad @ T.LUMA  # (H, W) luminance of the re-shaded previous samples
        strata = C.stratum_gradients(prev_lum, l_grad, prev.hit, prev.depth, prev.normal,
                                     backend=backend)
        if mode == "filtered_abs":  # |δ| filtered: changes of either sign add up
            strata = dict(strata, delta=np.abs(strata["delta"]))
        filt = C.filter_gradients(strata, iterations, sigma_z, sigma_n, backend)
        if mode == "seed":
            low = filt["g"]
        else:  # λ = |δ̂| / Δ̂ of the separately filtered δ and Δ (the A-SVGF paper)
            with np.errstate(divide="ignore", invalid="ignore"):
                low = np.where(filt["norm"] > 0,
                               np.minimum(1.0, np.abs(filt["delta"]) / filt["norm"]), 0.0)
            if mode in ("filtered", "filtered_abs"):  # squared as the seed's G, into its N', α
                low = np.square(low).astype(np.float32)
    history_rule = "paper" if mode == "paper" else "seed"
    return C.adaptive_history(low, motion, geo.hit, hist_n, n_max, history_rule, ALPHA0_PAPER,
                              backend)
