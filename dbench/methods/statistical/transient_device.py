"""The transient statistical denoiser on a device (docs/gpu.md §2): the spatio-temporal filter of
:func:`.transient.statistical_filter_video` on a transient :class:`~dbench.device.DeviceFrame`,
the same rules as its Numba path (:func:`.transient.statistical_video_fast`), in PyTorch ops and
one Triton launch (:mod:`dbench.methods.kernels.gpu.window3d`).

Steps, each as the host does it:

* the non-empty bins (any value other than exactly 0, NaN counting as energy) and the bins
  their temporal window reaches, the "bins in play" (:func:`.transient_inputs.bins_in_play`);
* the per-voxel statistics θ̂ = μ + M3/(6σ²n), Var(θ̂) and the rounded n, a voxel whose θ̂,
  Var(θ̂) or n is not finite being "bad": θ̂ NaN there (every test with it fails, so it keeps
  only its own colour), Var 0 (:func:`.transient_inputs.prepare_video`);
* one read-back of seven integers (no image data): the refusals of negative variances or counts
  and the smallest and largest count of the good voxels, all over the bins in play only, which
  resolve γ_t as :func:`.transient._threshold_for` does, the count of bad voxels, of non-empty
  bins and of bins in play;
* the kernel over the non-empty bins only (the others stay 0), with the shrinkage of
  :mod:`.shrink` in its epilogue when it is on;
* the per-pixel total rule of :func:`.shrink.mass_shrink` (:func:`mass_shrink_device`), applied
  by the method as on the host.

Shapes: colour and statistics (H, W, T, 3) tensors (colour float32, statistics float64); the
kernel's layouts (T, H, W, 4) and planes (T, H, W, 4 or 8); output (H, W, T, 3) float32.
"""
from __future__ import annotations

from functools import lru_cache
from typing import Any

from ...errors import DbenchInputError
from ..kernels.bilateral.guide import temporal_factors
from ..kernels.bilateral.params import PLANE_MAX, TEMPORAL_PROFILES
from ..kernels.gpu.guide import E_CUT, make_device_guide
from ..kernels.gpu.bilateral import g2_tensor
from ..kernels.gpu.window3d import window3d_filter
from ..checks import check_choice, check_positive, check_radius
from .device import refuse_negative, _threshold
from .shrink import bias_from_colour, shrink_layout
from .transient import VIDEO_GAMMA, resolve_base, window_size

__all__ = ["bins_in_play_device", "mass_shrink_device", "scale_planes_device",
           "statistical_video_device", "video_planes_device", "video_shape_device",
           "video_stats_device"]


def video_shape_device(color: Any) -> tuple[int, int, int]:
    """(H, W, T) of an (H, W, T, 3) colour tensor, or DbenchInputError naming ``color``."""
    shape = None if color is None else tuple(color.shape)
    if shape is None or len(shape) != 4 or shape[3] != 3 or 0 in shape:
        raise DbenchInputError(f"color: expected shape (H, W, T, 3), got {shape}")
    return shape[0], shape[1], shape[2]


def video_stats_device(stats: Any, h: int, w: int, t: int):
    """(theta, var, n, bad): the statistics of every bin in the kernel's (T, H, W, 3) layout,
    float64, θ̂ = μ + M3/(6σ²n) (correction 0 where that denominator is not > 0), the
    (T, H, W) bool mask of voxels whose θ̂, Var(θ̂) or n is not finite (θ̂ NaN, Var 0 and n 0
    there), as :func:`.transient_inputs.prepare_video` computes them."""
    import torch

    full = (h, w, t, 3)
    if stats is None:
        raise DbenchInputError(f"stats: missing; expected SampleStats with arrays of shape "
                               f"{full}")
    arrs = []
    for name in ("mean", "var_mean", "n", "m3"):
        a = getattr(stats, name)
        if a.ndim == 0:                   # a scalar statistic stands for every voxel
            a = a.expand(full)
        if tuple(a.shape) != full:
            raise DbenchInputError(f"stats.{name}: expected shape {full}, got {tuple(a.shape)}")
        arrs.append(a.to(torch.float64).permute(2, 0, 1, 3))
    mean, var, n, m3 = arrs
    denom = 6.0 * var * n * n
    safe = torch.where(denom > 0, denom, torch.ones_like(denom))
    theta = mean + torch.where(denom > 0, m3 / safe, torch.zeros_like(denom))
    bad = ~(torch.isfinite(theta).all(-1) & torch.isfinite(var).all(-1)
            & torch.isfinite(n).all(-1))
    zero = bad[..., None]
    return (torch.where(zero, float("nan"), theta), torch.where(zero, 0.0, var),
            torch.where(zero, 0.0, n), bad)


def bins_in_play_device(keep: Any, radius_t: int):
    """(T,) bool: the kept bins dilated by r_t (:func:`.transient_inputs.bins_in_play`)."""
    out = keep.clone()
    for k in range(1, min(int(radius_t), keep.shape[0]) + 1):
        out[k:] |= keep[:-k]
        out[:-k] |= keep[k:]
    return out


def video_planes_device(color: Any, theta: Any, var: Any, bad: Any, n_planes: int):
    """(T, H, W, PP) float32 kernel planes of an (H, W, T, 3) colour tensor, PP = 4 for
    ``n_planes`` 4, else 8 (zero-padded): colour·v, v, then for the shrinkage
    (:func:`.shrink.shrink_layout`) θ̄·v (7 planes only), V̄·v and v, θ̄ and V̄ the channel
    means of θ̂ and Var(θ̂) (0 at bad voxels), as :func:`.transient_inputs.prepare_video`
    writes them."""
    import torch

    col = color.to(torch.float32).permute(2, 0, 1, 3)
    v = torch.isfinite(col).all(-1, keepdim=True)
    vf = v.to(torch.float32)
    planes = [torch.where(v, col, 0.0), vf]
    if n_planes > 4:
        good = ~bad[..., None]
        var_bar = torch.where(good, var.sum(-1, keepdim=True) / 3.0, 0.0)
        if n_planes == 7:
            theta_bar = torch.where(good, theta.sum(-1, keepdim=True) / 3.0, 0.0)
            planes.append((theta_bar * vf).to(torch.float32))
        planes += [(var_bar * vf).to(torch.float32), vf]
    out = torch.cat(planes, -1)
    pp = 4 if n_planes == 4 else 8
    return torch.nn.functional.pad(out, (0, pp - out.shape[-1])).contiguous()


def scale_planes_device(planes: Any, in_play: Any):
    """Divide the (T, H, W, PP) ``planes`` in place by per-plane powers of two and return the
    (PP,) float64 factors: a plane whose largest finite |value| over the bins in play exceeds
    :data:`~dbench.methods.kernels.bilateral.params.PLANE_MAX` (a block of colours near the
    float32 maximum, whose float32 window sums would overflow to Inf) is scaled down, the others
    are divided by 1 (unchanged); the factors the host's
    :func:`~dbench.methods.kernels.bilateral.numba3d.accumulate3d` takes for the same planes.
    No read-back: the factors stay on the device."""
    import torch

    peaks = []
    for p in range(planes.shape[-1]):       # one (T, H, W) temporary at a time, not a copy
        a = planes[..., p].abs()
        keep = torch.isfinite(a) & in_play[:, None, None]
        peaks.append(torch.where(keep, a, 0.0).amax())
    peak = torch.stack(peaks).to(torch.float64)
    exps = torch.where(peak > PLANE_MAX, torch.ceil(torch.log2(peak / PLANE_MAX)),
                       torch.zeros_like(peak))
    scale = torch.exp2(exps)
    planes.div_(scale.to(torch.float32))    # exact: powers of two, and 1 for ordinary planes
    return scale.contiguous()


@lru_cache(maxsize=16)
def _tfac(radius_t: int, profile: str, sigma_t: float, device: str):
    """The host's temporal factors (float32, as its kernel takes them) on ``device``, once."""
    import torch
    return torch.as_tensor(temporal_factors(radius_t, profile, sigma_t), dtype=torch.float32,
                           device=device)


def mass_shrink_device(video: Any, color: Any, total_var: Any, h: int, w: int):
    """:func:`.shrink.mass_shrink` on tensors: ((H, W, T, 3) float32 video, (H, W, 3) float64 β),
    float64 sums over the bins, the same branches (a pixel whose noisy total is not finite,
    or whose denoised total is not > 0, keeps the denoiser's total)."""
    import torch

    if total_var is None or tuple(total_var.shape) != (h, w, 3):
        raise DbenchInputError(f"total_var: expected shape ({h}, {w}, 3), got "
                               f"{None if total_var is None else tuple(total_var.shape)}")
    m_d = video.to(torch.float64).sum(2)
    m_n = color.to(torch.float64).sum(2)
    tv = total_var.to(torch.float64)
    v_m = torch.where(torch.isnan(tv), tv, torch.clamp(tv, min=0.0))
    d = m_d - m_n
    den = v_m + d * d
    beta = torch.where(den > 0, v_m / torch.where(den > 0, den, 1.0), 1.0)
    target = m_n + beta * d
    ok = (m_d > 0) & torch.isfinite(target) & torch.isfinite(m_d)
    scale = torch.where(ok, target / torch.where(ok, m_d, 1.0), 1.0)
    return (video.to(torch.float64) * scale[:, :, None, :]).to(torch.float32), beta


def statistical_video_device(frame: Any, *, radius: int, radius_t: int, alpha: float | None,
                             gamma: float | None, base: str, temporal_profile: str | None,
                             sigma_t: float, guide_options: dict, membership_on: bool = True,
                             skip_empty: bool = True, shrink: bool = True) -> tuple[Any, dict]:
    """The spatio-temporal statistical denoiser of a transient
    :class:`~dbench.device.DeviceFrame`: ((H, W, T, 3) float32 tensor on its device, resolved
    settings as :func:`.transient.statistical_filter_video` reports them, backend "triton").
    Parameters as that function's (``guide_options``: sigma, sigma_convention, window,
    hit_mask)."""
    import torch

    h, w, t = video_shape_device(frame.color)
    color = frame.color.to(torch.float32).contiguous()
    dev = color.device
    radius_t = check_radius(radius_t, "radius_t")
    base = resolve_base(base, frame.normal, frame.albedo)
    profile = temporal_profile or ("box" if base == "jbf" else "gaussian")
    check_choice("temporal_profile", profile, TEMPORAL_PROFILES)
    sigma_t = check_positive("sigma_t", sigma_t, allow_inf=True)
    opts = dict(guide_options)
    if base == "gauss3d":        # the plain 3-D Gaussian: the spatial term only, no hit mask
        opts.update(features=("xy",), hit_mask=False)
        guide = make_device_guide(None, None, None, None, shape=(h, w), radius=radius, **opts)
    else:
        guide = make_device_guide(frame.albedo, frame.normal, frame.depth, None, shape=(h, w),
                                  radius=radius, **opts)
    theta, var, n, bad = video_stats_device(frame.stats, h, w, t)
    keep = ((color != 0).permute(2, 0, 1, 3).reshape(t, -1).any(1) if skip_empty
            else torch.ones(t, dtype=torch.bool, device=dev))
    in_play = bins_in_play_device(keep, radius_t)
    ip = in_play[:, None, None]
    nint = torch.clamp(torch.round(n), max=2.0 ** 30).to(torch.int32)
    good = (ip & ~bad)[..., None].expand(t, h, w, 3)
    big = torch.iinfo(torch.int32).max
    # the one read-back of the call (seven integers, no image data), over the bins in play
    neg_var, neg_n, lo, hi, n_bad, n_keep, n_play = torch.stack([
        (ip[..., None] & (var < 0)).any().to(torch.int64),
        (ip[..., None] & (n < 0)).any().to(torch.int64),
        torch.where(good, nint, big).amin().to(torch.int64),
        torch.where(good, nint, -1).amax().to(torch.int64),
        (ip & bad).sum(), keep.sum(), in_play.sum()]).tolist()
    refuse_negative((bool(neg_var), bool(neg_n)))
    if alpha is None and gamma is None:
        gamma = VIDEO_GAMMA
    want_nint = membership_on and gamma is None
    if hi < 0:                    # no good voxel: the host takes the counts {0}
        lo = hi = 0
    if not want_nint:             # the host resolves a table only when the kernel reads it
        hi = lo
    thr, table = _threshold(int(lo), int(hi), alpha, gamma, str(dev))
    shrink = bool(shrink and membership_on)
    n_planes, squared_from, theta_plane = shrink_layout(bias_from_colour(frame.stats.transform))
    if not shrink:
        n_planes, squared_from = 4, None
    out = torch.zeros((h, w, t, 3), dtype=torch.float32, device=dev)
    if n_keep:
        # the non-empty bins in increasing order, without a further synchronisation
        bins = torch.argsort((~keep).to(torch.int32), stable=True)[:n_keep].to(torch.int64)
        test: dict[str, Any] = {}
        if membership_on:
            test = dict(theta=_pad4(theta), var=_pad4(var))
            if thr.table is None:
                test["table"] = g2_tensor(float(thr.g2), str(dev))
            else:
                test.update(nint=_pad4(nint), table=table)
        elif n_bad:
            # plain base filter, bad voxels still isolated: θ NaN there, 0 elsewhere, γ_t = 0
            test = dict(theta=_pad4(theta * 0.0), var=_pad4(torch.zeros_like(var)),
                        table=g2_tensor(0.0, str(dev)))
        planes = video_planes_device(color, theta, var, bad, n_planes)
        scale = scale_planes_device(planes, in_play)
        window3d_filter(guide.feat, guide.labels, planes, scale,
                        _tfac(radius_t, profile, float(sigma_t), str(dev)), bins.contiguous(),
                        out, radius=guide.radius, radius_t=radius_t, inv_x=guide.inv_x,
                        inv_y=guide.inv_y, disk=guide.disk, e_cut=E_CUT,
                        shrink=(0 if not shrink else (1 if theta_plane < 0 else 2)),
                        squared_from=squared_from, **test)
    info = dict(guide.settings, base=base, radius_t=radius_t, temporal_profile=profile,
                sigma_t=sigma_t, window_voxels=window_size(guide.radius, radius_t,
                                                           guide.settings["window"]),
                alpha=thr.alpha, gamma=thr.gamma, gamma_t=thr.gamma_t, nu=thr.nu,
                threshold_source=thr.source, uniform_n=thr.table is None,
                transform=frame.stats.transform, lam=frame.stats.lam,
                membership=bool(membership_on), backend="triton", skip_empty=bool(skip_empty),
                shrink=shrink, bins=t, nonempty_bins=int(n_keep), bins_in_play=int(n_play),
                n_bad_stats=int(n_bad))
    if base == "gauss3d":
        info["features"] = ("xy",)
        info["hit_mask"] = False
    return out, info


def _pad4(a: Any):
    """(T, H, W, 3) → (T, H, W, 4), the 4th channel zero (it passes the test by itself)."""
    import torch
    return torch.nn.functional.pad(a, (0, 1)).contiguous()
