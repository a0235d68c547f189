"""Baselines on transient (H, W, T, 3) videos: ``jbf-bins``, ``oidn-bins`` and ``gauss3d``.

* ``jbf-bins``: the joint bilateral filter of :mod:`dbench.methods.jbf` on every time bin, with
  the G-buffers (constant along time) shared by all bins (docs/methods/jbf.md §1.4). The weights of a
  pixel pair do not depend on the bin, so all bins go through one call of the JBF's compiled
  accumulation kernel (:func:`dbench.methods.kernels.bilateral.numba2d.accumulate`) with 4 planes per bin (colour
  × validity, validity): the same result as calling the JBF bin by bin (tests prove it), at a
  fraction of the cost. ``temporal_radius`` > 0 gives the JBF 3D of the spec (window
  (2r+1)² × (2r_t+1), ``temporal_profile`` "box" or "gaussian" with ``sigma_t`` bins; bins
  outside [0, T) get no weight).
* ``oidn-bins``: Intel Open Image Denoise on every bin as an image (albedo and normal shared),
  through :func:`dbench.methods.oidn.oidn_denoise`.
* ``gauss3d``: the plain 3D Gaussian of docs/methods/jbf.md §1.4 for participating media:
  ρ = exp(−½(Δx² + Δy²)/σ_s² − ½Δt²/σ_t²) over a (2r_s+1)² × (2r_t+1) window, normalised per
  voxel; out-of-image and out-of-range neighbours get no weight. Defaults σ_s² = 10 px²,
  σ_t = 1 bin, r_s = 5, r_t = 1. The kernel is separable and so are the masks, so the fast path
  is three 1-D correlations of (colour·validity) and validity; :func:`gauss3d_reference` is the
  readable direct sum the tests compare it with.

Every method skips what the data does not need: a bin with no energy anywhere in the frame (all
values exactly 0) costs nothing and comes back as 0.

Non-finite policy (as the steady JBF): a voxel with a NaN/Inf channel is missing: it gets no
weight as a neighbour, and its own output is the filtered value of its valid neighbours (0 if
none). ``oidn-bins`` replaces non-finite values by 0 (the ``oidn`` policy). Outputs are finite.

Example:
    >>> import numpy as np
    >>> from dbench.data import TransientFrame
    >>> from dbench.registry import get
    >>> v = TransientFrame(color=np.ones((8, 8, 5, 3), np.float32))
    >>> out = get("gauss3d").denoise(v)
    >>> out.shape, bool(np.allclose(out, 1.0))
    ((8, 8, 5, 3), True)
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from ...data import check_buffer
from ...errors import DbenchInputError
from ...denoiser import Denoiser, register
from ..checks import check_choice, check_features, check_positive, check_radius
from ..kernels.bilateral.guide import check_sigma, make_guide
from ..kernels.bilateral.numba2d import accumulate
from ..kernels.bilateral.params import FEATURES, SEED_SIGMA, SIGMA_CONVENTIONS, WINDOWS
from ..oidn import FEATURE_NEEDS, FEATURE_SETS, QUALITIES, oidn_denoise

TEMPORAL_PROFILES = ("box", "gaussian")

__all__ = ["JBFBins", "OIDNBins", "Gauss3D", "jbf_bins", "oidn_bins", "gauss3d",
           "gauss3d_reference", "nonempty_bins", "check_video"]


# ---------------------------------------------------------------------------------------------
# shared helpers


def check_video(data: Any, name: str) -> np.ndarray:
    """The (H, W, T, 3) colour of a TransientFrame, or a DbenchInputError naming the input."""
    if getattr(data, "kind", None) != "transient":
        raise DbenchInputError(f"{name}: expected a TransientFrame with color of shape "
                               f"(H, W, T, 3), got {getattr(data, 'kind', type(data).__name__)} "
                               "data")
    return check_buffer("color", data.color, (None, None, None, 3))


def nonempty_bins(video: np.ndarray) -> np.ndarray:
    """(T,) bool: bins holding any value other than exactly 0 (NaN counts as non-empty)."""
    return np.asarray(np.any(video != 0, axis=(0, 1, 3)))


def _valid_planes(video: np.ndarray):
    """float64 colour with missing voxels zeroed, and the (H, W, T) validity mask."""
    col = np.asarray(video, np.float64)
    valid = np.all(np.isfinite(col), axis=-1)
    return np.where(valid[..., None], col, 0.0), valid


def _temporal_weights(radius: int, profile: str, sigma_t: float) -> np.ndarray:
    """(2r_t+1,) weights of the temporal offsets −r_t..r_t."""
    dt = np.arange(-radius, radius + 1, dtype=np.float64)
    if profile == "box":
        return np.ones_like(dt)
    return np.exp(-0.5 * dt * dt / (sigma_t * sigma_t))


def _temporal_mix(x: np.ndarray, weights: np.ndarray, axis: int) -> np.ndarray:
    """Σ_τ w_τ x[t + τ] along ``axis`` with zero outside [0, T) (no weight there)."""
    r = (len(weights) - 1) // 2
    if r == 0:
        return x * weights[0]
    out = np.zeros_like(x)
    n = x.shape[axis]
    for k, w in zip(range(-r, r + 1), weights):
        lo, hi = max(0, -k), min(n, n - k)
        if lo >= hi:
            continue
        dst = [slice(None)] * x.ndim
        src = [slice(None)] * x.ndim
        dst[axis] = slice(lo, hi)
        src[axis] = slice(lo + k, hi + k)
        out[tuple(dst)] += w * x[tuple(src)]
    return out


def _expand_keep(keep: np.ndarray, radius: int) -> np.ndarray:
    """Bins needed as neighbours of the kept bins (keep dilated by ``radius``)."""
    if radius == 0:
        return keep.copy()
    out = keep.copy()
    for k in range(1, radius + 1):
        out[k:] |= keep[:-k]
        out[:-k] |= keep[k:]
    return out


# ---------------------------------------------------------------------------------------------
# jbf-bins


def jbf_bins(video: Any, albedo: Any, normal: Any, depth: Any = None, position: Any = None, *,
             temporal_radius: int = 0, temporal_profile: str = "box", sigma_t: float = 1.0,
             skip_empty: bool = True, **options: Any) -> np.ndarray:
    """JBF of every bin of an (H, W, T, 3) video with shared G-buffers (docs/methods/jbf.md §1, §1.4).

    Args:
        video: (H, W, T, 3) linear noisy radiance per bin.
        albedo, normal, depth, position: G-buffers as for :func:`make_guide`.
        temporal_radius: r_t; 0 filters each bin alone (the per-bin JBF).
        temporal_profile, sigma_t: temporal weight, "box" (1 for |Δt| ≤ r_t) or "gaussian".
        skip_empty: bins without energy anywhere return 0 and cost nothing.
        **options: :func:`make_guide` keywords (radius, sigma, sigma_convention, window, ...).

    Returns:
        (H, W, T, 3) float32.
    """
    vid = check_buffer("color", video, (None, None, None, 3), dtype=np.float32)
    h, w, t = vid.shape[:3]
    r_t = check_radius(temporal_radius, "temporal_radius")
    check_choice("temporal_profile", temporal_profile, TEMPORAL_PROFILES)
    check_positive("sigma_t", sigma_t)
    guide = make_guide(albedo, normal, depth, position, shape=(h, w), **options)
    keep = nonempty_bins(vid) if skip_empty else np.ones(t, bool)
    out = np.zeros((h, w, t, 3), np.float32)
    need = _expand_keep(keep, r_t)
    idx = np.flatnonzero(need)
    if idx.size == 0:
        return out
    col, valid = _valid_planes(vid[:, :, idx])
    v = valid.astype(np.float64)                                   # (H, W, n)
    planes = np.concatenate([np.moveaxis(col, (2, 3), (0, 1)).reshape(-1, h, w),
                             np.moveaxis(v, 2, 0)], axis=0)        # (3n + n, H, W)
    sums = accumulate(guide, planes)
    sums += planes                                                 # centre: ρ_ii = 1
    n = idx.size
    num = sums[:3 * n].reshape(n, 3, h, w)
    den = sums[3 * n:]                                             # (n, H, W)
    if r_t > 0:
        # scatter back to the full time axis so that temporal neighbours line up
        full_num = np.zeros((t, 3, h, w))
        full_den = np.zeros((t, h, w))
        full_num[idx] = num
        full_den[idx] = den
        tw = _temporal_weights(r_t, temporal_profile, float(sigma_t))
        num = _temporal_mix(full_num, tw, 0)[keep]
        den = _temporal_mix(full_den, tw, 0)[keep]
        kept = np.flatnonzero(keep)
    else:
        sel = keep[idx]
        num, den, kept = num[sel], den[sel], idx[sel]
    res = np.divide(num, den[:, None], out=np.zeros_like(num), where=den[:, None] > 0)
    out[:, :, kept] = np.moveaxis(res, (0, 1), (2, 3)).astype(np.float32)
    return out


@register("jbf-bins")
class JBFBins(Denoiser):
    """JBF per time bin with shared G-buffers; ``temporal_radius`` > 0 gives the JBF 3D."""

    kinds = {"transient"}
    needs = {"color", "albedo", "normal", "depth"}
    defaults: dict[str, Any] = dict(
        radius=20, sigma=SEED_SIGMA, sigma_convention="variance", window="square",
        features=("xy", "albedo", "normal"), hit_mask=True, temporal_radius=0,
        temporal_profile="box", sigma_t=1.0, skip_empty=True)

    def __init__(self, **params: Any) -> None:
        super().__init__(**params)
        p = self.params
        check_radius(p["radius"])
        check_sigma(p["sigma"])
        check_choice("sigma_convention", p["sigma_convention"], SIGMA_CONVENTIONS)
        check_choice("window", p["window"], WINDOWS)
        check_radius(p["temporal_radius"], "temporal_radius")
        check_choice("temporal_profile", p["temporal_profile"], TEMPORAL_PROFILES)
        check_positive("sigma_t", p["sigma_t"])
        # a video's guide has no position buffer (jbf-bins does not load one)
        check_features(p["features"], [f for f in FEATURES if f != "position"])

    def denoise(self, data: Any) -> np.ndarray:
        video = check_video(data, self.name)
        p = self.params
        return jbf_bins(video, data.albedo, data.normal, getattr(data, "depth", None),
                        temporal_radius=p["temporal_radius"],
                        temporal_profile=p["temporal_profile"], sigma_t=p["sigma_t"],
                        skip_empty=p["skip_empty"], radius=p["radius"], sigma=p["sigma"],
                        sigma_convention=p["sigma_convention"], window=p["window"],
                        features=p["features"], hit_mask=p["hit_mask"])


# ---------------------------------------------------------------------------------------------
# oidn-bins


def oidn_bins(video: Any, albedo: Any = None, normal: Any = None, *, quality: str = "high",
              clean_aux: bool = True, skip_empty: bool = True) -> np.ndarray:
    """OIDN on every bin of an (H, W, T, 3) video as an image; albedo/normal shared."""
    vid = check_buffer("color", video, (None, None, None, 3), dtype=np.float32)
    out = np.zeros_like(vid)
    keep = nonempty_bins(vid) if skip_empty else np.ones(vid.shape[2], bool)
    for t in np.flatnonzero(keep):
        out[:, :, t] = oidn_denoise(vid[:, :, t], albedo, normal, quality=quality,
                                    clean_aux=clean_aux)
    return out


@register("oidn-bins")
class OIDNBins(Denoiser):
    """Intel Open Image Denoise on each time bin (features shared by all bins)."""

    kinds = {"transient"}
    needs = {"color", "albedo", "normal"}
    defaults = dict(quality="high", features="albedo+normal", clean_aux=True, skip_empty=True)

    def __init__(self, **params: Any) -> None:
        super().__init__(**params)
        check_choice("features", self.params["features"], FEATURE_SETS)
        check_choice("quality", self.params["quality"], QUALITIES)
        self.needs = {"color"} | FEATURE_NEEDS[self.params["features"]]  # as oidn's

    def denoise(self, data: Any) -> np.ndarray:
        video = check_video(data, self.name)
        h, w = video.shape[:2]
        features = self.params["features"]
        albedo = data.albedo if features != "none" else None
        normal = data.normal if features == "albedo+normal" else None
        if features != "none":
            check_buffer("albedo", albedo, (h, w, 3))
        if features == "albedo+normal":
            check_buffer("normal", normal, (h, w, 3))
        return oidn_bins(video, albedo, normal, quality=self.params["quality"],
                         clean_aux=self.params["clean_aux"],
                         skip_empty=self.params["skip_empty"])


# ---------------------------------------------------------------------------------------------
# gauss3d


def _gauss_taps(radius: int, sigma2: float) -> np.ndarray:
    d = np.arange(-radius, radius + 1, dtype=np.float64)
    return np.exp(-0.5 * d * d / sigma2)


def _check_gauss(r_s, r_t, sigma_s2, sigma_t):
    return (check_radius(r_s, "radius"), check_radius(r_t, "temporal_radius"),
            check_positive("sigma_s2", sigma_s2, allow_inf=True),
            check_positive("sigma_t", sigma_t, allow_inf=True))


def gauss3d(video: Any, *, radius: int = 5, temporal_radius: int = 1, sigma_s2: float = 10.0,
            sigma_t: float = 1.0, skip_empty: bool = True) -> np.ndarray:
    """Plain 3D Gaussian filter of an (H, W, T, 3) video (docs/methods/jbf.md §1.4), float32.

    Separable: out = G∗(c·v) / G∗v with G = g_y ⊗ g_x ⊗ g_t truncated to the window and zero
    outside the video (no weight there); v is the validity of each voxel.
    """
    from scipy.ndimage import correlate1d

    vid = check_buffer("color", video, (None, None, None, 3), dtype=np.float32)
    r_s, r_t, s2, st = _check_gauss(radius, temporal_radius, sigma_s2, sigma_t)
    h, w, t = vid.shape[:3]
    out = np.zeros_like(vid)
    keep = nonempty_bins(vid) if skip_empty else np.ones(t, bool)
    if not keep.any():
        return out
    kept = np.flatnonzero(keep)
    lo, hi = max(0, kept[0] - r_t), min(t, kept[-1] + r_t + 1)
    col, valid = _valid_planes(vid[:, :, lo:hi])
    v = valid.astype(np.float64)
    gs = _gauss_taps(r_s, s2)
    gt = _gauss_taps(r_t, st * st)

    def blur(x, channel_axis):
        for axis, taps in ((0, gs), (1, gs), (2, gt)):
            x = correlate1d(x, taps, axis=axis, mode="constant", cval=0.0)
        return x

    num = blur(col * v[..., None], True)
    den = blur(v, False)
    res = np.divide(num, den[..., None], out=np.zeros_like(num), where=den[..., None] > 0)
    sel = keep[lo:hi]
    out[:, :, lo:hi][:, :, sel] = res[:, :, sel].astype(np.float32)
    return out


def gauss3d_reference(video: Any, *, radius: int = 5, temporal_radius: int = 1,
                      sigma_s2: float = 10.0, sigma_t: float = 1.0) -> np.ndarray:
    """Readable definition (float64): loop over the (2r+1)²(2r_t+1) offsets, shifted videos."""
    vid = np.asarray(video, np.float64)
    r_s, r_t, s2, st = _check_gauss(radius, temporal_radius, sigma_s2, sigma_t)
    h, w, t = vid.shape[:3]
    col, valid = _valid_planes(vid)
    num = np.zeros_like(col)
    den = np.zeros(valid.shape)
    for dy in range(-r_s, r_s + 1):
        for dx in range(-r_s, r_s + 1):
            for dt in range(-r_t, r_t + 1):
                rho = math.exp(-0.5 * (dx * dx + dy * dy) / s2 - 0.5 * dt * dt / (st * st))
                ys, yn = slice(max(0, -dy), min(h, h - dy)), slice(max(0, dy), min(h, h + dy))
                xs, xn = slice(max(0, -dx), min(w, w - dx)), slice(max(0, dx), min(w, w + dx))
                ts, tn = slice(max(0, -dt), min(t, t - dt)), slice(max(0, dt), min(t, t + dt))
                vv = valid[yn, xn, tn]
                num[ys, xs, ts] += rho * col[yn, xn, tn] * vv[..., None]
                den[ys, xs, ts] += rho * vv
    return np.divide(num, den[..., None], out=np.zeros_like(num), where=den[..., None] > 0)


@register("gauss3d")
class Gauss3D(Denoiser):
    """Plain 3D Gaussian (x, y, t) without G-buffer terms: the media baseline (docs/methods/jbf.md §1.4)."""

    kinds = {"transient"}
    needs = {"color"}
    defaults = dict(radius=5, temporal_radius=1, sigma_s2=10.0, sigma_t=1.0, skip_empty=True)

    def __init__(self, **params: Any) -> None:
        super().__init__(**params)
        p = self.params
        _check_gauss(p["radius"], p["temporal_radius"], p["sigma_s2"], p["sigma_t"])

    def denoise(self, data: Any) -> np.ndarray:
        video = check_video(data, self.name)
        p = self.params
        return gauss3d(video, radius=p["radius"], temporal_radius=p["temporal_radius"],
                       sigma_s2=p["sigma_s2"], sigma_t=p["sigma_t"], skip_empty=p["skip_empty"])
