"""The residual hand-back's first two passes as Triton kernels (the maths in
:mod:`dbench.methods.kernels.residual_handback`, the arithmetic of its compiled pass
``_handback_bands`` and of BMFR's moments pass :func:`dbench.methods.bmfr.handback.moments_fast`;
the last pass, fused with BMFR's second accumulation, is
:data:`dbench.methods.kernels.gpu.bmfr.bmfr_finish_kernel`).

* :data:`handback_low_kernel` — per pixel and channel: var(z) (the temporal moments times Σw²,
  or below 4 effective samples the 7×7 spatial variance of this frame's samples over the fit
  pixels with a finite sample, in float64) and the residual's local mean ``low`` (the 7×7
  Gaussian of r = z − y on the fit pixels over G*1, x taps then y taps as the host sums them).
* :data:`handback_energy_kernel` — per pixel and channel: high² (high = r − low, every pixel)
  and, for the signed rule, min(high, 0)² / V3 capped (V3: the 3×3 mean of the masked variance;
  ½ where it is 0; 0 off the fit pixels).

Planes are (3, H, W) float32; flags (H, W) uint8 with bit 1 the fit set and bit 4 a finite
sample (:mod:`.bmfr`'s FIT, PRESENT). Min/max are selects in the host's operand order.
"""
from __future__ import annotations

import triton.language as tl
from triton.language import core as tl_core  # noqa: F401 - patched by the interpreter (runtime)

from .runtime import kernel


@kernel
def handback_low_kernel(illum_ptr, z_ptr, zz_ptr, s_ptr, y_ptr, flags_ptr, g_ptr, var_ptr,
                        low_ptr, H, W, BLOCK: tl.constexpr):
    """illum, z, zz, y (3, H, W) f32 (planes hw apart), s (H, W) Σw²; g (7,) f64 Gaussian taps;
    outputs var and low (3, H, W) f32."""
    idx = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    hw = H * W
    inside = idx < hw
    y = idx // W
    x = idx - y * W
    fl = tl.load(flags_ptr + idx, mask=inside, other=0).to(tl.int32)
    fit = inside & ((fl & 1) != 0)
    s = tl.load(s_ptr + idx, mask=inside, other=0.0)
    short = fit & (s * 4.0 > 1.0)
    # G*1 along both axes (zero padding), float64 as the host's, then float32
    nx = tl.zeros((BLOCK,), tl.float64)
    ny = tl.zeros((BLOCK,), tl.float64)
    for k in tl.static_range(7):
        gk = tl.load(g_ptr + k)
        nx += tl.where((x + (k - 3) >= 0) & (x + (k - 3) < W), gk, 0.0)
        ny += tl.where((y + (k - 3) >= 0) & (y + (k - 3) < H), gk, 0.0)
    inv_norm_x = (1.0 / nx).to(tl.float32)
    inv_ny = 1.0 / ny.to(tl.float32)
    # channels and the rare 49-tap variance as loops, not unrolled: each unrolled copy cost
    # the GPU compiler seconds (docs/gpu.md §6), and the order of the sums is the same
    for c in range(3):
        zc = tl.load(z_ptr + c * hw + idx, mask=inside, other=0.0)
        zz = tl.load(zz_ptr + c * hw + idx, mask=inside, other=0.0)
        v = zz - zc * zc
        var = tl.where(v < 0.0, 0.0, v) * s
        # the spatial variance below 4 effective samples (pixel_window_variance)
        if tl.max(tl.where(short, 1, 0), axis=0) > 0:
            n = tl.zeros((BLOCK,), tl.int32)
            s1 = tl.zeros((BLOCK,), tl.float64)
            s2 = tl.zeros((BLOCK,), tl.float64)
            for t in range(49):
                yy = y + (t // 7 - 3)
                xx = x + (t % 7 - 3)
                inb = short & (yy >= 0) & (yy < H) & (xx >= 0) & (xx < W)
                q = yy * W + xx
                fq = tl.load(flags_ptr + q, mask=inb, other=0).to(tl.int32)
                use = inb & ((fq & 1) != 0) & ((fq & 4) != 0)
                iv = tl.load(illum_ptr + c * hw + q, mask=use, other=0.0).to(tl.float64)
                n += tl.where(use, 1, 0)
                s1 += tl.where(use, iv, 0.0)
                s2 += tl.where(use, iv * iv, 0.0)
            nf = tl.where(n > 0, n, 1).to(tl.float64)
            m = s1 / nf
            sv = s2 / nf - m * m
            sv = tl.where(n > 0, tl.where(sv < 0.0, 0.0, sv), 0.0)
            var = tl.where(short, sv.to(tl.float32) * s, var)
        tl.store(var_ptr + c * hw + idx, var, mask=inside)
        acc = tl.zeros((BLOCK,), tl.float32)
        for ky in tl.static_range(7):
            yy = y + (ky - 3)
            rowin = inside & (yy >= 0) & (yy < H)
            rx = tl.zeros((BLOCK,), tl.float32)
            for kx in tl.static_range(7):
                xx = x + (kx - 3)
                inb = rowin & (xx >= 0) & (xx < W)
                q = yy * W + xx
                fq = tl.load(flags_ptr + q, mask=inb, other=0).to(tl.int32)
                m_q = inb & ((fq & 1) != 0)
                d = (tl.load(z_ptr + c * hw + q, mask=m_q, other=0.0)
                     - tl.load(y_ptr + c * hw + q, mask=m_q, other=0.0))
                rx += tl.load(g_ptr + kx).to(tl.float32) * tl.where(m_q, d, 0.0)
            acc += tl.where(rowin, tl.load(g_ptr + ky).to(tl.float32) * rx, 0.0)
        tl.store(low_ptr + c * hw + idx, acc * (inv_ny * inv_norm_x), mask=inside)


@kernel
def handback_energy_kernel(z_ptr, y_ptr, var_ptr, low_ptr, flags_ptr, hh_ptr, q_ptr, H, W,
                           SIGNED: tl.constexpr, BLOCK: tl.constexpr):
    """z, y, var, low (3, H, W) f32; outputs hh = high² and (SIGNED) q = the capped ratio
    min(high, 0)² / V3, (3, H, W) f32."""
    idx = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    hw = H * W
    inside = idx < hw
    y = idx // W
    x = idx - y * W
    fl = tl.load(flags_ptr + idx, mask=inside, other=0).to(tl.int32)
    fit = inside & ((fl & 1) != 0)
    if SIGNED:  # 1 / the 3×3 window's count inside the image
        cx = (tl.where(x + 1 < W, x + 1, W - 1) - tl.where(x - 1 > 0, x - 1, 0) + 1)
        cy = (tl.where(y + 1 < H, y + 1, H - 1) - tl.where(y - 1 > 0, y - 1, 0) + 1)
        inv3 = (1.0 / cx.to(tl.float64)).to(tl.float32) * (1.0 / cy.to(tl.float64)).to(tl.float32)
    for c in tl.static_range(3):
        d = (tl.load(z_ptr + c * hw + idx, mask=fit, other=0.0)
             - tl.load(y_ptr + c * hw + idx, mask=fit, other=0.0))
        rr = tl.where(fit, d, 0.0)
        hv = rr - tl.load(low_ptr + c * hw + idx, mask=inside, other=0.0)
        tl.store(hh_ptr + c * hw + idx, hv * hv, mask=inside)
        if SIGNED:
            eq = tl.zeros((BLOCK,), tl.float32)
            for dy in tl.static_range(3):
                yy = y + (dy - 1)
                rowin = inside & (yy >= 0) & (yy < H)
                v3 = tl.zeros((BLOCK,), tl.float32)
                for dx in tl.static_range(3):
                    xx = x + (dx - 1)
                    inb = rowin & (xx >= 0) & (xx < W)
                    q = yy * W + xx
                    fq = tl.load(flags_ptr + q, mask=inb, other=0).to(tl.int32)
                    m_q = inb & ((fq & 1) != 0)
                    v3 += tl.where(m_q, tl.load(var_ptr + c * hw + q, mask=m_q, other=0.0), 0.0)
                eq += tl.where(rowin, v3, 0.0)
            neg = tl.where(hv < 0.0, hv, 0.0)
            n2 = tl.where(fit, neg * neg, 0.0)
            noise = eq * inv3
            capped = n2 * (1.0 / 1e6)
            den = tl.where(capped > noise, capped, noise)
            den = tl.where(1e-30 > den, 1e-30, den)
            ratio = n2 / den
            tl.store(q_ptr + c * hw + idx, tl.where(fit, tl.where(noise > 0.0, ratio, 0.5), 0.0),
                     mask=inside)


__all__ = ["handback_energy_kernel", "handback_low_kernel"]
