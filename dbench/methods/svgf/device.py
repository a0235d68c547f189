"""``svgf`` and ``asvgf`` on a device (docs/temporal.md §3, §4, §12-§18; the per-frame steps of
:meth:`dbench.methods.svgf._SVGFBase._denoise`), every step a Triton kernel on the frame's
tensors (:mod:`dbench.methods.kernels.gpu`):

===========================================  ================================================
launch                                       host step
===========================================  ================================================
``strata_kernel`` + ``gradient_iterations``  A-SVGF: stratum_gradients, filter_gradients
× ``atrous_kernel`` (A-SVGF, from frame 2)
``reproject_kernel``                         frame_geometry, History.fetch
``temporal_kernel``                          prepare, adaptive_history, accumulate (colour,
                                             moments, emission), frame_count, variance
``variance_kernel``                          spatial_variance, boost_spatial, boost_all
``iterations`` × ``atrous_kernel``           atrous (the last also remodulates; one with
(at least one)                               ``feedback_tap`` writes the history's colour)
``taa_kernel`` (``taa=True``)                _with_taa
===========================================  ================================================

The history stays on the device: two alternating (16, H, W) buffers (geometry 4, raw luminance,
colour 3, moments 2, N, Σw², emission 3, frame count) of a
:class:`~dbench.methods.temporal.device.DeviceHistory`. Shapes: the frame's buffers (H, W, C)
float32 tensors; the output (H, W, 3) float32. ``last`` holds ``n``, ``alpha``, ``variance``,
``status``, ``weight_sq``, ``frames`` (A-SVGF's count or None), ``iterations`` and for A-SVGF
``gradient``, tensors valid until the next call. Every parameter of the host path is honoured.
"""
from __future__ import annotations

from typing import Any

from ..kernels.gpu.asvgf import gradient_strata
from ..kernels.gpu.runtime import cdiv
from ..kernels.gpu.svgf import atrous_kernel, temporal_kernel, variance_kernel
from ..kernels.gpu.temporal import BASE, block_for
from ..temporal.device import DeviceHistory, camera_origin, device_buffer, sequence_buffers
from .params import ALPHA0_PAPER, EPS_Z, auto_iterations

#: history planes after the base: colour 3, moments 2, N, Σw², emission 3, frame count
PLANES = 11
_GMODE = {"seed": 0, "filtered": 1, "filtered_abs": 1, "paper": 2}


def _boost_code(boost: Any, counting: bool) -> int:
    """variance_kernel's BOOST for the ``variance_boost`` parameter."""
    if boost is False:
        return 0
    if boost == "asvgf":
        return 2
    if boost == "gradient" and counting:
        return 3
    return 1  # "svgf", and "gradient" without A-SVGF's frame count


def svgf_device(method: Any, frame: Any):
    """One frame of ``svgf``/``asvgf`` (the instance ``method``; its device history lives in
    ``method._device_history``) on a :class:`~dbench.device.DeviceFrame`: (H, W, 3) tensor."""
    import torch

    p = method.params
    asvgf = hasattr(method, "n_max")
    h, w, b = sequence_buffers(frame, ("color", "albedo", "depth", "normal", "position",
                                       "motion", "emission"))
    color, albedo, depth, normal, position, motion, emission = (
        b["color"], b["albedo"], b["depth"], b["normal"], b["position"], b["motion"],
        b["emission"])
    nb = p["normal_buffer"]
    wsrc = None if nb == "normal" else device_buffer(
        frame, nb, h, w, 3, why=f", and normal_buffer={nb!r} needs it; the sequence scenes' PSR "
        "G-buffers (gbuffer=psr or psr-glossy) provide it")
    origin = camera_origin(frame.meta)
    dev = color.device
    emissive = emission is not None
    counting = bool(method.counts_frames)
    r = 7 + 3 * emissive + counting

    hist = getattr(method, "_device_history", None)
    if hist is None:
        hist = method._device_history = DeviceHistory(PLANES, p["tau_d"], p["tau_n"])
    prev, new = hist.begin(h, w, dev)
    n_max = float(method.n_max) if asvgf else 256.0
    par = hist._work.get(f"svgf-par-{n_max!r}")
    if par is None:  # two host floats (n_max, A-SVGF's α0) on the device, once per size
        par = hist._work[f"svgf-par-{n_max!r}"] = torch.tensor(
            [n_max, ALPHA0_PAPER], dtype=torch.float64, device=dev)
    blk = block_for(h * w, dev)
    grid = (cdiv(h * w, blk),)

    grad = 0
    low = par
    hs, ws = -(-h // 3), -(-w // 3)
    if asvgf:
        grad = 1
        if hist.has_prev and motion is not None:  # the gradient needs a previous frame
            g_buf = device_buffer(frame, "gradient", h, w, 3)
            low = gradient_strata(hist, prev, g_buf, int(p["gradient_iterations"]),
                                  p["gradient_mode"], p["sigma_z"], p["sigma_n"], EPS_Z)
            grad = 2
    flag = hist.taa_flag(bool(p["taa"]), dev)
    _, new, fetched, status, _ = hist.reproject(depth, normal, position, motion, r,
                                                ("svgf", emissive), flag)
    acc = hist.work("acc", (3, h, w))
    var = hist.work("var", (h, w))
    flags = hist.work("flags", (h, w), torch.uint8)
    a_used = hist.work("alpha", (h, w))
    g_img = hist.work("gradient", (h, w)) if asvgf else a_used
    wn = hist.work("w-normal", (3, h, w)) if wsrc is not None else new[1:4]
    iterations = auto_iterations(h, w) if p["iterations"] == "auto" else int(p["iterations"])
    tap = p["feedback_tap"]
    feedback_none = tap is None or int(tap) >= iterations
    of_mean = p["variance_of"] == "mean"
    temporal_kernel[grid](
        color, albedo, emission if emissive else color, wsrc if wsrc is not None else color,
        motion if motion is not None else color, fetched, status, new, low, acc, wn, var, flags,
        a_used, g_img, par, float(p["albedo_floor"]), float(p["alpha_min"]),
        float(p["alpha_min_moments"]), h, w, hs, ws, EMISSIVE=emissive, COUNTING=counting,
        WNB=wsrc is not None, GRAD=grad, GMODE=_GMODE[p["gradient_mode"]] if asvgf else 0,
        ALPHA_FLOOR=bool(p.get("alpha_floor", False)), OF_MEAN=of_mean,
        FEEDBACK_NONE=feedback_none, BLOCK=blk)
    sz, sn = float(p["sigma_z"]), float(p["sigma_n"])
    variance_kernel[grid](new, wn, flags, var, h, w, sz, sn, EPS_Z,
                          BOOST=_boost_code(p["variance_boost"], counting), OF_MEAN=of_mean,
                          BLOCK=blk)

    out = torch.empty((h, w, 3), dtype=torch.float32, device=dev)
    emis_acc = new[BASE + 7:BASE + 10]
    bufs = ((hist.work("col-a", (3, h, w)), hist.work("var-a", (h, w))),
            (hist.work("col-b", (3, h, w)), hist.work("var-b", (h, w))))
    cur, cur_v = acc, var
    for i in range(max(iterations, 1)):  # 0 iterations: one launch without taps (remodulate)
        c_out, v_out = bufs[i % 2]
        atrous_kernel[grid](
            cur, cur_v, new[0], wn, flags, c_out, v_out, new[BASE:BASE + 3], albedo, emis_acc,
            out, h, w, 2 ** i, sz, sn, float(p["sigma_l"]), EPS_Z, float(p["eps_var"]),
            float(p["albedo_floor"]), USE_LUM=True, GAUSS=p["luminance_kernel"] == "gaussian",
            SN128=sn == 128.0, TAPS=iterations > 0, USE_VAR=True,
            FEEDBACK=not feedback_none and i == int(tap), FINAL=i == max(iterations, 1) - 1,
            EMISSIVE=emissive, BLOCK=blk)
        cur, cur_v = c_out, v_out
    hist.commit(origin, ("svgf", emissive))
    method.last = {"n": new[BASE + 5], "alpha": a_used, "variance": cur_v, "status": status,
                   "weight_sq": new[BASE + 6], "iterations": iterations,
                   "frames": new[BASE + 7 + 3 * emissive] if counting else None}
    if asvgf:
        method.last["gradient"] = g_img
    if p["taa"]:
        out = hist.taa(out, motion, float(p["taa_alpha"]), flag)
    return out


__all__ = ["svgf_device"]
