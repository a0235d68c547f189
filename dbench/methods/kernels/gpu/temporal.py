"""The reprojection, ``accumulate``'s accumulation and the temporal antialiasing (TAA) of the
temporal methods as Triton kernels, and the history they keep on the device (docs/temporal.md;
the maths is :mod:`dbench.methods.temporal`'s, whose docstring states it).

History layout: a method keeps two (5 + P, H, W) float32 buffers
(:class:`dbench.methods.temporal.device.DeviceHistory`) and
alternates between them, so that one frame's kernels read the previous buffer while they write
the other (a pixel's reprojection reads its neighbours' previous values). Planes 0-3 hold the
frame's geometry (depth, 0 without a hit; the shading normal, 0 without a hit), plane 4 the raw
luminance A-SVGF compares its re-shaded samples with, planes 5… the method's history
(``accumulate``: colour 3, moments [l, l²] 2, N). A previous pixel is readable when its depth and
its history length N are > 0 (``History.store``'s ``valid``: hit and not empty).

Kernels (one launch each per frame):

* :data:`reproject_kernel` — the frame's geometry (``frame_geometry``: hit = finite depth > 0,
  finite normal and position) written into the new buffer, and the first R history planes of the
  previous buffer reprojected (2×2 bilinear with validity, normalised 3×3 fallback, reset on
  disocclusion: ``reproject_reference``'s rules, positions and weights in float64 as the
  compiled host path computes them), with the status (0 reset, 1 bilinear, 2 fallback).
* :data:`accumulate_kernel` — ``accumulate``'s blend (:func:`dbench.methods.accumulate.fast.
  accumulate_frame`): the colour clamped to ±1e15, the moments, N, the output and the variance.
* :data:`taa_kernel` — :func:`dbench.methods.temporal.taa.taa_fast` per pixel (the YCoCg box
  and cross ranges read from the 3×3 neighbourhood directly).

Every min/max is written as a select with the host's operand order, so a NaN behaves as in the
compiled host path and alike in both modes (``tl.minimum`` propagates NaN in the interpreter and
not on the GPU).
"""
from __future__ import annotations

from typing import Any

import triton
import triton.language as tl
from triton.language import core as tl_core  # noqa: F401 - patched by the interpreter (runtime)

from .runtime import kernel, on_gpu_layout

#: Planes before a method's history: depth, normal (3), raw luminance.
BASE = 5
#: Pixels per program on the GPU; the interpreter takes the whole image (fewer, larger steps).
GPU_BLOCK = 128
CPU_BLOCK_MAX = 4096
FLT_MAX = 3.4028234663852886e38
RADIANCE = 1e15  # dbench.methods.guards.RADIANCE_MAX, as float32 in the kernels


def block_for(n: int, device: Any) -> int:
    """Pixels per program: :data:`GPU_BLOCK` on CUDA (or inside ``runtime.gpu_layout``), else
    the image up to 4096 (interpreter)."""
    if on_gpu_layout(device):
        return GPU_BLOCK
    return min(CPU_BLOCK_MAX, triton.next_power_of_2(max(int(n), 16)))


@kernel
def reproject_kernel(depth_ptr, normal_ptr, pos_ptr, motion_ptr, prev_ptr, new_ptr, out_ptr,
                     status_ptr, flag_ptr, par_ptr, ox, oy, oz, H, W,
                     HAS_HIST: tl.constexpr, HAS_ORIGIN: tl.constexpr, R: tl.constexpr,
                     RP: tl.constexpr, N_PLANE: tl.constexpr, FLAG: tl.constexpr,
                     BLOCK: tl.constexpr):
    """depth (H, W) f32, normal/pos (H, W, 3) f32, motion (H, W, 2) f32; prev/new (5 + P, H, W)
    f32 history buffers; out (R, H, W) f32 reprojected planes 5 … 5 + R − 1; status (H, W) u8;
    flag (1,) i32 (set to 1 when some status > 0, if FLAG); par (12,) f64: τ_d, τ_n, ε_f and the
    3×3 fallback kernel; (ox, oy, oz) the previous camera origin (HAS_ORIGIN)."""
    idx = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    hw = H * W
    inside = idx < hw
    y = idx // W
    x = idx - y * W
    big = 3.4028234663852886e38
    d = tl.load(depth_ptr + idx, mask=inside, other=0.0)
    n0 = tl.load(normal_ptr + 3 * idx, mask=inside, other=0.0)
    n1 = tl.load(normal_ptr + 3 * idx + 1, mask=inside, other=0.0)
    n2 = tl.load(normal_ptr + 3 * idx + 2, mask=inside, other=0.0)
    p0 = tl.load(pos_ptr + 3 * idx, mask=inside, other=0.0)
    p1 = tl.load(pos_ptr + 3 * idx + 1, mask=inside, other=0.0)
    p2 = tl.load(pos_ptr + 3 * idx + 2, mask=inside, other=0.0)
    # |v| <= FLT_MAX is "finite" (NaN compares false)
    hit = (inside & (tl.abs(d) <= big) & (d > 0) & (tl.abs(n0) <= big) & (tl.abs(n1) <= big)
           & (tl.abs(n2) <= big) & (tl.abs(p0) <= big) & (tl.abs(p1) <= big)
           & (tl.abs(p2) <= big))
    dp = tl.where(hit, d, 0.0)
    n0 = tl.where(hit, n0, 0.0)
    n1 = tl.where(hit, n1, 0.0)
    n2 = tl.where(hit, n2, 0.0)
    tl.store(new_ptr + idx, dp, mask=inside)
    tl.store(new_ptr + hw + idx, n0, mask=inside)
    tl.store(new_ptr + 2 * hw + idx, n1, mask=inside)
    tl.store(new_ptr + 3 * hw + idx, n2, mask=inside)
    status = tl.zeros((BLOCK,), tl.int32)
    if HAS_HIST:
        mx = tl.load(motion_ptr + 2 * idx, mask=inside, other=0.0)
        my = tl.load(motion_ptr + 2 * idx + 1, mask=inside, other=0.0)
        go = hit & (tl.abs(mx) <= big) & (tl.abs(my) <= big)
        if HAS_ORIGIN:  # expected_distance: ‖P(p) − o←‖ in float32
            ex = p0 - ox
            ey = p1 - oy
            ez = p2 - oz
            de = tl.where(hit, tl.sqrt_rn(ex * ex + ey * ey + ez * ez), 0.0)
        else:
            de = dp
        de64 = de.to(tl.float64)
        tau_d = tl.load(par_ptr)
        tau_n = tl.load(par_ptr + 1)
        eps_f = tl.load(par_ptr + 2)
        px = x.to(tl.float64) + tl.where(go, mx, 0.0).to(tl.float64)
        py = y.to(tl.float64) + tl.where(go, my, 0.0).to(tl.float64)
        # far outside the image every tap is invalid anyway; the clamp keeps the int conversion
        # defined for huge finite motion
        px = tl.where(px < -8.0, -8.0, tl.where(px > W + 8.0, W + 8.0, px))
        py = tl.where(py < -8.0, -8.0, tl.where(py > H + 8.0, H + 8.0, py))
        fx0 = tl.floor(px)
        fy0 = tl.floor(py)
        wx = px - fx0
        wy = py - fy0
        x0 = fx0.to(tl.int32)
        y0 = fy0.to(tl.int32)
        cx = tl.floor(px + 0.5).to(tl.int32)
        cy = tl.floor(py + 0.5).to(tl.int32)
        # pass 1: the bilinear taps' total weight f (docs/methods/temporal.md §3.3)
        f = tl.zeros((BLOCK,), tl.float64)
        for t in tl.static_range(4):
            qx = x0 + (t % 2)
            qy = y0 + (t // 2)
            if t % 2 == 1:
                bx = wx
            else:
                bx = 1.0 - wx
            if t // 2 == 1:
                by = wy
            else:
                by = 1.0 - wy
            q = qy * W + qx
            inb = go & (qx >= 0) & (qy >= 0) & (qx < W) & (qy < H)
            pd = tl.load(prev_ptr + q, mask=inb, other=0.0)
            dot = (tl.load(prev_ptr + hw + q, mask=inb, other=0.0) * n0
                   + tl.load(prev_ptr + 2 * hw + q, mask=inb, other=0.0) * n1
                   + tl.load(prev_ptr + 3 * hw + q, mask=inb, other=0.0) * n2)
            pn = tl.load(prev_ptr + (5 + N_PLANE) * hw + q, mask=inb, other=0.0)
            ok = (inb & (pd > 0) & (pn > 0) & (tl.abs(pd - de).to(tl.float64) <= tau_d * de64)
                  & (dot.to(tl.float64) >= tau_n))
            b = bx * by
            f += tl.where(ok & (b > 0), b, 0.0)
        bil = f > eps_f
        f_safe = tl.where(bil, f, 1.0)
        # pass 2: the 3×3 window around round(p←) holds the 2×2 bilinear taps, in the same
        # row-major order, and the fallback's (§3.4); one gather serves both
        r = tl.arange(0, RP)
        rmask = r < R
        acc = tl.zeros((BLOCK, RP), tl.float64)
        g = tl.zeros((BLOCK,), tl.float64)
        for j in tl.static_range(9):
            qx = cx + (j % 3 - 1)
            qy = cy + (j // 3 - 1)
            q = qy * W + qx
            inb = go & (qx >= 0) & (qy >= 0) & (qx < W) & (qy < H)
            pd = tl.load(prev_ptr + q, mask=inb, other=0.0)
            dot = (tl.load(prev_ptr + hw + q, mask=inb, other=0.0) * n0
                   + tl.load(prev_ptr + 2 * hw + q, mask=inb, other=0.0) * n1
                   + tl.load(prev_ptr + 3 * hw + q, mask=inb, other=0.0) * n2)
            pn = tl.load(prev_ptr + (5 + N_PLANE) * hw + q, mask=inb, other=0.0)
            ok = (inb & (pd > 0) & (pn > 0) & (tl.abs(pd - de).to(tl.float64) <= tau_d * de64)
                  & (dot.to(tl.float64) >= tau_n))
            bx = tl.where(qx == x0, 1.0 - wx, tl.where(qx == x0 + 1, wx, 0.0))
            by = tl.where(qy == y0, 1.0 - wy, tl.where(qy == y0 + 1, wy, 0.0))
            b = bx * by
            k = tl.load(par_ptr + 3 + j)
            wk = tl.where(ok, k, 0.0)
            g += wk
            wgt = tl.where(bil, tl.where(ok & (b > 0), b / f_safe, 0.0), wk)
            v = tl.load(prev_ptr + (5 + r[None, :]) * hw + q[:, None],
                        mask=(wgt > 0)[:, None] & rmask[None, :], other=0.0)
            acc += wgt[:, None] * v.to(tl.float64)
        fb = (f <= eps_f) & (g > 0)
        g_safe = tl.where(fb, g, 1.0)
        res = tl.where(bil[:, None], acc, tl.where(fb[:, None], acc / g_safe[:, None], 0.0))
        tl.store(out_ptr + r[None, :] * hw + idx[:, None], res.to(tl.float32),
                 mask=inside[:, None] & rmask[None, :])
        status = tl.where(bil, 1, tl.where(fb, 2, 0))
        if FLAG:
            tl.atomic_max(flag_ptr, tl.max(tl.where(inside & (status > 0), 1, 0), axis=0))
    tl.store(status_ptr + idx, status.to(tl.uint8), mask=inside)


@kernel
def accumulate_kernel(color_ptr, fetched_ptr, status_ptr, new_ptr, out_ptr, var_ptr, alpha_min,
                      n_max, H, W, BLOCK: tl.constexpr):
    """color (H, W, 3) f32; fetched (6, H, W) reprojected colour, moments, N; status (H, W) u8;
    new (5 + 6, H, W) history buffer (planes 5-10 written); out (H, W, 3); var (H, W)."""
    idx = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    hw = H * W
    inside = idx < hw
    big = 3.4028234663852886e38
    r = tl.load(color_ptr + 3 * idx, mask=inside, other=0.0)
    g = tl.load(color_ptr + 3 * idx + 1, mask=inside, other=0.0)
    b = tl.load(color_ptr + 3 * idx + 2, mask=inside, other=0.0)
    # clamp_radiance: finite values beyond ±1e15 to ±1e15 (NaN, ±Inf stay missing)
    r = tl.where((tl.abs(r) > 1e15) & (tl.abs(r) <= big), tl.where(r > 0, 1e15, -1e15), r)
    g = tl.where((tl.abs(g) > 1e15) & (tl.abs(g) <= big), tl.where(g > 0, 1e15, -1e15), g)
    b = tl.where((tl.abs(b) > 1e15) & (tl.abs(b) <= big), tl.where(b > 0, 1e15, -1e15), b)
    finite = (tl.abs(r) <= big) & (tl.abs(g) <= big) & (tl.abs(b) <= big)
    ok = inside & (tl.load(status_ptr + idx, mask=inside, other=0) > 0)
    h0 = tl.load(fetched_ptr + idx, mask=ok, other=0.0)
    h1 = tl.load(fetched_ptr + hw + idx, mask=ok, other=0.0)
    h2 = tl.load(fetched_ptr + 2 * hw + idx, mask=ok, other=0.0)
    h3 = tl.load(fetched_ptr + 3 * hw + idx, mask=ok, other=0.0)
    h4 = tl.load(fetched_ptr + 4 * hw + idx, mask=ok, other=0.0)
    h5 = tl.load(fetched_ptr + 5 * hw + idx, mask=ok, other=0.0)
    n1 = h5 + 1.0
    n = tl.where(ok, tl.where(n_max < n1, n_max, n1), 1.0)
    inv = 1.0 / n
    a = tl.where(ok, tl.where(inv > alpha_min, inv, alpha_min), 1.0)
    lum = 0.2126 * tl.where(finite, r, 0.0) + 0.7152 * tl.where(finite, g, 0.0) \
        + 0.0722 * tl.where(finite, b, 0.0)
    c0 = tl.where(finite, a * r + (1.0 - a) * h0, h0)
    c1 = tl.where(finite, a * g + (1.0 - a) * h1, h1)
    c2 = tl.where(finite, a * b + (1.0 - a) * h2, h2)
    m1 = tl.where(finite, a * lum + (1.0 - a) * h3, h3)
    m2 = tl.where(finite, a * (lum * lum) + (1.0 - a) * h4, h4)
    nn = tl.where(finite, n, h5)  # h* are 0 where the reprojection failed: an empty history
    base = new_ptr + 5 * hw + idx
    tl.store(base, c0, mask=inside)
    tl.store(base + hw, c1, mask=inside)
    tl.store(base + 2 * hw, c2, mask=inside)
    tl.store(base + 3 * hw, m1, mask=inside)
    tl.store(base + 4 * hw, m2, mask=inside)
    tl.store(base + 5 * hw, nn, mask=inside)
    full = nn > 0  # an empty history keeps the (non-finite) input: nothing spreads
    tl.store(out_ptr + 3 * idx, tl.where(full, c0, r), mask=inside)
    tl.store(out_ptr + 3 * idx + 1, tl.where(full, c1, g), mask=inside)
    tl.store(out_ptr + 3 * idx + 2, tl.where(full, c2, b), mask=inside)
    v = m2 - m1 * m1
    tl.store(var_ptr + idx, tl.where(v > 0.0, v, 0.0), mask=inside)


@kernel
def taa_kernel(cur_ptr, hist_ptr, motion_ptr, flag_ptr, out_ptr, keep_ptr, alpha, H, W,
               BLOCK: tl.constexpr):
    """cur, hist (H, W, 3) f32 (this output, the previous TAA output); motion (H, W, 2);
    flag (1,) i32: the history is used where > 0; out and keep (H, W, 3) receive the result."""
    idx = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    hw = H * W
    inside = idx < hw
    y = idx // W
    x = idx - y * W
    big = 3.4028234663852886e38
    c0 = tl.load(cur_ptr + 3 * idx, mask=inside, other=0.0)
    c1 = tl.load(cur_ptr + 3 * idx + 1, mask=inside, other=0.0)
    c2 = tl.load(cur_ptr + 3 * idx + 2, mask=inside, other=0.0)
    mx = tl.load(motion_ptr + 2 * idx, mask=inside, other=0.0)
    my = tl.load(motion_ptr + 2 * idx + 1, mask=inside, other=0.0)
    use = tl.load(flag_ptr) > 0
    ok = (inside & use & (tl.abs(mx) <= big) & (tl.abs(my) <= big) & (tl.abs(c0) <= big)
          & (tl.abs(c1) <= big) & (tl.abs(c2) <= big))
    qx = x.to(tl.float64) + tl.where(ok, mx, 0.0).to(tl.float64)
    qy = y.to(tl.float64) + tl.where(ok, my, 0.0).to(tl.float64)
    qx = tl.where(qx < -8.0, -8.0, tl.where(qx > W + 8.0, W + 8.0, qx))
    qy = tl.where(qy < -8.0, -8.0, tl.where(qy > H + 8.0, H + 8.0, qy))
    fqx = tl.floor(qx)
    fqy = tl.floor(qy)
    x0 = fqx.to(tl.int32)
    y0 = fqy.to(tl.int32)
    ok = ok & (x0 >= -1) & (y0 >= -1) & (x0 < W) & (y0 < H)  # the BMFR code's rule
    fx = qx - fqx
    fy = qy - fqy
    a0 = tl.zeros((BLOCK,), tl.float64)
    a1 = tl.zeros((BLOCK,), tl.float64)
    a2 = tl.zeros((BLOCK,), tl.float64)
    total = tl.zeros((BLOCK,), tl.float64)
    for t in tl.static_range(4):
        tx = x0 + (t % 2)
        ty = y0 + (t // 2)
        if t % 2 == 1:
            wxx = fx
        else:
            wxx = 1.0 - fx
        if t // 2 == 1:
            wyy = fy
        else:
            wyy = 1.0 - fy
        wt = wxx * wyy
        inb = ok & (tx >= 0) & (ty >= 0) & (tx < W) & (ty < H)
        q = 3 * (ty * W + tx)
        v0 = tl.load(hist_ptr + q, mask=inb, other=0.0).to(tl.float64)
        v1 = tl.load(hist_ptr + q + 1, mask=inb, other=0.0).to(tl.float64)
        v2 = tl.load(hist_ptr + q + 2, mask=inb, other=0.0).to(tl.float64)
        # a non-finite history value (a missing pixel's previous output) is no tap, as on the
        # host: it would carry NaN into a pixel whose own input is finite
        inb = inb & (v0 == v0) & (v1 == v1) & (v2 == v2) & (tl.abs(v0) < float("inf")) \
            & (tl.abs(v1) < float("inf")) & (tl.abs(v2) < float("inf"))
        a0 += tl.where(inb, wt * v0, 0.0)
        a1 += tl.where(inb, wt * v1, 0.0)
        a2 += tl.where(inb, wt * v2, 0.0)
        total += tl.where(inb, wt, 0.0)
    ok = ok & (total > 0)
    tot = tl.where(ok, total, 1.0)
    h0 = a0 / tot
    h1 = a1 / tot
    h2 = a2 / tot
    # YCoCg ranges of the 3×3 box and the 5-pixel cross (float32, as the host's range arrays);
    # ±FLT_MAX stand for "no value" (the centre is finite here, so it never wins)
    blo0 = tl.full((BLOCK,), big, tl.float32)
    blo1 = blo0
    blo2 = blo0
    bhi0 = tl.full((BLOCK,), -big, tl.float32)
    bhi1 = bhi0
    bhi2 = bhi0
    clo0 = blo0
    clo1 = blo0
    clo2 = blo0
    chi0 = bhi0
    chi1 = bhi0
    chi2 = bhi0
    for j in tl.static_range(9):
        dy = j // 3 - 1
        dx = j % 3 - 1
        xx = x + dx
        yy = y + dy
        inb = inside & (xx >= 0) & (yy >= 0) & (xx < W) & (yy < H)
        q = 3 * (yy * W + xx)
        r = tl.load(cur_ptr + q, mask=inb, other=0.0).to(tl.float64)
        g = tl.load(cur_ptr + q + 1, mask=inb, other=0.0).to(tl.float64)
        b = tl.load(cur_ptr + q + 2, mask=inb, other=0.0).to(tl.float64)
        v0 = 0.25 * r + 0.5 * g + 0.25 * b
        v1 = 0.5 * (r - b)
        v2 = -0.25 * r + 0.5 * g - 0.25 * b
        f0 = inb & (tl.abs(v0) <= big)
        f1 = inb & (tl.abs(v1) <= big)
        f2 = inb & (tl.abs(v2) <= big)
        lo0 = tl.where(f0, v0.to(tl.float32), big)
        lo1 = tl.where(f1, v1.to(tl.float32), big)
        lo2 = tl.where(f2, v2.to(tl.float32), big)
        hi0 = tl.where(f0, v0.to(tl.float32), -big)
        hi1 = tl.where(f1, v1.to(tl.float32), -big)
        hi2 = tl.where(f2, v2.to(tl.float32), -big)
        blo0 = tl.where(lo0 < blo0, lo0, blo0)
        blo1 = tl.where(lo1 < blo1, lo1, blo1)
        blo2 = tl.where(lo2 < blo2, lo2, blo2)
        bhi0 = tl.where(hi0 > bhi0, hi0, bhi0)
        bhi1 = tl.where(hi1 > bhi1, hi1, bhi1)
        bhi2 = tl.where(hi2 > bhi2, hi2, bhi2)
        if dx * dy == 0:  # the 5-pixel cross
            clo0 = tl.where(lo0 < clo0, lo0, clo0)
            clo1 = tl.where(lo1 < clo1, lo1, clo1)
            clo2 = tl.where(lo2 < clo2, lo2, clo2)
            chi0 = tl.where(hi0 > chi0, hi0, chi0)
            chi1 = tl.where(hi1 > chi1, hi1, chi1)
            chi2 = tl.where(hi2 > chi2, hi2, chi2)
    p0 = 0.25 * h0 + 0.5 * h1 + 0.25 * h2
    p1 = 0.5 * (h0 - h2)
    p2 = -0.25 * h0 + 0.5 * h1 - 0.25 * h2
    # min(max(v, lo), hi) with the host's operand order: a NaN history value stays NaN
    lo = ((blo0 + clo0) * 0.5).to(tl.float64)
    hi = ((bhi0 + chi0) * 0.5).to(tl.float64)
    p0 = tl.where(lo > p0, lo, p0)
    p0 = tl.where(hi < p0, hi, p0)
    lo = ((blo1 + clo1) * 0.5).to(tl.float64)
    hi = ((bhi1 + chi1) * 0.5).to(tl.float64)
    p1 = tl.where(lo > p1, lo, p1)
    p1 = tl.where(hi < p1, hi, p1)
    lo = ((blo2 + clo2) * 0.5).to(tl.float64)
    hi = ((bhi2 + chi2) * 0.5).to(tl.float64)
    p2 = tl.where(lo > p2, lo, p2)
    p2 = tl.where(hi < p2, hi, p2)
    al = tl.zeros((BLOCK,), tl.float64) + alpha
    o0 = tl.where(ok, (al * c0.to(tl.float64) + (1.0 - al) * (p0 + p1 - p2)).to(tl.float32), c0)
    o1 = tl.where(ok, (al * c1.to(tl.float64) + (1.0 - al) * (p0 + p2)).to(tl.float32), c1)
    o2 = tl.where(ok, (al * c2.to(tl.float64) + (1.0 - al) * (p0 - p1 - p2)).to(tl.float32), c2)
    tl.store(out_ptr + 3 * idx, o0, mask=inside)
    tl.store(out_ptr + 3 * idx + 1, o1, mask=inside)
    tl.store(out_ptr + 3 * idx + 2, o2, mask=inside)
    tl.store(keep_ptr + 3 * idx, o0, mask=inside)
    tl.store(keep_ptr + 3 * idx + 1, o1, mask=inside)
    tl.store(keep_ptr + 3 * idx + 2, o2, mask=inside)


__all__ = ["BASE", "FLT_MAX", "RADIANCE", "accumulate_kernel", "block_for", "reproject_kernel",
           "taa_kernel"]
