"""``bmfr`` on a device (the per-frame steps of :meth:`dbench.methods.bmfr.BMFR._denoise`), every
step a Triton kernel on the frame's tensors (:mod:`dbench.methods.kernels.gpu.bmfr`,
:mod:`dbench.methods.kernels.gpu.handback`):

=====================================  ======================================================
launch                                 host step
=====================================  ======================================================
``strata_kernel`` + 3 × ``atrous``     gradient_history's strata (a ``gradient`` buffer,
(temporal_gradient, from frame 2)      ``temporal_gradient=True``, a previous frame)
``reproject_kernel``                   frame_geometry, History.fetch
``bmfr_accumulate_kernel``             prepare, _alphas, accumulation 1 (+ emission),
                                       moments_fast's z² and Σw²
``bmfr_fit_kernel`` (a program/block)  bmfr_fit_fast: features, noise, Householder QR, recon
``handback_low_kernel`` (hand-back)    moments_fast's var(z), the residual's local mean
``handback_energy_kernel`` (hand-back) high², the signed rule's ratios
``bmfr_finish_kernel``                 handback's λ and output, accumulation 2, remodulate
``taa_kernel`` (``taa=True``)          _with_taa
=====================================  ======================================================

Six launches per frame with the default hand-back (four with ``handback="none"``), plus four
for the gradient's strata and one for TAA. The history stays on the device: two alternating
(5 + 15, H, W) buffers of a :class:`~dbench.methods.temporal.device.DeviceHistory` (z 3, N, the
accumulated fit 3, z² 3, Σw², emission 3, a validity plane the reprojection reads as "usable",
the host's ``valid = hit & (filled | recon)``).

Parameters on the device: every default and ``features`` in "paper", "seed", "normals",
"positions"; block_size, noise_amount, offsets, alpha1, alpha2, clamp_negative, rcond, seed,
temporal_gradient, tau_d, tau_n, handback (all three), taa, taa_alpha, albedo_floor, preset
"paper". Not ported (``runs_on_device`` is False, they run on the host): ``samples`` (so
preset "seed") and the features reading ``reflected_normal``/``geo_normal`` ("reflected",
"paper+geo", "reflected+geo"); and block_size above 64 (the block's matrix is one program's
registers). ``last`` holds ``dropped`` (a 0-d int tensor), ``offset``, ``n1``, ``n2``,
``status`` and ``gradient`` (a tensor, or None without the gradient step), tensors valid until
the next call.
"""
from __future__ import annotations

from typing import Any

import triton

from ..kernels.gpu.bmfr import (PLANES, VALID_PLANE, bmfr_accumulate_kernel, bmfr_finish_kernel,
                                bmfr_fit_kernel)
from ..kernels.gpu.handback import handback_energy_kernel, handback_low_kernel
from ..kernels.gpu.runtime import cdiv, on_gpu_layout
from ..kernels.gpu.temporal import BASE, block_for, reproject_kernel
from ..temporal.device import DeviceHistory, camera_origin, device_buffer, sequence_buffers

#: Feature presets the fit kernel builds (columns 1, n, p, p² present or not).
DEVICE_FEATURES = {"paper": (1, 1, 1), "seed": (1, 1, 0), "normals": (1, 0, 0),
                   "positions": (0, 1, 0)}
#: The largest block the fit kernel holds (B² rows × 16 float64 columns per program).
MAX_DEVICE_BLOCK = 64


def device_refusal(params: dict) -> str:
    """Why these parameters do not run on the device ("" when they do)."""
    if params["samples"] is not None:
        return "samples (preset 'seed')"
    if params["features"] not in DEVICE_FEATURES:
        return f"features={params['features']!r}"
    if int(params["block_size"]) > MAX_DEVICE_BLOCK:
        return f"block_size > {MAX_DEVICE_BLOCK}"
    return ""


def _origins(n: int, block: int, off: int) -> tuple[int, int]:
    """(first block start, count) along an axis of length n (block_origins' rule)."""
    starts = [off + j * block for j in range(-2, n // block + 3)
              if off + (j + 1) * block > 0 and off + j * block < n]
    return starts[0], len(starts)


def bmfr_device(method: Any, frame: Any):
    """One frame of ``bmfr`` (the instance ``method``; its device history lives in
    ``method._device_history``) on a :class:`~dbench.device.DeviceFrame`: (H, W, 3) tensor."""
    import torch

    from ...errors import DbenchInputError

    p = method.params
    why = device_refusal(p)
    if why:
        raise DbenchInputError(f"bmfr: {why} has no device path; run it on the host (denoise)")
    h, w, b = sequence_buffers(frame, ("color", "albedo", "depth", "normal", "position",
                                       "motion", "emission"))
    color, albedo, depth, normal, position, motion, emission = (
        b["color"], b["albedo"], b["depth"], b["normal"], b["position"], b["motion"],
        b["emission"])
    origin = camera_origin(frame.meta)
    dev = color.device
    emissive = emission is not None
    hb = p["handback"] != "none"
    r = 14 if emissive else (11 if hb else 7)
    layout = ("bmfr", emissive, hb)

    hist = getattr(method, "_device_history", None)
    if hist is None:
        hist = method._device_history = DeviceHistory(PLANES, p["tau_d"], p["tau_n"])
    prev, new = hist.begin(h, w, dev)
    blk = block_for(h * w, dev)
    grid = (cdiv(h * w, blk),)

    # A-SVGF's adaptive history (gradient_history, mode "seed") when the frame has re-shaded
    # samples; G = 0 without a previous frame or motion (grad 1)
    grad, low = 0, new
    g_img = hist.work("gradient", (h, w))
    if p["temporal_gradient"] and frame.buffers.get("gradient") is not None:
        grad = 1
        if hist.has_prev and motion is not None:
            from ..kernels.gpu.asvgf import gradient_strata
            from ..svgf.params import EPS_Z
            g_buf = device_buffer(frame, "gradient", h, w, 3)
            low = gradient_strata(hist, prev, g_buf, 3, "seed", 1.0, 128.0, EPS_Z)
            grad = 2

    # the reprojection (DeviceHistory.reproject with BMFR's validity plane as "usable")
    flag = hist.taa_flag(bool(p["taa"]), dev)
    fetched = hist.work("fetched", (r, h, w))
    status = hist.work("status", (h, w), torch.uint8)
    has = hist.has_prev and motion is not None and hist.layout == layout
    o = hist.origin if has else None
    par = hist.params()
    reproject_kernel[grid](
        depth, normal, position, motion if motion is not None else normal, prev, new, fetched,
        status, flag if flag is not None else par, par, *(o if o is not None else (0.0, 0.0, 0.0)),
        h, w, HAS_HIST=bool(has), HAS_ORIGIN=o is not None, R=r, RP=triton.next_power_of_2(r),
        N_PLANE=VALID_PLANE, FLAG=flag is not None, BLOCK=blk)

    illum = hist.work("illum", (3, h, w))
    flags = hist.work("flags", (h, w), torch.uint8)
    a2 = hist.work("alpha2", (h, w))
    nu = hist.work("n-used", (h, w))
    floor = float(p["albedo_floor"])
    bmfr_accumulate_kernel[grid](
        color, albedo, emission if emissive else color, motion if motion is not None else color,
        fetched, status, new, low, illum, flags, a2, g_img, floor, float(p["alpha1"]),
        float(p["alpha2"]), 256.0, h, w, -(-w // 3), nu, EMISSIVE=emissive, HB=hb, GRAD=grad,
        BLOCK=blk)

    # the block fit: this frame's grid offset, the noise seed of the host
    block = int(p["block_size"])
    k = method.frame_index
    off_x, off_y = (int(v) for v in method.grid[k % len(method.grid)].tolist())
    y0, nby = _origins(h, block, off_y)
    x0, nbx = _origins(w, block, off_x)
    noise_seed = (int(p["seed"]) * 1_000_003 + k) & 0x7FFFFFFFFFFFFFFF
    y_fit = hist.work("fit", (3, h, w))
    dropped = hist.work("dropped", (nby * nbx,), torch.int32)
    nn, npos, nsq = DEVICE_FEATURES[p["features"]]
    z_acc = new[BASE:BASE + 3]
    meta = dict(B=block, BP=triton.next_power_of_2(block * block), NN=nn, NP=npos, NP2=nsq,
                NOISE=float(p["noise_amount"]) > 0, CLAMP=bool(p["clamp_negative"]))
    if on_gpu_layout(dev):
        meta["num_warps"] = 16 if block > 16 else 4
    bmfr_fit_kernel[(nby * nbx,)](
        z_acc, normal, position, flags, y_fit, dropped, h, w, y0, x0, nbx,
        noise_seed & 0xFFFFFFFF, noise_seed >> 32, 2.0 * float(p["noise_amount"]),
        float(p["rcond"]), **meta)

    var = low_hb = hh = qq = y_fit
    signed = p["handback"] == "signed"
    if hb:
        g64 = hist._work.get("hb-taps")
        if g64 is None:  # the 7 Gaussian taps, once per size and device
            from ..kernels.residual_handback import handback_taps
            g64 = hist._work["hb-taps"] = torch.tensor(
                [float(v) for v in handback_taps()], dtype=torch.float64, device=dev)
        var = hist.work("hb-var", (3, h, w))
        low_hb = hist.work("hb-low", (3, h, w))
        hh = hist.work("hb-hh", (3, h, w))
        qq = hist.work("hb-q", (3, h, w)) if signed else hh
        handback_low_kernel[grid](illum, z_acc, new[BASE + 7:BASE + 10], new[BASE + 10],
                                  y_fit, flags, g64, var, low_hb, h, w, BLOCK=blk)
        handback_energy_kernel[grid](z_acc, y_fit, var, low_hb, flags, hh, qq, h, w,
                                     SIGNED=signed, BLOCK=blk)
    out = torch.empty((h, w, 3), dtype=torch.float32, device=dev)
    n2 = hist.work("n2", (h, w))
    bmfr_finish_kernel[grid](
        y_fit, z_acc, var, low_hb, hh, qq, flags, fetched, a2, nu, new, albedo, out, n2, floor,
        h, w, HB=hb, SIGNED=signed, CLAMP=bool(p["clamp_negative"]), EMISSIVE=emissive,
        BLOCK=blk)
    hist.commit(origin, layout)
    method.frame_index += 1
    method.last = {"gradient": g_img if grad else None, "dropped": dropped.sum(),
                   "offset": (off_x, off_y), "n1": new[BASE + 3], "n2": n2, "status": status}
    if p["taa"]:
        out = hist.taa(out, motion, float(p["taa_alpha"]), flag)
    return out


__all__ = ["DEVICE_FEATURES", "MAX_DEVICE_BLOCK", "bmfr_device", "device_refusal"]
