"""SVGF / A-SVGF's per-frame steps after the reprojection as Triton kernels (docs/temporal.md
§3, §12, §15, §18; the maths in :mod:`dbench.methods.svgf` and
:mod:`dbench.methods.svgf.reference`, the arithmetic of the compiled host path
:mod:`dbench.methods.svgf.numba_path`).

* :data:`temporal_kernel` — per pixel: ``prepare`` (radiance clamp, emission, demodulation by
  clip(albedo, floor, 1), moments, raw luminance), A-SVGF's adaptive history (the filtered
  gradient strata of :mod:`.asvgf` fetched through the motion vectors, N', α and its floor),
  the accumulation of illumination, moments and emission, the frame count and the variance
  from the moments (times Σw² with ``variance_of="mean"``).
* :data:`variance_kernel` — the 7×7 spatial estimate where N < 4 and the variance boosts of
  :mod:`dbench.methods.svgf.boost`.
* :data:`atrous_kernel` — one à-trous iteration (5×5 taps of step 2^i: normal, depth and
  luminance weights, the B3 kernel, variance propagation); optionally it also writes the
  history feedback, and on the last iteration the remodulated output a_eff · I + E. Without
  taps it is the remodulation alone (0 iterations). A-SVGF's gradient filter runs it too, on
  the stratum image with the luminance weight off.

Per-pixel flags (uint8): :data:`TAP` (a neighbour may read the pixel: hit, not an emitter, not
empty), :data:`CENTRE` (its own value counts: not empty), :data:`GATHER` (it gathers from
neighbours: hit, not an emitter), :data:`SHORT` (the gradient shortened its history),
:data:`SPATIAL` (filled and N < 4). The depth gradient (``depth_gradient``: the one-sided
difference of smaller magnitude) is recomputed from the depth plane where it is needed; a pixel
has a hit where its depth plane is > 0. The weights use the host's polynomial e^−x
(``fast_exp_neg``); min/max are selects in the host's operand order.
"""
from __future__ import annotations

import triton.language as tl
from triton.language import core as tl_core  # noqa: F401 - patched by the interpreter (runtime)

from .common import demodulate, depth_gradient
from .runtime import kernel

TAP, CENTRE, GATHER, SHORT, SPATIAL = 1, 2, 4, 8, 16


@kernel
def temporal_kernel(color_ptr, albedo_ptr, emis_ptr, wsrc_ptr, motion_ptr, fetched_ptr,
                    status_ptr, new_ptr, low_ptr, acc_ptr, wn_ptr, var_ptr, flags_ptr, a_ptr,
                    g_ptr, par_ptr, floor, alpha_min, alpha_min_m, H, W, HS, WS,
                    EMISSIVE: tl.constexpr, COUNTING: tl.constexpr, WNB: tl.constexpr,
                    GRAD: tl.constexpr, GMODE: tl.constexpr, ALPHA_FLOOR: tl.constexpr,
                    OF_MEAN: tl.constexpr, FEEDBACK_NONE: tl.constexpr, BLOCK: tl.constexpr):
    """color/albedo/emis/wsrc (H, W, 3), motion (H, W, 2) f32; fetched (R, H, W) reprojected
    planes; status (H, W) u8; new (5 + P, H, W) this frame's history (geometry planes already
    written); low (3, HS, WS) filtered strata [δ, Δ, G]; outputs acc (3, H, W) accumulated
    illumination, wn (3, H, W) feature normal (WNB), var, a (α used), g (G) (H, W) f32, flags
    (H, W) u8. par (2,) f64: n_max, α0. GRAD: 0 SVGF, 1 A-SVGF without strata (G = 0), 2 with;
    GMODE: 0 seed, 1 filtered(_abs), 2 paper."""
    idx = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    hw = H * W
    inside = idx < hw
    y = idx // W
    x = idx - y * W
    big = 3.4028234663852886e38
    hit = inside & (tl.load(new_ptr + idx, mask=inside, other=0.0) > 0)
    c0, c1, c2, present, e0, e1, e2, emitter, i0, i1, i2 = demodulate(
        color_ptr, albedo_ptr, emis_ptr, idx, inside, hit, floor, EMISSIVE, BLOCK)
    lum = 0.2126 * i0 + 0.7152 * i1 + 0.0722 * i2
    if GRAD > 0:  # the raw luminance the next frame's strata compare with (-FLT_MAX: missing)
        lr = 0.2126 * c0 + 0.7152 * c1 + 0.0722 * c2
        tl.store(new_ptr + 4 * hw + idx, tl.where(present, lr, -big), mask=inside)
    ok = inside & (tl.load(status_ptr + idx, mask=inside, other=0) > 0)
    h0 = tl.load(fetched_ptr + idx, mask=ok, other=0.0)
    h1 = tl.load(fetched_ptr + hw + idx, mask=ok, other=0.0)
    h2 = tl.load(fetched_ptr + 2 * hw + idx, mask=ok, other=0.0)
    h3 = tl.load(fetched_ptr + 3 * hw + idx, mask=ok, other=0.0)
    h4 = tl.load(fetched_ptr + 4 * hw + idx, mask=ok, other=0.0)
    hist_n = tl.load(fetched_ptr + 5 * hw + idx, mask=ok, other=0.0)
    h6 = tl.load(fetched_ptr + 6 * hw + idx, mask=ok, other=0.0)
    nmax64 = tl.load(par_ptr)
    nmax = nmax64.to(tl.float32)
    if GRAD > 0:  # adaptive_history: G at the stratum holding round(p + motion(p))
        g = tl.zeros((BLOCK,), tl.float64)
        if GRAD == 2:
            mx = tl.load(motion_ptr + 2 * idx, mask=inside, other=0.0).to(tl.float64)
            my = tl.load(motion_ptr + 2 * idx + 1, mask=inside, other=0.0).to(tl.float64)
            qx = tl.floor(x.to(tl.float64) + mx + 0.5)
            qy = tl.floor(y.to(tl.float64) + my + 0.5)
            inr = hit & (qx >= 0) & (qy >= 0) & (qx < W) & (qy < H)  # False for NaN motion
            s = (tl.where(inr, qy, 0.0).to(tl.int32) // 3) * WS \
                + tl.where(inr, qx, 0.0).to(tl.int32) // 3
            sd = tl.load(low_ptr + s, mask=inr, other=0.0)
            sn = tl.load(low_ptr + HS * WS + s, mask=inr, other=0.0)
            sg = tl.load(low_ptr + 2 * HS * WS + s, mask=inr, other=0.0)
            if GMODE == 0:
                low = sg
            else:  # λ = |δ̂| / Δ̂, squared into the seed's G for "filtered"/"filtered_abs"
                lam = tl.div_rn(tl.abs(sd), tl.where(sn > 0, sn, 1.0))
                low = tl.where(sn > 0, tl.where(lam > 1.0, 1.0, lam), 0.0)
                if GMODE == 1:
                    low = low * low
            low = tl.where(low == low, low, 0.0).to(tl.float64)
            g = tl.where(inr, tl.where(low < 0.0, 0.0, tl.where(low > 1.0, 1.0, low)), 0.0)
        om = 1.0 - g
        p2 = om * om
        p8 = p2 * p2
        p8 = p8 * p8
        n_new = hist_n.to(tl.float64) * (p8 * p2) + 1.0
        n_new = tl.where(nmax64 < n_new, nmax64, n_new)
        al = om / n_new + g
        if GMODE == 2:
            pa = om * tl.load(par_ptr + 1) + g
            inv = 1.0 / n_new
            al = tl.where(inv > pa, inv, pa)
        tl.store(g_ptr + idx, g.to(tl.float32), mask=inside)
        alpha = al.to(tl.float32)
        hist_n = n_new.to(tl.float32) - 1.0  # accumulate() adds the frame back
        if ALPHA_FLOOR:  # α never below SVGF's (docs/temporal.md §4)
            a_c = tl.where(alpha_min > alpha, alpha_min, alpha)
            a_m = tl.where(alpha_min_m > alpha, alpha_min_m, alpha)
        else:
            a_c = alpha
            a_m = alpha
    n1 = hist_n + 1.0
    n = tl.where(ok, tl.where(nmax < n1, nmax, n1), 1.0)
    if GRAD == 0:
        inv = 1.0 / n
        a_c = tl.where(inv > alpha_min, inv, alpha_min)
        a_m = tl.where(inv > alpha_min_m, inv, alpha_min_m)
    a_c = tl.where(ok, a_c, 1.0)
    a_m = tl.where(ok, a_m, 1.0)
    # h* are 0 where the reprojection failed: a missing sample there leaves an empty history
    acc0 = tl.where(present, a_c * i0 + (1.0 - a_c) * h0, h0)
    acc1 = tl.where(present, a_c * i1 + (1.0 - a_c) * h1, h1)
    acc2 = tl.where(present, a_c * i2 + (1.0 - a_c) * h2, h2)
    m0 = tl.where(present, a_m * lum + (1.0 - a_m) * h3, h3)
    m1 = tl.where(present, a_m * (lum * lum) + (1.0 - a_m) * h4, h4)
    n_out = tl.where(present, n, tl.where(ok, hist_n, 0.0))
    a_used = tl.where(present, a_c, 0.0)
    base = new_ptr + 5 * hw + idx
    if EMISSIVE:
        for k in tl.static_range(3):
            he = tl.load(fetched_ptr + (7 + k) * hw + idx, mask=ok, other=0.0)
            if k == 0:
                ek = e0
            elif k == 1:
                ek = e1
            else:
                ek = e2
            tl.store(base + (7 + k) * hw, tl.where(present, a_c * ek + (1.0 - a_c) * he, he),
                     mask=inside)
    short = n_out < 0.0
    if COUNTING:  # frames since the surface appeared (boost.frame_count)
        hf = tl.load(fetched_ptr + (7 + 3 * EMISSIVE) * hw + idx, mask=ok, other=0.0)
        f1 = hf + 1.0
        frames = tl.where(present, tl.where(ok, tl.where(nmax < f1, nmax, f1), 1.0), hf)
        tl.store(base + (7 + 3 * EMISSIVE) * hw, frames, mask=inside)
        short = n_out < frames - 0.5
    filled = n_out > 0
    gather = hit & (emitter == 0)
    v = m1 - m0 * m0
    var = tl.where(v > 0.0, v, 0.0)
    wsq = tl.where(ok, a_used * a_used + (1.0 - a_used) * (1.0 - a_used) * h6, 1.0)
    if OF_MEAN:
        var = var * wsq
    spatial = filled & (n_out < 4.0)
    flags = (tl.where(gather & filled, 1, 0) + tl.where(filled, 2, 0) + tl.where(gather, 4, 0)
             + tl.where(short, 8, 0) + tl.where(spatial, 16, 0))
    if FEEDBACK_NONE:
        tl.store(base, acc0, mask=inside)
        tl.store(base + hw, acc1, mask=inside)
        tl.store(base + 2 * hw, acc2, mask=inside)
    tl.store(base + 3 * hw, m0, mask=inside)
    tl.store(base + 4 * hw, m1, mask=inside)
    tl.store(base + 5 * hw, n_out, mask=inside)
    tl.store(base + 6 * hw, wsq, mask=inside)
    tl.store(acc_ptr + idx, acc0, mask=inside)
    tl.store(acc_ptr + hw + idx, acc1, mask=inside)
    tl.store(acc_ptr + 2 * hw + idx, acc2, mask=inside)
    tl.store(var_ptr + idx, var, mask=inside)
    tl.store(a_ptr + idx, a_used, mask=inside)
    tl.store(flags_ptr + idx, flags.to(tl.uint8), mask=inside)
    if WNB:  # feature_normal: the frame's buffer where hit and finite, else 0
        w0 = tl.load(wsrc_ptr + 3 * idx, mask=inside, other=0.0)
        w1 = tl.load(wsrc_ptr + 3 * idx + 1, mask=inside, other=0.0)
        w2 = tl.load(wsrc_ptr + 3 * idx + 2, mask=inside, other=0.0)
        wok = hit & (tl.abs(w0) <= big) & (tl.abs(w1) <= big) & (tl.abs(w2) <= big)
        tl.store(wn_ptr + idx, tl.where(wok, w0, 0.0), mask=inside)
        tl.store(wn_ptr + hw + idx, tl.where(wok, w1, 0.0), mask=inside)
        tl.store(wn_ptr + 2 * hw + idx, tl.where(wok, w2, 0.0), mask=inside)


@kernel
def variance_kernel(hist_ptr, wn_ptr, flags_ptr, var_ptr, H, W, sz, sn, ez,
                    BOOST: tl.constexpr, OF_MEAN: tl.constexpr, BLOCK: tl.constexpr):
    """hist (5 + P, H, W) this frame's history (depth, moments, N, Σw²); wn (3, H, W) feature
    normal; flags (H, W) u8; var (H, W) f32 read and rewritten. BOOST (variance_boost): 0 none,
    1 Falcor's ("svgf", and "gradient" without a frame count), 2 Schied's ("asvgf"),
    3 "gradient" with A-SVGF's frame count."""
    idx = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    hw = H * W
    inside = idx < hw
    y = idx // W
    x = idx - y * W
    fl = tl.load(flags_ptr + idx, mask=inside, other=0).to(tl.int32)
    filled = (fl & 2) != 0
    spatial = inside & ((fl & 16) != 0)
    short = (fl & 8) != 0
    n = tl.load(hist_ptr + 10 * hw + idx, mask=inside, other=0.0)
    wsq = tl.load(hist_ptr + 11 * hw + idx, mask=inside, other=0.0)
    var = tl.load(var_ptr + idx, mask=inside, other=0.0)
    sv = tl.zeros((BLOCK,), tl.float32)
    if tl.max(tl.where(spatial, 1, 0), axis=0) > 0:  # the 7×7 estimate only near short histories
        z, gx, gy = depth_gradient(hist_ptr, idx, x, y, H, W, inside)
        n0 = tl.load(wn_ptr + idx, mask=inside, other=0.0)
        n1 = tl.load(wn_ptr + hw + idx, mask=inside, other=0.0)
        n2 = tl.load(wn_ptr + 2 * hw + idx, mask=inside, other=0.0)
        go = spatial & ((fl & 4) != 0)
        sw = tl.full((BLOCK,), 1.0, tl.float64)
        s1 = tl.load(hist_ptr + 8 * hw + idx, mask=inside, other=0.0).to(tl.float64)
        s2 = tl.load(hist_ptr + 9 * hw + idx, mask=inside, other=0.0).to(tl.float64)
        for j in range(49):  # a loop, not unrolled: compile time (docs/gpu.md §6)
            if j != 24:
                dy = j // 7 - 3
                dx = j % 7 - 3
                yy = y + dy
                xx = x + dx
                q = yy * W + xx
                inb = go & (yy >= 0) & (yy < H) & (xx >= 0) & (xx < W)
                tq = (tl.load(flags_ptr + q, mask=inb, other=0).to(tl.int32) & 1) != 0
                d = (n0 * tl.load(wn_ptr + q, mask=inb, other=0.0)
                     + n1 * tl.load(wn_ptr + hw + q, mask=inb, other=0.0)
                     + n2 * tl.load(wn_ptr + 2 * hw + q, mask=inb, other=0.0))
                use = inb & tq & (d > 0)
                zq = tl.load(hist_ptr + q, mask=inb, other=0.0)
                ex = sn * tl.log(tl.where(use, d, 1.0)) - tl.abs(z - zq) / (
                    sz * tl.abs(gx * dx + gy * dy) + ez)
                wt = tl.where(use, tl.exp(ex), 0.0).to(tl.float64)
                sw += wt
                s1 += wt * tl.load(hist_ptr + 8 * hw + q, mask=use, other=0.0).to(tl.float64)
                s2 += wt * tl.load(hist_ptr + 9 * hw + q, mask=use, other=0.0).to(tl.float64)
        mean = s1 / sw
        est = s2 / sw - mean * mean
        sv = tl.where(est > 0.0, est, 0.0).to(tl.float32)
    nn = tl.where(n > 1.0, n, 1.0)
    if BOOST == 1:  # Falcor: ×4/N on the spatial estimate
        sv = tl.div_rn(sv * 4.0, nn)
    if BOOST == 3:  # Falcor's on new surfaces, Schied's (below) where the gradient shortened
        sv = tl.where(short, sv, tl.div_rn(sv * 4.0, nn))
    if OF_MEAN:
        sv = sv * wsq
    var = tl.where(spatial, sv, var)
    boost = tl.div_rn(tl.full((BLOCK,), 64.0, tl.float32), nn * nn)
    boost = tl.where(boost > 1.0, boost, 1.0)
    if BOOST == 2:  # Schied: every estimate × max(1, 64/N²)
        var = tl.where(filled, var * boost, var)
    if BOOST == 3:
        var = tl.where(filled & short, var * boost, var)
    tl.store(var_ptr + idx, var, mask=inside)


@kernel(do_not_specialize=("step",))
def atrous_kernel(cin_ptr, vin_ptr, z_ptr, nrm_ptr, flags_ptr, cout_ptr, vout_ptr, fb_ptr,
                  albedo_ptr, emis_ptr, out_ptr, H, W, step, sz, sn, sl, ez, eps_var, floor,
                  USE_LUM: tl.constexpr, GAUSS: tl.constexpr, SN128: tl.constexpr,
                  TAPS: tl.constexpr, USE_VAR: tl.constexpr, FEEDBACK: tl.constexpr,
                  FINAL: tl.constexpr, EMISSIVE: tl.constexpr, BLOCK: tl.constexpr):
    """cin (3, H, W), vin (H, W) f32 this iteration's colour and variance; z (H, W) depth;
    nrm (3, H, W) normals; flags (H, W) u8; cout (3, H, W), vout (H, W) the result; fb (3, H, W)
    a copy of it (FEEDBACK); FINAL: out (H, W, 3) = cout · clip(albedo (H, W, 3), floor, 1) +
    emis (3, H, W) (EMISSIVE, else + 0). TAPS False: cout = cin (the remodulation alone)."""
    idx = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    hw = H * W
    inside = idx < hw
    y = idx // W
    x = idx - y * W
    big = 3.4028234663852886e38
    c0 = tl.load(cin_ptr + idx, mask=inside, other=0.0)
    c1 = tl.load(cin_ptr + hw + idx, mask=inside, other=0.0)
    c2 = tl.load(cin_ptr + 2 * hw + idx, mask=inside, other=0.0)
    vc = tl.zeros((BLOCK,), tl.float32)
    if USE_VAR:
        vc = tl.load(vin_ptr + idx, mask=inside, other=0.0)
    if TAPS:
        fl = tl.load(flags_ptr + idx, mask=inside, other=0).to(tl.int32)
        z, gx, gy = depth_gradient(z_ptr, idx, x, y, H, W, inside)
        n0 = tl.load(nrm_ptr + idx, mask=inside, other=0.0)
        n1 = tl.load(nrm_ptr + hw + idx, mask=inside, other=0.0)
        n2 = tl.load(nrm_ptr + 2 * hw + idx, mask=inside, other=0.0)
        lum = 0.2126 * c0 + 0.7152 * c1 + 0.0722 * c2
        isl = tl.zeros((BLOCK,), tl.float32)
        if USE_LUM:  # 1 / (σ_l √(g₃ₓ₃(Var) + ε)), the blur with edge replication, in float64
            ym = tl.where(y > 0, y - 1, 0)
            yp = tl.where(y + 1 < H, y + 1, H - 1)
            xm = tl.where(x > 0, x - 1, 0)
            xp = tl.where(x + 1 < W, x + 1, W - 1)
            gb = tl.zeros((BLOCK,), tl.float64)
            for r in tl.static_range(3):
                if r == 0:
                    yy = ym
                elif r == 1:
                    yy = y
                else:
                    yy = yp
                vl = tl.load(vin_ptr + yy * W + xm, mask=inside, other=0.0).to(tl.float64)
                vm = tl.load(vin_ptr + yy * W + x, mask=inside, other=0.0).to(tl.float64)
                vr = tl.load(vin_ptr + yy * W + xp, mask=inside, other=0.0).to(tl.float64)
                row = 0.25 * vl + 0.5 * vm + 0.25 * vr
                if r == 1:
                    gb += 0.5 * row
                else:
                    gb += 0.25 * row
            gb = tl.where(gb > 0.0, gb, 0.0)
            isl = (1.0 / (sl * tl.sqrt(gb + eps_var))).to(tl.float32)
        hitp = (fl & 4) != 0
        wc = tl.where((fl & 2) != 0, 0.140625, 0.0)  # h(0)² for an own (non-empty) value
        sw = wc
        s0 = wc * c0
        s1 = wc * c1
        s2 = wc * c2
        sv = wc * wc * vc
        for t in tl.static_range(25):
            oy = t // 5 - 2
            ox = t % 5 - 2
            if t != 12:  # not the centre
                ax = ox if ox >= 0 else -ox
                ay = oy if oy >= 0 else -oy
                hx = 0.375 if ax == 0 else (0.25 if ax == 1 else 0.0625)
                hy = 0.375 if ay == 0 else (0.25 if ay == 1 else 0.0625)
                dy = oy * step
                dx = ox * step
                yy = y + dy
                xx = x + dx
                q = yy * W + xx
                inb = inside & hitp & (yy >= 0) & (yy < H) & (xx >= 0) & (xx < W)
                tq = inb & ((tl.load(flags_ptr + q, mask=inb, other=0).to(tl.int32) & 1) != 0)
                d = (n0 * tl.load(nrm_ptr + q, mask=tq, other=0.0)
                     + n1 * tl.load(nrm_ptr + hw + q, mask=tq, other=0.0)
                     + n2 * tl.load(nrm_ptr + 2 * hw + q, mask=tq, other=0.0))
                d = tl.where(d > 0.0, d, 0.0)
                if SN128:  # max(0, n·n')^128: seven squarings
                    d = d * d
                    d = d * d
                    d = d * d
                    d = d * d
                    d = d * d
                    d = d * d
                    d = d * d
                else:
                    d = tl.where(d > 0.0, tl.exp(sn * tl.log(tl.where(d > 0.0, d, 1.0))), 0.0)
                den = sz * tl.abs(gx * dx + gy * dy) + ez
                e = tl.abs(z - tl.load(z_ptr + q, mask=tq, other=0.0)) / den
                q0 = tl.load(cin_ptr + q, mask=tq, other=0.0)
                q1 = tl.load(cin_ptr + hw + q, mask=tq, other=0.0)
                q2 = tl.load(cin_ptr + 2 * hw + q, mask=tq, other=0.0)
                if USE_LUM:
                    dl = tl.abs(lum - (0.2126 * q0 + 0.7152 * q1 + 0.0722 * q2)) * isl
                    dl = tl.where(1e4 < dl, 1e4, dl)
                    if GAUSS:
                        e = e + dl * dl
                    else:
                        e = e + dl
                # the host's e^−x: exp(−x/64)^64, degree-7 Taylor polynomial, x capped at 30
                p = tl.where(30.0 < e, 30.0, e) * 0.015625
                pe = -1.9841269841269841e-4 * p + 1.3888888888888889e-3
                pe = pe * p - 8.3333333333333333e-3
                pe = pe * p + 4.1666666666666667e-2
                pe = pe * p - 1.6666666666666667e-1
                pe = pe * p + 0.5
                pe = pe * p - 1.0
                pe = pe * p + 1.0
                pe = pe * pe
                pe = pe * pe
                pe = pe * pe
                pe = pe * pe
                pe = pe * pe
                pe = pe * pe
                w = tl.where(tq, (hx * hy) * d * pe, 0.0)
                sw += w
                s0 += w * q0
                s1 += w * q1
                s2 += w * q2
                if USE_VAR:
                    sv += w * w * tl.load(vin_ptr + q, mask=tq, other=0.0)
        # in float64: a pixel without its own sample may gather only subnormal weights
        pos = sw > 0
        inv = 1.0 / tl.where(pos, sw, 1.0).to(tl.float64)
        o0 = tl.where(pos, (s0.to(tl.float64) * inv).to(tl.float32), 0.0)
        o1 = tl.where(pos, (s1.to(tl.float64) * inv).to(tl.float32), 0.0)
        o2 = tl.where(pos, (s2.to(tl.float64) * inv).to(tl.float32), 0.0)
        ov = tl.where(pos, (sv.to(tl.float64) * inv * inv).to(tl.float32), 0.0)
    else:
        o0 = c0
        o1 = c1
        o2 = c2
        ov = vc
    tl.store(cout_ptr + idx, o0, mask=inside)
    tl.store(cout_ptr + hw + idx, o1, mask=inside)
    tl.store(cout_ptr + 2 * hw + idx, o2, mask=inside)
    if USE_VAR:
        tl.store(vout_ptr + idx, ov, mask=inside)
    if FEEDBACK:  # the history keeps this iteration's output (feedback_tap)
        tl.store(fb_ptr + idx, o0, mask=inside)
        tl.store(fb_ptr + hw + idx, o1, mask=inside)
        tl.store(fb_ptr + 2 * hw + idx, o2, mask=inside)
    if FINAL:  # remodulate: a_eff · I + E
        for k in tl.static_range(3):
            a = tl.load(albedo_ptr + 3 * idx + k, mask=inside, other=1.0)
            a = tl.where(tl.abs(a) <= big, tl.where(a < floor, floor, tl.where(a > 1.0, 1.0, a)),
                         1.0)
            ek = tl.zeros((BLOCK,), tl.float32)
            if EMISSIVE:
                ek = tl.load(emis_ptr + k * hw + idx, mask=inside, other=0.0)
            if k == 0:
                ok_ = o0
            elif k == 1:
                ok_ = o1
            else:
                ok_ = o2
            tl.store(out_ptr + 3 * idx + k, ok_ * a + ek, mask=inside)


__all__ = ["CENTRE", "GATHER", "SHORT", "SPATIAL", "TAP", "atrous_kernel", "temporal_kernel",
           "variance_kernel"]
