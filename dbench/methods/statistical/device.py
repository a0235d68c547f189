"""The steady statistical denoiser on a device (docs/gpu.md §2): statistics checked and turned
into planes there, the threshold resolved from two integers read back (the smallest and largest
sample count), and the Welch-tested window as one Triton launch (:mod:`dbench.methods.kernels.gpu`).
The same rules as :func:`.dispatch.statistical_filter`: pixels with non-finite θ̂, Var(θ̂) or n
are isolated (their output is their own colour), negative variances or counts are refused."""
from __future__ import annotations

from functools import lru_cache
from typing import Any

from ...errors import DbenchInputError
from ..kernels.gpu.bilateral import window_filter
from ..kernels.gpu.guide import E_CUT, check_tensor, color_planes, depth_or_hit, make_device_guide
from .params import resolve_threshold


def stat_planes_device(stats: Any, h: int, w: int):
    """(theta, var, nint, bad, negative): (H, W, 4) float64, float64, int32 (4th channel 0), the
    (H, W) bool mask of non-finite statistics (zeroed there), as
    :func:`.reference.stat_planes` builds them, and a (2,) bool tensor: any negative variance,
    any negative count (read back by the caller with the sample-count range, in one
    synchronisation)."""
    import torch

    if stats is None:
        raise DbenchInputError(f"stats: missing; expected SampleStats with arrays of shape "
                               f"({h}, {w}, 3)")
    for name in ("mean", "var_mean", "n", "m3"):
        t = getattr(stats, name)
        if tuple(t.shape) != (h, w, 3):
            raise DbenchInputError(f"stats.{name}: expected shape ({h}, {w}, 3), "
                                   f"got {tuple(t.shape)}")
    theta, var, n = stats.theta, stats.var_mean, stats.n
    bad = ~(torch.isfinite(theta).all(-1) & torch.isfinite(var).all(-1)
            & torch.isfinite(n).all(-1))
    zero = bad[..., None]
    theta = torch.where(zero, 0.0, theta)
    var = torch.where(zero, 0.0, var)
    nint = torch.clamp(torch.round(torch.where(zero, 0.0, n)), max=2.0 ** 30).to(torch.int32)
    # (H, W, 4): each pixel's channels one wide load in the kernel; the zero 4th channel
    # passes the test by itself (d = 0)
    padded = [torch.nn.functional.pad(t, (0, 1)).contiguous() for t in (theta, var, nint)]
    return padded[0], padded[1], padded[2], bad, torch.stack([(var < 0).any(), (n < 0).any()])


def refuse_negative(flags: tuple[bool, bool]) -> None:
    """The host's refusals of negative variances or counts, from the flags read back."""
    if flags[0]:
        raise DbenchInputError("stats.var_mean: negative values; expected Var(θ̂) ≥ 0")
    if flags[1]:
        raise DbenchInputError("stats.n: negative sample counts")


@lru_cache(maxsize=32)
def _threshold(lo: int, hi: int, alpha: float | None, gamma: float | None, device: str):
    """The host's :func:`.params.resolve_threshold` for counts ranging over [lo, hi] (it reads
    nothing else of them), with its γ_t² table uploaded to ``device`` once."""
    import numpy as np
    import torch
    thr = resolve_threshold(np.array([lo, hi], np.int64), alpha, gamma)
    table = (None if thr.table is None
             else torch.as_tensor(thr.table, dtype=torch.float64, device=device))
    return thr, table


def statistical_device(frame: Any, *, radius: int, alpha: float | None, gamma: float | None,
                       guide_options: dict, membership_on: bool = True) -> tuple[Any, dict]:
    """The statistical denoiser of a steady :class:`~dbench.device.DeviceFrame`:
    ((H, W, 3) float32 tensor on its device, resolved settings)."""
    import torch

    h, w = frame.shape
    color = check_tensor("color", frame.color, h, w, 3)
    theta, var, nint, bad, negative = stat_planes_device(frame.stats, h, w)
    guide = make_device_guide(frame.albedo, frame.normal, depth_or_hit(frame), frame.position,
                              shape=(h, w), radius=radius, isolate=bad,
                              emitter=getattr(frame, "emitter", None), **guide_options)
    valid = (~bad)[..., None].expand(h, w, 3)
    counts = nint[..., :3]
    big = torch.iinfo(torch.int32).max
    # the one read-back of the call (five integers, no image data): the refusals and the
    # sample-count range that decides the threshold, as the host decides it
    neg_var, neg_n, lo, hi, n_bad = torch.cat([
        negative.to(torch.int64), torch.stack([torch.where(valid, counts, big).amin(),
                                               torch.where(valid, counts, -1).amax(),
                                               bad.sum().to(torch.int32)]).to(torch.int64)
    ]).tolist()
    refuse_negative((bool(neg_var), bool(neg_n)))
    if hi < 0:  # no valid pixel: the host takes the counts {0}
        lo = hi = 0
    thr, table = _threshold(int(lo), int(hi), alpha, gamma, str(color.device))
    planes, scale = color_planes(color)
    out = torch.empty((h, w, 3), dtype=torch.float32, device=color.device)
    test: dict[str, Any] = {}
    if membership_on:
        test = dict(theta=theta, var=var)
        if thr.table is None:
            test["g2"] = thr.g2
        else:
            test.update(nint=nint, table=table)
    window_filter(guide.feat, guide.labels, planes, scale, out, radius=guide.radius,
                  inv_x=guide.inv_x, inv_y=guide.inv_y, disk=guide.disk, e_cut=E_CUT, **test)
    info = dict(guide.settings, alpha=thr.alpha, gamma=thr.gamma, gamma_t=thr.gamma_t,
                nu=thr.nu, threshold_source=thr.source, uniform_n=thr.table is None,
                transform=frame.stats.transform, lam=frame.stats.lam,
                membership=bool(membership_on), backend="triton", n_bad_stats=int(n_bad))
    return out, info
