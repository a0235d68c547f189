"""A-SVGF's temporal gradient on the device (docs/temporal.md §2, §14; the maths of
``stratum_gradients``, ``filter_gradients`` and ``adaptive_history`` in
:mod:`dbench.methods.svgf.dispatch` and :mod:`dbench.methods.svgf.reference`).

* :data:`strata_kernel` — per 3×3 stratum of the previous frame its brightest usable pixel
  (a previous hit whose raw luminance and re-shaded luminance are finite; ties go to the first in
  row-major order) and there δ = L_new − L_prev (|δ| for ``"filtered_abs"``), Δ = max(L_prev,
  L_new), G = (|δ| / Δ)² clipped to [0, 1] (0 where Δ ≤ 0), the sample's depth and normal.
* :func:`gradient_strata` — that launch and the ``gradient_iterations`` à-trous passes over the
  stratum image (:data:`~.svgf.atrous_kernel` with the luminance weight off, steps 1, 2, 4 …).
  The full-resolution gather, N' and α are computed in :data:`~.svgf.temporal_kernel`.
"""
from __future__ import annotations

from typing import Any

import triton.language as tl
from triton.language import core as tl_core  # noqa: F401 - patched by the interpreter (runtime)

from .runtime import cdiv, kernel
from .svgf import atrous_kernel
from .temporal import block_for


@kernel
def strata_kernel(prev_ptr, grad_ptr, st_ptr, sflags_ptr, H, W, HS, WS, ABS: tl.constexpr,
                  BLOCK: tl.constexpr):
    """prev (5 + P, H, W) the previous frame's history buffer (depth, normal, raw luminance;
    −FLT_MAX marks a missing sample); grad (H, W, 3) this frame's re-shaded samples; st
    (7, HS, WS) f32: δ, Δ, G, depth, normal (3); sflags (HS, WS) u8: 7 where the stratum has a
    sample (a tap, its own value and a gatherer for the filter), else 0 (and st 0)."""
    s = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    ns = HS * WS
    inside = s < ns
    sy = s // WS
    sx = s - sy * WS
    hw = H * W
    big = 3.4028234663852886e38
    best = tl.full((BLOCK,), -big, tl.float32)
    bq = tl.zeros((BLOCK,), tl.int32)
    found = s < 0
    for j in tl.static_range(9):
        yy = sy * 3 + j // 3
        xx = sx * 3 + j % 3
        inb = inside & (yy < H) & (xx < W)
        q = yy * W + xx
        lp = tl.load(prev_ptr + 4 * hw + q, mask=inb, other=-big)
        pd = tl.load(prev_ptr + q, mask=inb, other=0.0)
        g0 = tl.load(grad_ptr + 3 * q, mask=inb, other=0.0)
        g1 = tl.load(grad_ptr + 3 * q + 1, mask=inb, other=0.0)
        g2 = tl.load(grad_ptr + 3 * q + 2, mask=inb, other=0.0)
        g0 = tl.where((tl.abs(g0) > 1e15) & (tl.abs(g0) <= big), tl.where(g0 > 0, 1e15, -1e15), g0)
        g1 = tl.where((tl.abs(g1) > 1e15) & (tl.abs(g1) <= big), tl.where(g1 > 0, 1e15, -1e15), g1)
        g2 = tl.where((tl.abs(g2) > 1e15) & (tl.abs(g2) <= big), tl.where(g2 > 0, 1e15, -1e15), g2)
        lg = 0.2126 * g0 + 0.7152 * g1 + 0.0722 * g2
        usable = inb & (pd > 0) & (lp > -1e38) & (tl.abs(lg) <= big)
        better = usable & (lp > best)
        best = tl.where(better, lp, best)
        bq = tl.where(better, q, bq)
        found = found | usable
    lp = tl.load(prev_ptr + 4 * hw + bq, mask=found, other=0.0)
    g0 = tl.load(grad_ptr + 3 * bq, mask=found, other=0.0)
    g1 = tl.load(grad_ptr + 3 * bq + 1, mask=found, other=0.0)
    g2 = tl.load(grad_ptr + 3 * bq + 2, mask=found, other=0.0)
    g0 = tl.where(tl.abs(g0) > 1e15, tl.where(g0 > 0, 1e15, -1e15), g0)
    g1 = tl.where(tl.abs(g1) > 1e15, tl.where(g1 > 0, 1e15, -1e15), g1)
    g2 = tl.where(tl.abs(g2) > 1e15, tl.where(g2 > 0, 1e15, -1e15), g2)
    lg = (0.2126 * g0 + 0.7152 * g1 + 0.0722 * g2).to(tl.float64)
    lp64 = lp.to(tl.float64)
    delta = lg - lp64
    m = tl.where(lg > lp64, lg, lp64)
    r = tl.abs(delta) / tl.where(m > 0, m, 1.0)
    gg = tl.where(m > 0, r * r, 0.0)
    gg = tl.where(gg > 1.0, 1.0, gg)
    dl = delta.to(tl.float32)
    if ABS:
        dl = tl.abs(dl)
    tl.store(st_ptr + s, tl.where(found, dl, 0.0), mask=inside)
    tl.store(st_ptr + ns + s, tl.where(found, m.to(tl.float32), 0.0), mask=inside)
    tl.store(st_ptr + 2 * ns + s, tl.where(found, gg.to(tl.float32), 0.0), mask=inside)
    for k in tl.static_range(4):  # the sample's depth and normal
        v = tl.load(prev_ptr + k * hw + bq, mask=found, other=0.0)
        tl.store(st_ptr + (3 + k) * ns + s, tl.where(found, v, 0.0), mask=inside)
    tl.store(sflags_ptr + s, tl.where(found, 7, 0).to(tl.uint8), mask=inside)


def gradient_strata(hist: Any, prev, grad, iterations: int, mode: str, sigma_z: float,
                    sigma_n: float, eps_z: float):
    """The filtered stratum image [δ̂, Δ̂, Ĝ] (3, ⌈H/3⌉, ⌈W/3⌉) float32 of this frame
    (1 + ``iterations`` launches), from the previous history buffer ``prev`` and the frame's
    ``gradient`` tensor (H, W, 3); work tensors come from ``hist``
    (:class:`~dbench.methods.temporal.device.DeviceHistory`)."""
    import torch

    h, w = prev.shape[1:]
    hs, ws = -(-h // 3), -(-w // 3)
    st = hist.work("strata", (7, hs, ws))
    sflags = hist.work("strata-flags", (hs, ws), torch.uint8)
    blk = block_for(hs * ws, prev.device)
    grid = (cdiv(hs * ws, blk),)
    strata_kernel[grid](prev, grad, st, sflags, h, w, hs, ws, ABS=mode == "filtered_abs",
                        BLOCK=blk)
    cur = st[0:3]
    bufs = (hist.work("strata-a", (3, hs, ws)), hist.work("strata-b", (3, hs, ws)))
    for i in range(int(iterations)):
        out = bufs[i % 2]
        atrous_kernel[grid](cur, cur, st[3], st[4:7], sflags, out, out, out, out, out, out,
                            hs, ws, 2 ** i, float(sigma_z), float(sigma_n), 1.0, float(eps_z),
                            1.0, 1.0, USE_LUM=False, GAUSS=False, SN128=float(sigma_n) == 128.0,
                            TAPS=True, USE_VAR=False, FEEDBACK=False, FINAL=False,
                            EMISSIVE=False, BLOCK=blk)
        cur = out
    return cur


__all__ = ["gradient_strata", "strata_kernel"]
