"""Spatio-temporal statistical denoiser for transient videos (docs/methods/statistical.md §11.3).

θ~_i = Σ_j w_ij L_j,  w_ij = ρ_ij m_ij v_j / Σ_k ρ_ik m_ik v_k,   i, j voxels (y, x, t)

* Window: the full non-separable box of (2r_s+1)² × (2r_t+1) voxels (r_s = 5, r_t = 1 → 363),
  square or disk in space (docs/methods/statistical.md §11.3; :func:`window_size`). The centre voxel (same pixel, same
  bin) always counts; the other bins of the same pixel are ordinary neighbours that must pass
  the test. Bins outside [0, T) are not neighbours (masked like padded pixels), as are pixels
  outside the image.
* Base filter ρ (docs/methods/statistical.md §11.3, docs/methods/jbf.md §1.4), two choices:
  ``"jbf"``: the joint bilateral filter of the ``jbf`` method with its G-buffers replicated along
  time (they are per pixel), times a temporal factor (``temporal_profile`` ``"box"``, the default:
  1 for |τ| ≤ r_t; or ``"gaussian"``: exp(−½τ²/σ_t²));
  ``"gauss3d"``: the plain 3D Gaussian for participating media, ρ = exp(−½(Δx² + Δy²)/σ_s²
  − ½τ²/σ_t²) without G-buffer terms or hit mask, σ_s² from the spatial Σ entries of ``sigma``
  (10 px² by default, the JBF's spatial term) and σ_t = 1 bin (default profile ``"gaussian"``).
* m_ij: the per-channel Welch test of docs/methods/statistical.md §5 on the per-bin statistics, AND over channels (§6).
  Default threshold for videos: γ = 0.1 given directly (γ_t = 2; the upper end of the range
  docs/methods/statistical.md §5.1 / §11.3 recommends, 0.05-0.1: measured better on every rendered scene,
  results/transient_statistical.md §6); ``alpha``
  gives γ_t = t_{1−α/2, ν}, ν = n_i + n_j − 2 (= 2·spp − 2 for rendered videos).
* v_j = 1 where the colour is finite. A voxel whose θ̂, Var(θ̂) or n is not finite has no
  neighbours and is nobody's neighbour (its output is its own colour, as in the steady method).
  A pixel isolated by non-finite G-buffers (jbf base) still mixes with its own other bins:
  the G-buffer terms of a pixel with itself are 0 [dbench].
* Centre-versus-neighbourhood shrinkage (``shrink=True``, the default; [dbench],
  :mod:`dbench.methods.statistical.shrink`): after the seed's weights are summed, the centre
  and the combination of its accepted neighbours are mixed by docs/methods/statistical.md §5's MSE rule once more, so
  a high-variance voxel (a light reached by a few paths) that passed the test against dim
  neighbours keeps the weight its precision earns instead of collapsing onto them.
  ``shrink=False`` is the seed's normalised sum. The inputs (statistics of the bins in play)
  are prepared by :mod:`dbench.methods.statistical.transient_inputs`.
* The sample transform (identity by default for transient data, Yeo-Johnson the alternative;
  docs/methods/statistical.md §3, §11.3) is a property of the statistics, recorded in the info, not chosen here.

Skipping empty bins (``skip_empty=True``, the default) [dbench]: a bin whose colour is exactly
0 at every pixel and channel (no path reached it; NaN counts as energy) comes back as 0 and costs
nothing: only the non-empty bins and their r_t neighbours enter the kernel, and a pair between
two empty bins is never evaluated. Empty bins still serve as neighbours of the non-empty ones
(their voxels are samples of g(0) with variance 0), so the non-empty bins get exactly the values
of the full filter; only the empty bins differ (the full filter could leak energy into them from
the neighbouring bins; 0 is what the data says). ``skip_empty=False`` filters every bin.

Implementations: :func:`statistical_video_reference` (readable NumPy float64, loop over the 3D
offsets on whole shifted videos) and :func:`statistical_video_fast` (the shared Numba kernel
:func:`dbench.methods.kernels.bilateral.numba3d.accumulate3d`: float32 weights, float64 Welch
test identical to the reference's, symmetric pairs, spatial weights computed once per row and
reused by every bin). They agree to 1e-5 relative (tests). On a GPU the method runs
:mod:`dbench.methods.statistical.transient_device` (docs/gpu.md §2), equal to the Numba path
within the same tolerance.

Shapes: colour and statistics (H, W, T, 3); G-buffers (H, W, ·); outputs (H, W, T, 3) float32.

Example:
    >>> import numpy as np
    >>> from dbench.data import SampleStats
    >>> rng = np.random.default_rng(0)
    >>> y = rng.normal(1.0, 1.0, size=(8, 8, 6, 3, 32))
    >>> st = SampleStats(n=32.0, mean=y.mean(-1), var_mean=y.var(-1, ddof=1) / 32,
    ...                  m3=((y - y.mean(-1, keepdims=True)) ** 3).mean(-1), transform="identity")
    >>> out, info = statistical_filter_video(y.mean(-1), st, base="gauss3d", radius=2,
    ...                                      return_info=True)
    >>> out.shape, info["gamma_t"], info["window_voxels"]
    ((8, 8, 6, 3), 2.0, 75)
"""
from __future__ import annotations

from typing import Any, Sequence

import numpy as np

from ...data import check_buffer
from ..checks import check_choice, check_positive, check_radius
from ..kernels.bilateral.guide import Guide, make_guide, temporal_factors, window_offsets
from ..kernels.bilateral.numba3d import accumulate3d
from ..kernels.bilateral.params import SEED_SIGMA, TEMPORAL_PROFILES
from ..kernels.bilateral.reference import reference_weights, shift_slices
from .params import Threshold, resolve_threshold
from .reference import welch_pass
from .shrink import bias_from_colour, merge_shrink3d, shrink_layout, shrink_reference
from .transient_inputs import (VideoStats, bins_in_play, nonempty_bins, prepare_video,
                               video_shape, video_stats)

#: Defaults for videos (docs/methods/statistical.md §7 "Radius defaults", §5.1 "Transient default", §11.3).
VIDEO_RADIUS = 5
VIDEO_RADIUS_T = 1
VIDEO_GAMMA = 0.1
#: Optical path length (m) the automatic temporal radius covers on each side of a bin, and its
#: cap (:func:`auto_radius_t`).
AUTO_RT_OPL = 0.02
AUTO_RT_MAX = 3
BASES = ("jbf", "gauss3d")
VIDEO_BACKENDS = ("auto", "numba", "reference")

__all__ = ["auto_radius_t", "AUTO_RT_OPL", "VideoStats", "video_stats", "nonempty_bins",
           "bins_in_play", "window_size",
           "make_video_guide", "resolve_base", "prepare_video", "statistical_video_reference",
           "statistical_video_fast", "statistical_filter_video", "BASES", "VIDEO_RADIUS",
           "VIDEO_RADIUS_T", "VIDEO_GAMMA"]


def window_size(radius: int, radius_t: int, window: str = "square") -> int:
    """Voxels in the 3D window, centre included: (2r_s+1)²(2r_t+1) for the square window
    (docs/methods/statistical.md §11.3 / §13 check 15: r_s = 5, r_t = 1 → 363; r_s = 20, r_t = 1 → 5043)."""
    dy, _ = window_offsets(radius, window)
    return int(dy.size) * (2 * check_radius(radius_t, "radius_t") + 1)


def auto_radius_t(bin_width_opl: float | None) -> int:
    """The temporal radius that follows the bin width: r_t = min(3, ⌊20 mm / Δ⌋) for bins of
    optical path length Δ (m); the spec default 1 when Δ is unknown.

    Why (results/transient_statistical.md §6.5, seed Fig. 5.5 and docs/methods/statistical.md §11.3 "the temporal
    radius matters most for narrow bins (8 ps), little at 83 ps and not at 833 ps"): on
    cornell-transient at 256 spp, r_t = 0 was the best or within 0.003 of it for bins of 248,
    77 and 25 mm, and r_t = 2-3 the best for 7.7 mm bins. At the catalogue's 200-bin windows
    (31-52 mm bins) r_t = 0 beat r_t = 1 in 7 of 12 scene × spp cells over all voxels and in 8
    of 12 on the time-integrated image (2 ties), by up to 0.20 of the noisy error; caustic at
    16-256 spp preferred r_t = 1 (by up to 0.055). A neighbouring bin is a sample of the same
    signal only while the signal changes little over the bin gap; 20 mm of path (67 ps) is
    where that stopped holding in these measurements.
    """
    if bin_width_opl is None:
        return VIDEO_RADIUS_T
    width = float(bin_width_opl)
    if not (np.isfinite(width) and width > 0):
        return VIDEO_RADIUS_T
    return int(min(AUTO_RT_MAX, np.floor(AUTO_RT_OPL / width + 1e-9)))


def resolve_base(base: str, normal: Any = None, albedo: Any = None) -> str:
    """``"auto"`` → ``"jbf"`` when the frame has albedo and normal G-buffers, else ``"gauss3d"``.

    The seed uses the plain 3D Gaussian for participating media (docs/methods/statistical.md §11.3). dbench's media
    scenes are rooms with fog or a cloud in front of surfaces whose G-buffers (rendered without
    the medium) still mark the geometric edges, and there the JBF base is better at every spp
    (results/transient_statistical.md §6: fog-transient, whole-video RMSE 0.61-0.75× the
    noisy input's with the JBF base against 0.72-1.08× with gauss3d); a medium no longer
    decides the base by itself."""
    check_choice("base", base, ("auto",) + BASES)
    if base != "auto":
        return base
    return "gauss3d" if (normal is None or albedo is None) else "jbf"


def make_video_guide(base: str, shape: tuple[int, int], albedo: Any = None, normal: Any = None,
                     depth: Any = None, position: Any = None, *, radius: int = VIDEO_RADIUS,
                     sigma: Sequence[float] = SEED_SIGMA, sigma_convention: str = "variance",
                     window: str = "square", hit_mask: bool = True,
                     features: Sequence[str] = ("xy", "albedo", "normal")) -> Guide:
    """The spatial part of the base filter: the JBF guide (``"jbf"``) or, for ``"gauss3d"``,
    a guide with the ``"xy"`` feature only (σ_s² = sigma[0], sigma[1] in ``sigma_convention``)
    and no hit mask (docs/methods/jbf.md §1.4)."""
    check_choice("base", base, BASES)
    if base == "gauss3d":
        return make_guide(None, None, None, radius=radius, sigma=sigma,
                          sigma_convention=sigma_convention, window=window, features=("xy",),
                          hit_mask=False, shape=shape)
    return make_guide(albedo, normal, depth, position, radius=radius, sigma=sigma,
                      sigma_convention=sigma_convention, window=window, hit_mask=hit_mask,
                      features=features, shape=shape)


# ---------------------------------------------------------------------------------------------
# Reference (dense NumPy, float64)
# ---------------------------------------------------------------------------------------------

def statistical_video_reference(color: Any, vs: VideoStats, guide: Guide, tfac: np.ndarray,
                                threshold: Threshold, *, membership_on: bool = True,
                                keep: np.ndarray | None = None, shrink: bool = False,
                                return_weights: bool = False):
    """Readable spatio-temporal statistical denoiser (docs/methods/statistical.md §11.3), float64.

    Loops over the (spatial offset o, temporal offset τ) of the window and accumulates whole
    shifted videos: ρ from
    :func:`~dbench.methods.kernels.bilateral.reference.reference_weights` (the JBF's own
    code) times tfac[τ], m from the per-channel Welch predicate (centre voxel: m = 1), v from the
    colour's finiteness; voxels with bad statistics only keep their centre.

    Args:
        color: (H, W, T, 3) linear noisy video.
        vs: :class:`VideoStats` of all T bins, channel-last
            (``video_stats(..., channel_first=False)``).
        guide: spatial base filter; tfac: (2r_t+1,) temporal factors.
        keep: (T,) bool bins whose output is wanted (the others come back as 0), or None (all).
        return_weights: also return the (O, H, W, T) normalised weights of every 3D offset (the
            offsets in the order spatial offset × τ) and the memberships.

    Returns:
        (H, W, T, 3) float64 (and the weights, memberships).
    """
    h, w, t = video_shape(color)
    col = check_buffer("color", color, (h, w, t, 3), dtype=np.float64)
    valid = np.all(np.isfinite(col), axis=-1)
    col = np.where(valid[..., None], col, 0.0)
    theta, var, nint, good = vs.theta, vs.var, vs.nint.astype(np.int64), ~vs.bad
    tfac = np.asarray(tfac, np.float64)
    r_t = (len(tfac) - 1) // 2
    num = np.zeros((h, w, t, 3))
    den = np.zeros((h, w, t))
    centre_w = np.zeros((h, w, t))
    theta_num, var2_num, w2_num = (np.zeros((h, w, t)) for _ in range(3))
    # the bias of the shrinkage is measured on the colour for the identity transform (shrink)
    theta_bar = col.mean(-1) if bias_from_colour(vs.transform) else theta.mean(-1)
    var_bar = var.mean(-1)
    stack, members = [], []
    for k in range(len(guide.dy)):
        dy, dx = int(guide.dy[k]), int(guide.dx[k])
        (ys, xs), (yn, xn) = shift_slices(dy, dx, h, w)
        rho_s = reference_weights(guide, k)
        for tau in range(-r_t, r_t + 1):
            ts = slice(max(0, -tau), max(0, min(t, t - tau)))
            tn = slice(ts.start + tau, ts.stop + tau)
            m = np.zeros((h, w, t), bool)
            inside = ys.start < ys.stop and xs.start < xs.stop and ts.start < ts.stop
            if dy == 0 and dx == 0 and tau == 0:
                m[:] = True                                    # the centre always counts
            elif inside:
                ok = good[ys, xs, ts] & good[yn, xn, tn]
                if membership_on:
                    d = theta[ys, xs, ts] - theta[yn, xn, tn]
                    s = var[ys, xs, ts] + var[yn, xn, tn]
                    g2 = threshold.g2_for(nint[ys, xs, ts] + nint[yn, xn, tn] - 2)
                    ok &= np.all(welch_pass(d, s, g2), axis=-1)
                m[ys, xs, ts] = ok
            wk = rho_s[..., None] * tfac[tau + r_t] * m
            if inside:
                wk[ys, xs, ts] *= valid[yn, xn, tn]
                num[ys, xs, ts] += wk[ys, xs, ts, None] * col[yn, xn, tn]
                if shrink and not (dy == 0 and dx == 0 and tau == 0):
                    wn = wk[ys, xs, ts]
                    theta_num[ys, xs, ts] += wn * theta_bar[yn, xn, tn]
                    var2_num[ys, xs, ts] += wn * wn * var_bar[yn, xn, tn]
                    w2_num[ys, xs, ts] += wn * wn
            if dy == 0 and dx == 0 and tau == 0:
                centre_w = wk.copy()
            den += wk
            if return_weights:
                stack.append(wk)
                members.append(m)
    out = np.divide(num, den[..., None], out=np.zeros_like(num), where=den[..., None] > 0)
    if shrink and membership_on:
        # neighbour sums without the centre term (its weight is v_i), spec: shrink module
        out = shrink_reference(col, theta_bar, var_bar, valid, num - centre_w[..., None] * col,
                               den - centre_w, theta_num, var2_num, w2_num)
    if keep is not None:
        out[:, :, ~np.asarray(keep, bool)] = 0.0
    if return_weights:
        ws = np.stack(stack)
        return out, np.divide(ws, den, out=np.zeros_like(ws), where=den > 0), np.stack(members)
    return out


# ---------------------------------------------------------------------------------------------
# Fast path (Numba, the shared 3D kernel)
# ---------------------------------------------------------------------------------------------

def _threshold_for(alpha: float | None, gamma: float | None, n_range: tuple[int, int],
                   vs: VideoStats | None) -> Threshold:
    """γ_t from γ (wins; both None → γ = VIDEO_GAMMA) or from α and ν = n_i + n_j − 2
    (docs/methods/statistical.md §5.1)."""
    if alpha is None and gamma is None:
        gamma = VIDEO_GAMMA
    if gamma is not None:
        return resolve_threshold(np.zeros(1, np.int32), alpha, gamma)
    lo, hi = n_range
    if lo == hi or vs is None or vs.nint is None:
        return resolve_threshold(np.full(1, max(lo, 0), np.int32), alpha)
    return resolve_threshold(vs.nint, alpha, valid=np.broadcast_to(~vs.bad[:, None],
                                                                    vs.nint.shape))


def statistical_video_fast(color: Any, stats: Any, guide: Guide, tfac: np.ndarray, *,
                           alpha: float | None = None, gamma: float | None = None,
                           membership_on: bool = True, keep: np.ndarray | None = None,
                           shrink: bool = False, return_info: bool = False):
    """Numba spatio-temporal statistical denoiser: (H, W, T, 3) float32.

    Only the ``keep`` bins (default all) and their r_t neighbours are prepared and enter the
    kernel (:func:`prepare_video`, :func:`dbench.methods.kernels.bilateral.numba3d.accumulate3d`);
    the other bins come back as 0. Threshold as :func:`statistical_filter_video`. With
    ``return_info`` also (threshold, VideoStats, bins in play).
    """
    h, w, t = video_shape(color)
    tfac = np.asarray(tfac, np.float64)
    r_t = (len(tfac) - 1) // 2
    keep = np.ones(t, bool) if keep is None else np.asarray(keep, bool)
    idx = np.flatnonzero(bins_in_play(keep, r_t))
    out = np.zeros((h, w, t, 3), np.float32)
    want_nint = membership_on and gamma is None and alpha is not None
    shrink = bool(shrink and membership_on)
    n_planes, squared_from, theta_plane = shrink_layout(
        bias_from_colour(getattr(stats, "transform", "unknown")))
    planes, vs, n_range = prepare_video(color, stats, idx, want_stats=True, want_nint=want_nint,
                                        n_planes=n_planes if shrink else 4)
    thr = _threshold_for(alpha, gamma, n_range, vs)
    if idx.size:
        test: dict[str, Any] = {}
        any_bad = bool(vs.bad.any())
        if membership_on:
            test = dict(theta=vs.theta, var=vs.var)           # θ̂ is NaN at bad voxels
            if thr.table is None:
                test["g2"] = thr.g2
            else:
                test.update(nint=vs.nint, g2_table=thr.table)
        elif any_bad:
            # plain base filter, bad voxels still isolated: θ = NaN there, 0 elsewhere, γ_t = 0
            theta = vs.theta * 0.0
            test = dict(theta=theta, var=np.zeros_like(theta), g2=0.0)
        if shrink:
            acc, band, scale = accumulate3d(guide, planes, tfac, idx, keep[idx], n_bins=t,
                                            squared_from=squared_from, bands=True, **test)
            merge_shrink3d(acc, band, scale, planes, keep[idx], idx, theta_plane, out)
        else:
            accumulate3d(guide, planes, tfac, idx, keep[idx], n_bins=t, normalise_into=out,
                         **test)
    if return_info:
        return out, (thr, vs, idx)
    return out


# ---------------------------------------------------------------------------------------------
# Public entry point
# ---------------------------------------------------------------------------------------------

def statistical_filter_video(color: Any, stats: Any, albedo: Any = None, normal: Any = None,
                             depth: Any = None, position: Any = None, *,
                             radius: int = VIDEO_RADIUS, radius_t: int = VIDEO_RADIUS_T,
                             alpha: float | None = None, gamma: float | None = None,
                             base: str = "jbf", temporal_profile: str | None = None,
                             sigma_t: float = 1.0, sigma: Sequence[float] = SEED_SIGMA,
                             sigma_convention: str = "variance", window: str = "square",
                             hit_mask: bool = True,
                             features: Sequence[str] = ("xy", "albedo", "normal"),
                             membership_on: bool = True, skip_empty: bool = True,
                             shrink: bool = True,
                             backend: str = "auto",
                             return_info: bool = False):
    """Statistical denoiser of docs/methods/statistical.md §11.3 on an (H, W, T, 3) video.

    Args:
        color: (H, W, T, 3) linear noisy video (the values that are filtered).
        stats: SampleStats of shape (H, W, T, 3): per-bin statistics of the transformed per-path
            bin sums (docs/methods/statistical.md §11.1).
        albedo, normal, depth, position: (H, W, ·) G-buffers of the ``"jbf"`` base (ignored by
            ``"gauss3d"``).
        radius, radius_t: r_s (default 5) and r_t (default 1) of the (2r_s+1)²(2r_t+1) window.
        alpha, gamma: test level (γ_t = t_{1−α/2, n_i+n_j−2}) or threshold given directly
            (``gamma`` wins when both are given; both None: γ = 0.1, γ_t = 2; docs/methods/statistical.md §5.1).
        base: ``"jbf"`` (G-buffers replicated along time), ``"gauss3d"`` (plain 3D Gaussian,
            media) or ``"auto"`` (:func:`resolve_base` from the G-buffers).
        temporal_profile: ``"box"`` or ``"gaussian"`` (σ_t = ``sigma_t`` bins); None = box for
            the jbf base, gaussian for gauss3d (docs/methods/jbf.md §1.4).
        sigma, sigma_convention, window, hit_mask, features: the spatial base filter as in
            docs/methods/jbf.md (gauss3d uses the spatial Σ entries only).
        membership_on: False gives the plain 3D base filter (ablation).
        skip_empty: bins without energy cost nothing and return 0 (module docstring).
        shrink: the centre-versus-neighbourhood shrinkage of
            :mod:`dbench.methods.statistical.shrink` (default); False gives the seed's
            normalised sum. Ignored with ``membership_on=False``.
        backend: ``"auto"``/``"numba"`` (fast path) or ``"reference"`` (float64 NumPy).
        return_info: also return the resolved settings (γ_t, ν, window, bins filtered, ...).

    Returns:
        (H, W, T, 3) float32 (and the info dict).
    """
    h, w, t = video_shape(color)
    check_choice("backend", backend, VIDEO_BACKENDS)
    radius_t = check_radius(radius_t, "radius_t")
    base = resolve_base(base, normal, albedo)
    profile = temporal_profile or ("box" if base == "jbf" else "gaussian")
    check_choice("temporal_profile", profile, TEMPORAL_PROFILES)
    sigma_t = check_positive("sigma_t", sigma_t, allow_inf=True)
    tfac = temporal_factors(radius_t, profile, sigma_t)
    guide = make_video_guide(base, (h, w), albedo, normal, depth, position, radius=radius,
                             sigma=sigma, sigma_convention=sigma_convention, window=window,
                             hit_mask=hit_mask, features=features)
    keep = nonempty_bins(color) if skip_empty else np.ones(t, bool)
    if backend == "reference":
        vs = video_stats(stats, (h, w, t), channel_first=False)
        if alpha is None and gamma is None:
            gamma = VIDEO_GAMMA
        thr = resolve_threshold(vs.nint, alpha, gamma,
                                valid=np.broadcast_to(~vs.bad[..., None], vs.nint.shape))
        out = statistical_video_reference(color, vs, guide, tfac, thr, membership_on=membership_on,
                                          keep=keep, shrink=shrink).astype(np.float32)
        idx = np.flatnonzero(bins_in_play(keep, radius_t))
    else:
        out, (thr, vs, idx) = statistical_video_fast(color, stats, guide, tfac, alpha=alpha,
                                                     gamma=gamma, membership_on=membership_on,
                                                     keep=keep, shrink=shrink,
                                                     return_info=True)
    if not return_info:
        return out
    info = dict(guide.settings, base=base, radius_t=radius_t, temporal_profile=profile,
                sigma_t=sigma_t, window_voxels=window_size(guide.radius, radius_t, guide.window),
                alpha=thr.alpha, gamma=thr.gamma, gamma_t=thr.gamma_t, nu=thr.nu,
                threshold_source=thr.source, uniform_n=thr.table is None,
                transform=vs.transform, lam=vs.lam, membership=bool(membership_on),
                backend="reference" if backend == "reference" else "numba",
                skip_empty=bool(skip_empty), shrink=bool(shrink and membership_on), bins=t,
                nonempty_bins=int(keep.sum()),
                bins_in_play=int(idx.size), n_bad_stats=int(vs.bad.sum()))
    if base == "gauss3d":
        info["features"] = ("xy",)
        info["hit_mask"] = False
    return out, info
