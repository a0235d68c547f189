"""Device functions shared by the temporal kernels (inlined into each kernel that calls them;
Triton's interpreter runs their Python bodies, see runtime.py).

:func:`depth_gradient` is the depth gradient of SVGF's variance estimate and à-trous passes
(``svgf.variance_kernel``, ``svgf.atrous_kernel``). :func:`demodulate` is the first step of SVGF's and BMFR's accumulation kernels
(``svgf.temporal_kernel``, ``bmfr.bmfr_accumulate_kernel``): the colour clamped to ±1e15, the
albedo to [floor, 1], the emission to [0, 1e15], and the illumination (colour − emission) /
albedo of the pixels whose colour is finite (docs/temporal.md; the host's
``dbench.methods.svgf.steps``)."""
from __future__ import annotations

import triton
import triton.language as tl


@triton.jit
def demodulate(color_ptr, albedo_ptr, emis_ptr, idx, inside, hit, floor,
               EMISSIVE: tl.constexpr, BLOCK: tl.constexpr):
    """color/albedo/emis (H, W, 3) f32 at pixels ``idx`` (BLOCK,). Returns c0, c1, c2 (the
    clamped colour), present (finite colour), e0, e1, e2 (the clamped emission, 0 without
    EMISSIVE), emitter (a hit with some emission > 0) and i0, i1, i2 (the illumination, 0 where
    the colour is missing)."""
    big = 3.4028234663852886e38
    c0 = tl.load(color_ptr + 3 * idx, mask=inside, other=0.0)
    c1 = tl.load(color_ptr + 3 * idx + 1, mask=inside, other=0.0)
    c2 = tl.load(color_ptr + 3 * idx + 2, mask=inside, other=0.0)
    c0 = tl.where((tl.abs(c0) > 1e15) & (tl.abs(c0) <= big), tl.where(c0 > 0, 1e15, -1e15), c0)
    c1 = tl.where((tl.abs(c1) > 1e15) & (tl.abs(c1) <= big), tl.where(c1 > 0, 1e15, -1e15), c1)
    c2 = tl.where((tl.abs(c2) > 1e15) & (tl.abs(c2) <= big), tl.where(c2 > 0, 1e15, -1e15), c2)
    present = inside & (tl.abs(c0) <= big) & (tl.abs(c1) <= big) & (tl.abs(c2) <= big)
    a0 = tl.load(albedo_ptr + 3 * idx, mask=inside, other=1.0)
    a1 = tl.load(albedo_ptr + 3 * idx + 1, mask=inside, other=1.0)
    a2 = tl.load(albedo_ptr + 3 * idx + 2, mask=inside, other=1.0)
    a0 = tl.where(tl.abs(a0) <= big, tl.where(a0 < floor, floor, tl.where(a0 > 1.0, 1.0, a0)), 1.0)
    a1 = tl.where(tl.abs(a1) <= big, tl.where(a1 < floor, floor, tl.where(a1 > 1.0, 1.0, a1)), 1.0)
    a2 = tl.where(tl.abs(a2) <= big, tl.where(a2 < floor, floor, tl.where(a2 > 1.0, 1.0, a2)), 1.0)
    e0 = tl.zeros((BLOCK,), tl.float32)
    e1 = e0
    e2 = e0
    if EMISSIVE:  # clamped like the colour; non-finite or ≤ 0 counts as 0
        e0 = tl.load(emis_ptr + 3 * idx, mask=inside, other=0.0)
        e1 = tl.load(emis_ptr + 3 * idx + 1, mask=inside, other=0.0)
        e2 = tl.load(emis_ptr + 3 * idx + 2, mask=inside, other=0.0)
        e0 = tl.where((tl.abs(e0) <= big) & (e0 > 0), tl.where(e0 > 1e15, 1e15, e0), 0.0)
        e1 = tl.where((tl.abs(e1) <= big) & (e1 > 0), tl.where(e1 > 1e15, 1e15, e1), 0.0)
        e2 = tl.where((tl.abs(e2) <= big) & (e2 > 0), tl.where(e2 > 1e15, 1e15, e2), 0.0)
    emitter = hit & ((e0 > 0) | (e1 > 0) | (e2 > 0))
    i0 = tl.where(present, tl.div_rn(c0 - e0, a0), 0.0)
    i1 = tl.where(present, tl.div_rn(c1 - e1, a1), 0.0)
    i2 = tl.where(present, tl.div_rn(c2 - e2, a2), 0.0)
    return c0, c1, c2, present, e0, e1, e2, emitter, i0, i1, i2


@triton.jit
def depth_gradient(z_ptr, idx, x, y, H, W, inside):
    """The screen-space depth gradient of SVGF's edge-stopping function at pixels ``idx``
    (BLOCK,) of the depth plane z (H, W) f32 (0 without a hit): along each axis the smaller of
    the forward and backward differences whose neighbour is a hit (one-sided where only one
    is), 0 at a pixel without a hit. Returns z, gx, gy (docs/temporal.md; the host's
    ``dbench.methods.svgf.steps``)."""
    z = tl.load(z_ptr + idx, mask=inside, other=0.0)
    hit = z > 0
    zr = tl.load(z_ptr + idx + 1, mask=inside & (x + 1 < W), other=0.0)
    zl = tl.load(z_ptr + idx - 1, mask=inside & (x > 0), other=0.0)
    zd = tl.load(z_ptr + idx + W, mask=inside & (y + 1 < H), other=0.0)
    zu = tl.load(z_ptr + idx - W, mask=inside & (y > 0), other=0.0)
    fw = zr - z
    bw = z - zl
    gx = tl.where((zr > 0) & (zl > 0), tl.where(tl.abs(fw) <= tl.abs(bw), fw, bw),
                  tl.where(zr > 0, fw, tl.where(zl > 0, bw, 0.0)))
    gx = tl.where(hit, gx, 0.0)
    fw = zd - z
    bw = z - zu
    gy = tl.where((zd > 0) & (zu > 0), tl.where(tl.abs(fw) <= tl.abs(bw), fw, bw),
                  tl.where(zd > 0, fw, tl.where(zu > 0, bw, 0.0)))
    gy = tl.where(hit, gy, 0.0)
    return z, gx, gy


__all__ = ["demodulate", "depth_gradient"]
