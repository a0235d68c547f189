"""BMFR's per-frame steps after the reprojection as Triton kernels (docs/temporal.md §9, §17;
the maths in :mod:`dbench.methods.bmfr`, the arithmetic of its compiled host path
:mod:`dbench.methods.bmfr.numba_path`, :mod:`dbench.methods.bmfr.handback`).

* :data:`bmfr_accumulate_kernel` — per pixel: ``prepare`` (radiance clamp, emission,
  demodulation), A-SVGF's adaptive history when a gradient is used, accumulation 1 of the
  illumination (and emission), the hand-back's z² and Σw² planes, the flags, α2.
* :data:`bmfr_fit_kernel` — one program per block of the grid: the features, the per-block
  scaling, the hashed feature noise, the Householder QR of the block's (pixels × features)
  matrix with the three channels' right-hand sides (float64, in registers; a fit row's pivot is
  its rank among the block's fit pixels, so the reflections are the host's on its compacted
  rows), the back substitution with the rank safeguard and the reconstruction.
* :data:`bmfr_finish_kernel` — per pixel: the hand-back's last pass (with ``HB``: the window
  sums of :mod:`.handback`'s planes, λ, the clamp), accumulation 2, remodulation, the history
  validity plane.

Flags (uint8): :data:`FIT` (hit, no emitter, filled: the fit set and the hand-back mask),
:data:`RECON` (hit, no emitter), :data:`PRESENT` (finite sample), :data:`OK` (history
reprojected). Min/max are selects in the host's operand order.
"""
from __future__ import annotations

import triton.language as tl
from triton.language import core as tl_core  # noqa: F401 - patched by the interpreter (runtime)

from .common import demodulate
from .runtime import kernel

FIT, RECON, PRESENT, OK = 1, 2, 4, 8
#: The method's history planes (after the BASE geometry planes): z 0-2, N 3, the accumulated
#: fit 4-6, z² 7-9, Σw² 10, emission 11-13, validity 14 (the reprojection's "usable" plane).
PLANES = 15
VALID_PLANE = 14
EMIS_PLANE = 11


@kernel
def bmfr_accumulate_kernel(color_ptr, albedo_ptr, emis_ptr, motion_ptr, fetched_ptr, status_ptr,
                           new_ptr, low_ptr, illum_ptr, flags_ptr, a2_ptr, g_ptr, floor, alpha1,
                           alpha2, n_max, H, W, WS, nu_ptr, EMISSIVE: tl.constexpr,
                           HB: tl.constexpr, GRAD: tl.constexpr, BLOCK: tl.constexpr):
    """color/albedo/emis (H, W, 3), motion (H, W, 2) f32; fetched (R, H, W) reprojected history
    planes; status (H, W) u8; new (5 + 15, H, W) this frame's history (geometry written);
    low (3, HS, WS) filtered gradient strata (GRAD 2); outputs illum (3, H, W), flags (H, W)
    u8, a2 (H, W) α of accumulation 2 (1 where the history failed), nu (H, W) the N a sample
    gets, g (H, W) G (GRAD > 0).
    GRAD: 0 the fixed α rule, 1 A-SVGF's history without strata (G = 0), 2 with."""
    idx = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    hw = H * W
    inside = idx < hw
    y = idx // W
    x = idx - y * W
    big = 3.4028234663852886e38
    hit = inside & (tl.load(new_ptr + idx, mask=inside, other=0.0) > 0)
    c0, c1, c2, present, e0, e1, e2, emitter, i0, i1, i2 = demodulate(
        color_ptr, albedo_ptr, emis_ptr, idx, inside, hit, floor, EMISSIVE, BLOCK)
    # the raw luminance the next frame's gradient strata compare with (-FLT_MAX: missing)
    lr = 0.2126 * c0 + 0.7152 * c1 + 0.0722 * c2
    tl.store(new_ptr + 4 * hw + idx, tl.where(present, lr, -big), mask=inside)
    ok = inside & (tl.load(status_ptr + idx, mask=inside, other=0) > 0)
    h0 = tl.load(fetched_ptr + idx, mask=ok, other=0.0)
    h1 = tl.load(fetched_ptr + hw + idx, mask=ok, other=0.0)
    h2 = tl.load(fetched_ptr + 2 * hw + idx, mask=ok, other=0.0)
    hist_n = tl.load(fetched_ptr + 3 * hw + idx, mask=ok, other=0.0)
    nmax = n_max
    if GRAD > 0:  # gradient_history: G at the stratum holding round(p + motion(p)), mode seed
        g = tl.zeros((BLOCK,), tl.float64)
        if GRAD == 2:
            mx = tl.load(motion_ptr + 2 * idx, mask=inside, other=0.0).to(tl.float64)
            my = tl.load(motion_ptr + 2 * idx + 1, mask=inside, other=0.0).to(tl.float64)
            qx = tl.floor(x.to(tl.float64) + mx + 0.5)
            qy = tl.floor(y.to(tl.float64) + my + 0.5)
            inr = hit & (qx >= 0) & (qy >= 0) & (qx < W) & (qy < H)  # False for NaN motion
            s = (tl.where(inr, qy, 0.0).to(tl.int32) // 3) * WS \
                + tl.where(inr, qx, 0.0).to(tl.int32) // 3
            hs_ws = ((H + 2) // 3) * WS
            sg = tl.load(low_ptr + 2 * hs_ws + s, mask=inr, other=0.0)
            sg = tl.where(sg == sg, sg, 0.0).to(tl.float64)
            g = tl.where(inr, tl.where(sg < 0.0, 0.0, tl.where(sg > 1.0, 1.0, sg)), 0.0)
        om = 1.0 - g
        p2 = om * om
        p8 = p2 * p2
        p8 = p8 * p8
        n_new = hist_n.to(tl.float64) * (p8 * p2) + 1.0
        n_new = tl.where(n_max < n_new, n_max, n_new)
        al = (om / n_new + g).to(tl.float32)
        tl.store(g_ptr + idx, g.to(tl.float32), mask=inside)
        hist_n = n_new.to(tl.float32) - 1.0  # accumulate() adds the frame back
        al1 = tl.where(al > alpha1, al, alpha1)  # np.maximum(a, α): NaN-free here
        al2 = tl.where(al > alpha2, al, alpha2)
    n1 = hist_n + 1.0
    n = tl.where(ok, tl.where(nmax < n1, nmax, n1), 1.0)
    if GRAD == 0:
        inv = 1.0 / n
        al1 = tl.where(alpha1 > inv, alpha1, inv)
        al2 = tl.where(alpha2 > inv, alpha2, inv)
    a = tl.where(ok, al1, 1.0)
    tl.store(a2_ptr + idx, tl.where(ok, al2, 1.0), mask=inside)
    tl.store(nu_ptr + idx, n, mask=inside)
    # accumulate_fast: a missing sample keeps the history (0 where none) and leaves α = 0
    z0 = tl.where(present, a * i0 + (1.0 - a) * h0, h0)
    z1 = tl.where(present, a * i1 + (1.0 - a) * h1, h1)
    z2 = tl.where(present, a * i2 + (1.0 - a) * h2, h2)
    nn = tl.where(present, n, tl.where(ok, hist_n, 0.0))
    a_used = tl.where(present, a, 0.0)
    base = new_ptr + 5 * hw + idx
    tl.store(base, z0, mask=inside)
    tl.store(base + hw, z1, mask=inside)
    tl.store(base + 2 * hw, z2, mask=inside)
    tl.store(base + 3 * hw, nn, mask=inside)
    if EMISSIVE:
        f0 = tl.load(fetched_ptr + 11 * hw + idx, mask=ok, other=0.0)
        f1 = tl.load(fetched_ptr + 12 * hw + idx, mask=ok, other=0.0)
        f2 = tl.load(fetched_ptr + 13 * hw + idx, mask=ok, other=0.0)
        tl.store(base + 11 * hw, tl.where(present, a * e0 + (1.0 - a) * f0, f0), mask=inside)
        tl.store(base + 12 * hw, tl.where(present, a * e1 + (1.0 - a) * f1, f1), mask=inside)
        tl.store(base + 13 * hw, tl.where(present, a * e2 + (1.0 - a) * f2, f2), mask=inside)
    if HB:  # moments_fast: z² with the same α, S = α² + (1 − α)² S←
        q0 = tl.load(fetched_ptr + 7 * hw + idx, mask=ok, other=0.0)
        q1 = tl.load(fetched_ptr + 8 * hw + idx, mask=ok, other=0.0)
        q2 = tl.load(fetched_ptr + 9 * hw + idx, mask=ok, other=0.0)
        sp = tl.load(fetched_ptr + 10 * hw + idx, mask=ok, other=0.0)
        om1 = 1.0 - a_used
        tl.store(base + 10 * hw, a_used * a_used + om1 * om1 * sp, mask=inside)
        tl.store(base + 7 * hw, a_used * (i0 * i0) + om1 * q0, mask=inside)
        tl.store(base + 8 * hw, a_used * (i1 * i1) + om1 * q1, mask=inside)
        tl.store(base + 9 * hw, a_used * (i2 * i2) + om1 * q2, mask=inside)
        tl.store(illum_ptr + idx, i0, mask=inside)
        tl.store(illum_ptr + hw + idx, i1, mask=inside)
        tl.store(illum_ptr + 2 * hw + idx, i2, mask=inside)
    recon = hit & (emitter == 0)
    fit = recon & (nn > 0)
    fl = (tl.where(fit, 1, 0) + tl.where(recon, 2, 0) + tl.where(present, 4, 0)
          + tl.where(ok, 8, 0))
    tl.store(flags_ptr + idx, fl.to(tl.uint8), mask=inside)


@kernel(do_not_specialize=("Y0", "X0", "NBX", "seed_lo", "seed_hi"))
def bmfr_fit_kernel(z_ptr, normal_ptr, pos_ptr, flags_ptr, out_ptr, dropped_ptr, H, W, Y0, X0,
                    NBX, seed_lo, seed_hi, amp, rcond, B: tl.constexpr, BP: tl.constexpr,
                    NN: tl.constexpr, NP: tl.constexpr, NP2: tl.constexpr,
                    NOISE: tl.constexpr, CLAMP: tl.constexpr):
    """z (3, H, W) f32 accumulated illumination; normal/pos (H, W, 3) f32; flags (H, W) u8;
    out (3, H, W) f32 the fit (z where a block has no fit row or nothing to reconstruct, and at
    pixels not reconstructed); dropped (blocks,) i32. Block b: rows Y0 + (b // NBX)·B …, columns
    X0 + (b % NBX)·B … (clipped); BP = next power of two ≥ B². Columns: 1, n (NN), p (NP),
    p² (NP2), then the three right-hand sides; 16 in all. seed = seed_hi·2³² + seed_lo."""
    pid = tl.program_id(0)
    by = pid // NBX
    bx = pid - by * NBX
    hw = H * W
    r = tl.arange(0, BP)
    ly = r // B
    lx = r - ly * B
    yy = Y0 + by * B + ly
    xx = X0 + bx * B + lx
    inb = (r < B * B) & (yy >= 0) & (yy < H) & (xx >= 0) & (xx < W)
    pix = tl.where(inb, yy * W + xx, 0)
    fl = tl.load(flags_ptr + pix, mask=inb, other=0).to(tl.int32)
    fit = inb & ((fl & 1) != 0)
    rec = inb & ((fl & 2) != 0)
    fit_i = tl.where(fit, 1, 0)
    rows = tl.sum(fit_i, axis=0)
    anyrec = tl.max(tl.where(rec, 1, 0), axis=0) > 0
    rank = tl.cumsum(fit_i, axis=0) - 1
    M: tl.constexpr = 1 + 3 * NN + 3 * NP + 3 * NP2
    CN: tl.constexpr = 1
    CP: tl.constexpr = 1 + 3 * NN
    CQ: tl.constexpr = CP + 3 * NP
    c = tl.arange(0, 16)
    c2 = c[None, :]
    isn = (c2 >= CN) & (c2 < CN + 3 * NN)
    isp = (c2 >= CP) & (c2 < CP + 3 * NP)
    isq = (c2 >= CQ) & (c2 < CQ + 3 * NP2)
    isz = (c2 >= M) & (c2 < M + 3)
    scaled = (c >= CP) & (c < M)
    rm = inb[:, None]
    nv = tl.load(normal_ptr + 3 * pix[:, None] + tl.where(isn, c2 - CN, 0), mask=rm & isn,
                 other=0.0).to(tl.float64)
    pv = tl.load(pos_ptr + 3 * pix[:, None] + tl.where(isp, c2 - CP, tl.where(isq, c2 - CQ, 0)),
                 mask=rm & (isp | isq), other=0.0).to(tl.float64)
    zv = tl.load(z_ptr + tl.where(isz, c2 - M, 0) * hw + pix[:, None], mask=rm & isz,
                 other=0.0).to(tl.float64)
    raw = tl.where(c2 == 0, 1.0, tl.where(isn, nv, tl.where(isp, pv, tl.where(isq, pv * pv,
                                                                                0.0))))
    # per-block scaling of the position columns over the fit rows: (f − min) / max(range, 1)
    lo = tl.min(tl.where(fit[:, None], raw, float("inf")), axis=0)
    hi = tl.max(tl.where(fit[:, None], raw, -float("inf")), axis=0)
    rng = hi - lo
    shift = tl.where(scaled, lo, 0.0)
    scale = tl.where(scaled, 1.0 / tl.where(rng > 1.0, rng, 1.0), 1.0)
    a_m = tl.where(scaled[None, :], (raw - shift[None, :]) * scale[None, :], raw)
    if NOISE:  # splitmix64 of (seed, pixel, column // 4), 16 bits per column
        # (an int argument equal to 1 arrives as a constexpr when compiled: add to a tensor)
        hi64 = (tl.zeros((), tl.int64) + seed_hi).to(tl.uint64)
        lo64 = (tl.zeros((), tl.int64) + seed_lo).to(tl.uint64)
        seed = (hi64 << tl.full((), 32, tl.uint64)) | lo64
        gold = tl.full((), 0x9E3779B97F4A7C15, tl.uint64)
        m1 = tl.full((), 0xBF58476D1CE4E5B9, tl.uint64)
        m2 = tl.full((), 0x94D049BB133111EB, tl.uint64)
        s30 = tl.full((), 30, tl.uint64)
        s27 = tl.full((), 27, tl.uint64)
        s31 = tl.full((), 31, tl.uint64)
        hz = (seed * gold + pix[:, None].to(tl.uint64) * m1
              + (c2 // 4).to(tl.uint64) * m2)
        hz = (hz ^ (hz >> s30)) * m1
        hz = (hz ^ (hz >> s27)) * m2
        hz = hz ^ (hz >> s31)
        part = (hz >> (16 * (c2 % 4)).to(tl.uint64)) & tl.full((), 0xFFFF, tl.uint64)
        u = (part.to(tl.float64) + 0.5) * (1.0 / 65536.0)
        a_m = tl.where((c2 >= 1) & (c2 < M), a_m + amp * (u - 0.5), a_m)
    mt = tl.where(fit[:, None] & (c2 < M), a_m, tl.where(fit[:, None] & isz, zv, 0.0))
    # Householder on the first M columns, pivot row k = the fit pixel of rank k
    for k in tl.static_range(M):
        act = fit & (rank >= k)
        piv = fit & (rank == k)
        colk = tl.sum(tl.where(c2 == k, mt, 0.0), axis=1)
        ck = tl.where(act, colk, 0.0)
        norm2 = tl.sum(ck * ck, axis=0)
        norm = tl.sqrt(norm2)
        x0 = tl.sum(tl.where(piv, colk, 0.0), axis=0)
        s = tl.where(x0 >= 0, -1.0, 1.0)
        v0 = x0 - s * norm
        vv = norm2 - x0 * x0 + v0 * v0
        go = vv > 0.0
        v = tl.where(piv, v0, ck)
        dots = tl.sum(tl.where(act[:, None], v[:, None] * mt, 0.0), axis=0)
        f = 2.0 * dots / tl.where(go, vv, 1.0)
        # the reflection where vv > 0 (a zero column is left as it is), as vectors: the
        # interpreter cannot combine a scalar mask with a tensor one
        go_r = act & ((tl.zeros((BP,), tl.float64) + vv) > 0.0)
        upd = (c > k) & (c < M + 3)
        mt = tl.where(go_r[:, None] & upd[None, :], mt - f[None, :] * v[:, None], mt)
        mt = tl.where(go_r[:, None] & (c2 == k), tl.where(piv, s * norm, 0.0)[:, None], mt)
    # R's rows (zero for k ≥ rows: no pivot), the diagonal's largest magnitude
    ri = tl.arange(0, 16)
    rt = tl.zeros((16, 16), tl.float64)
    for k in tl.static_range(M):
        rk = tl.sum(tl.where((fit & (rank == k))[:, None], mt, 0.0), axis=0)
        rt = tl.where(ri[:, None] == k, rk[None, :], rt)
    diag = tl.abs(tl.sum(tl.where(ri[:, None] == c2, rt, 0.0), axis=1))
    dmax = tl.max(tl.where(ri < M, diag, 0.0), axis=0)
    cq = tl.arange(0, 4)
    xs = tl.zeros((16, 4), tl.float64)
    dropped = 0
    for i in tl.static_range(M):
        k = M - 1 - i
        rk = tl.sum(tl.where(ri[:, None] == k, rt, 0.0), axis=0)
        d = tl.sum(tl.where(c == k, rk, 0.0), axis=0)
        keep = tl.abs(d) > rcond * dmax
        rhs = tl.sum(tl.where(c[:, None] == M + cq[None, :], rk[:, None], 0.0), axis=0)
        sub = tl.sum(tl.where(((c > k) & (c < M))[:, None], rk[:, None] * xs, 0.0), axis=0)
        xk = tl.where(keep, (rhs - sub) / tl.where(keep, d, 1.0), 0.0)
        xs = tl.where(c[:, None] == k, xk[None, :], xs)
        dropped += tl.where(keep, 0, 1)
    tl.store(dropped_ptr + pid, tl.where(rows > 0, dropped, 0))
    # y = b + Σ_j f_j X'_j with the scaling folded into the coefficients; noise-free features
    coef = scale[:, None] * xs
    b0 = -tl.sum(shift[:, None] * coef, axis=0)
    use = rec & (rows > 0) & anyrec
    for q in tl.static_range(3):
        cf = tl.sum(tl.where(cq[None, :] == q, coef, 0.0), axis=1)
        bq = tl.sum(tl.where(cq == q, b0, 0.0), axis=0)
        acc = bq + tl.sum(tl.where(c2 < M, raw * cf[None, :], 0.0), axis=1)
        if CLAMP:
            acc = tl.where(acc > 0.0, acc, 0.0)
        zq = tl.load(z_ptr + q * hw + pix, mask=inb, other=0.0)
        tl.store(out_ptr + q * hw + pix, tl.where(use, acc.to(tl.float32), zq), mask=inb)


@kernel
def bmfr_finish_kernel(fit_ptr, z_ptr, var_ptr, low_ptr, hh_ptr, q_ptr, flags_ptr, fetched_ptr,
                       a2_ptr, nu_ptr, new_ptr, albedo_ptr, out_ptr, n2_ptr, floor, H, W,
                       HB: tl.constexpr, SIGNED: tl.constexpr, CLAMP: tl.constexpr,
                       EMISSIVE: tl.constexpr, BLOCK: tl.constexpr):
    """fit, z, var, low, hh, q (3, H, W) f32 (the block fit, accumulated z, the hand-back's
    planes); flags (H, W) u8; fetched (R, H, W) reprojected history; a2, nu (H, W) α and N of
    the accumulations; new (5 + 15, H, W) this frame's history (the accumulated fit, validity
    written here); albedo (H, W, 3); out (H, W, 3) remodulated output; n2 (H, W)."""
    idx = tl.program_id(0) * BLOCK + tl.arange(0, BLOCK)
    hw = H * W
    inside = idx < hw
    y = idx // W
    x = idx - y * W
    big = 3.4028234663852886e38
    fl = tl.load(flags_ptr + idx, mask=inside, other=0).to(tl.int32)
    fit = inside & ((fl & 1) != 0)
    recon = inside & ((fl & 2) != 0)
    ok = inside & ((fl & 8) != 0)
    hit = inside & (tl.load(new_ptr + idx, mask=inside, other=0.0) > 0)
    filled = inside & (tl.load(new_ptr + 8 * hw + idx, mask=inside, other=0.0) > 0)
    sample_ok = filled | recon
    a = tl.load(a2_ptr + idx, mask=inside, other=1.0)
    nu = tl.load(nu_ptr + idx, mask=inside, other=0.0)
    tl.store(n2_ptr + idx, tl.where(sample_ok, nu, 0.0), mask=inside)
    tl.store(new_ptr + 19 * hw + idx, tl.where(hit & sample_ok, 1.0, 0.0), mask=inside)
    if HB:
        # the window's fit-pixel count, 1 / the window's count inside the image (7×7)
        cx = (tl.where(x + 3 < W, x + 3, W - 1) - tl.where(x - 3 > 0, x - 3, 0) + 1)
        cy = (tl.where(y + 3 < H, y + 3, H - 1) - tl.where(y - 3 > 0, y - 3, 0) + 1)
        inv7 = (1.0 / cx.to(tl.float64)).to(tl.float32) * (1.0 / cy.to(tl.float64)).to(tl.float32)
        mc = tl.zeros((BLOCK,), tl.float32)
        if SIGNED:
            for ky in tl.static_range(7):
                yy = y + (ky - 3)
                rowin = inside & (yy >= 0) & (yy < H)
                mx = tl.zeros((BLOCK,), tl.float32)
                for kx in tl.static_range(7):
                    xx = x + (kx - 3)
                    inb = rowin & (xx >= 0) & (xx < W)
                    fq = tl.load(flags_ptr + yy * W + xx, mask=inb, other=0).to(tl.int32)
                    mx += tl.where(inb & ((fq & 1) != 0), 1.0, 0.0)
                mc += tl.where(rowin, mx, 0.0)
    for c in range(3):  # a loop, not unrolled: compile time (docs/gpu.md §6)
        yv = tl.load(fit_ptr + c * hw + idx, mask=inside, other=0.0)
        if HB:  # residual_handback's last pass: window sums, λ, y + low + λ·high
            eh = tl.zeros((BLOCK,), tl.float32)
            ev = tl.zeros((BLOCK,), tl.float32)
            eq = tl.zeros((BLOCK,), tl.float32)
            for ky in tl.static_range(7):
                yy = y + (ky - 3)
                rowin = inside & (yy >= 0) & (yy < H)
                hx = tl.zeros((BLOCK,), tl.float32)
                vx = tl.zeros((BLOCK,), tl.float32)
                qx = tl.zeros((BLOCK,), tl.float32)
                for kx in tl.static_range(7):
                    xx = x + (kx - 3)
                    inb = rowin & (xx >= 0) & (xx < W)
                    q = c * hw + yy * W + xx
                    fq = tl.load(flags_ptr + yy * W + xx, mask=inb, other=0).to(tl.int32)
                    m_q = inb & ((fq & 1) != 0)
                    hx += tl.load(hh_ptr + q, mask=inb, other=0.0)
                    vx += tl.where(m_q, tl.load(var_ptr + q, mask=m_q, other=0.0), 0.0)
                    if SIGNED:
                        qx += tl.load(q_ptr + q, mask=inb, other=0.0)
                eh += tl.where(rowin, hx, 0.0)
                ev += tl.where(rowin, vx, 0.0)
                eq += tl.where(rowin, qx, 0.0)
            d = eh - ev
            excess = tl.where(d < 0.0, 0.0, d) * inv7
            vc = tl.load(var_ptr + c * hw + idx, mask=inside, other=0.0)
            total = excess.to(tl.float64) + vc.to(tl.float64)
            lam = tl.where(total > 0.0, (excess.to(tl.float64)
                                         / tl.where(total > 0.0, total, 1.0)).to(tl.float32), 1.0)
            low = tl.load(low_ptr + c * hw + idx, mask=inside, other=0.0)
            zc = tl.load(z_ptr + c * hw + idx, mask=fit, other=0.0)
            high = tl.where(fit, zc - yv, 0.0) - low
            if SIGNED:  # λ_neg = 1 − n / (2 Σ n2/V3) where positive
                e2 = 2.0 * eq
                lam_neg = tl.where(e2 > mc, 1.0 - mc / tl.where(e2 > mc, e2, 1.0), 0.0)
                lam = tl.where(high < 0.0, tl.where(lam_neg > lam, lam_neg, lam), lam)
            yv = tl.where(fit, yv + (low + lam * high), yv)
            if CLAMP:
                yv = tl.where(yv < 0.0, 0.0, yv)
        hy = tl.load(fetched_ptr + (4 + c) * hw + idx, mask=ok, other=0.0)
        ya = tl.where(sample_ok, a * yv + (1.0 - a) * hy, hy)
        tl.store(new_ptr + (9 + c) * hw + idx, ya, mask=inside)
        al = tl.load(albedo_ptr + 3 * idx + c, mask=inside, other=1.0)
        al = tl.where(tl.abs(al) <= big,
                      tl.where(al < floor, floor, tl.where(al > 1.0, 1.0, al)), 1.0)
        em = tl.zeros((BLOCK,), tl.float32)
        if EMISSIVE:
            em = tl.load(new_ptr + (16 + c) * hw + idx, mask=inside, other=0.0)
        tl.store(out_ptr + 3 * idx + c, ya * al + em, mask=inside)


__all__ = ["EMIS_PLANE", "FIT", "OK", "PLANES", "PRESENT", "RECON", "VALID_PLANE",
           "bmfr_accumulate_kernel", "bmfr_finish_kernel", "bmfr_fit_kernel"]
