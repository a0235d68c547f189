"""The spatio-temporal window of the transient ``statistical`` denoiser as one Triton kernel
launch (docs/gpu.md §2; the method in README.md's method table, the maths in
:mod:`dbench.methods.statistical.transient` and :mod:`dbench.methods.statistical.shrink`).

For every voxel i = (bin t, row y, column x) of the bins handed in, the kernel sums over the
(2r+1)² × (2r_t+1) window without its centre
W_ij · planes_j, W_ij = exp(−(e_o + Σ_k (F_i,k − F_j,k)²)) · [label_i = label_j] · tfac[τ] · m_ij,
with j = (t + τ, y + dy, x + dx): the spatial part of :mod:`.bilateral`'s window, computed once
per spatial offset and reused by the 2r_t + 1 bins, times the temporal factor, times the Welch
membership m_ij on the per-voxel statistics (every channel passes d² < γ_t² S or d = 0, in
float64, the predicate of :func:`dbench.methods.kernels.welch.row_welch_pair`). Bins outside
[0, T) are not neighbours. A voxel with bad statistics carries θ = NaN, which fails every test,
so it has no neighbours and is nobody's neighbour (its output is its own colour), as on the host.

Planes (T, H, W, PP) hold per voxel the colour premultiplied by its validity and the validity
(planes 0-3), then for the shrinkage of :mod:`~dbench.methods.statistical.shrink` θ̄·v (7-plane
layout only), V̄·v and v; planes from ``SQ`` on are summed with W_ij² (the variance of a
weighted mean). The epilogue runs in float64 per voxel: the normalised sum with the centre
term of weight v_i (``SHRINK`` = 0, :func:`~dbench.methods.kernels.bilateral.numba3d.accumulate3d`
with ``normalise_into``), or the centre-versus-neighbourhood rule of
:func:`~dbench.methods.statistical.shrink.merge_shrink3d` (``SHRINK`` = 1: θ̄ the colour's
channel mean, 6 planes; 2: θ̄ in plane 4, 7 planes). The output is written into the (H, W, T, 3)
video at the bins handed in.

It differs from the Numba path in arithmetic only: every voxel sums its whole window itself (no
symmetric half window, which would race on a GPU), in one float32 accumulator with the
hardware ``exp``; tests/methods/test_statistical_transient_device.py bounds the difference.
"""
from __future__ import annotations

import triton.language as tl
from triton.language import core as tl_core  # noqa: F401 - patched by the interpreter (runtime)

from .bilateral import TILE_H, TILE_W
from .runtime import cdiv, kernel


@kernel(do_not_specialize=("table_last",))
def window3d_kernel(feat_ptr, lab_ptr, plane_ptr, scale_ptr, theta_ptr, var_ptr, nint_ptr,
                    table_ptr, tfac_ptr, bins_ptr, out_ptr, H, W, T, ix, iy, table_last, e_cut,
                    R: tl.constexpr, RT: tl.constexpr, KP: tl.constexpr, PP: tl.constexpr,
                    SQ: tl.constexpr, SHRINK: tl.constexpr, DISK: tl.constexpr,
                    TEST: tl.constexpr, TH: tl.constexpr, TW: tl.constexpr):
    """feat (H, W, KP) f32 zero-padded; lab (H, W) i32; planes (T, H, W, PP) f32 and scale
    (PP,) f64, the factors the planes were divided by (the epilogue multiplies the centre values
    and the float32 sums back in float64; 1 for ordinary planes, an exact product); theta, var
    (T, H, W, 4) f64 and nint (T, H, W, 4) i32, the 4th channel zero; table (L,) f64; tfac
    (2·RT+1,) f32; bins (K,) i64, the bin of each program along axis 0; out (H, W, T, 3) f32.
    TEST: 0 no membership, 1 one γ_t², table[0], 2 γ_t² looked up by ν = n_i + n_j − 2 (γ_t²
    is read from the float64 table in both, so the test compares with the host's float64 value;
    a float scalar argument would be rounded to float32). R and RT are compile-time constants
    (loop bounds; docs/gpu.md §1)."""
    pid_k = tl.program_id(0)
    pid_y = tl.program_id(1)
    pid_x = tl.program_id(2)
    t = tl.load(bins_ptr + pid_k)
    i = tl.arange(0, TH * TW)
    y = pid_y * TH + i // TW
    x = pid_x * TW + i % TW
    inside = (y < H) & (x < W)
    idx = y * W + x
    vox = t * H * W + idx                     # int64: videos pass 2³¹ voxel channels
    k = tl.arange(0, KP)
    c4 = tl.arange(0, 4)
    cp = tl.arange(0, PP)
    fc = tl.load(feat_ptr + idx[:, None] * KP + k[None, :], mask=inside[:, None], other=0.0)
    lc = tl.load(lab_ptr + idx, mask=inside, other=-1)
    if TEST > 0:
        if TEST == 1:
            g2 = tl.load(table_ptr)
        tc = tl.load(theta_ptr + vox[:, None] * 4 + c4[None, :], mask=inside[:, None],
                     other=0.0)
        vc = tl.load(var_ptr + vox[:, None] * 4 + c4[None, :], mask=inside[:, None], other=0.0)
        if TEST == 2:
            nc = tl.load(nint_ptr + vox[:, None] * 4 + c4[None, :], mask=inside[:, None],
                         other=0)
    acc = tl.zeros((TH * TW, PP), dtype=tl.float32)
    for dy in range(-R, R + 1):
        yy = y + dy
        row_ok = inside & (yy >= 0) & (yy < H)
        for dx in range(-R, R + 1):
            e = 0.5 * (dx * dx * ix + dy * dy * iy)
            use = e < e_cut
            if DISK:
                use = use & (dx * dx + dy * dy <= R * R)
            if use:
                xx = x + dx
                nb = row_ok & (xx >= 0) & (xx < W)
                nidx = yy * W + xx
                ln = tl.load(lab_ptr + nidx, mask=nb, other=-2)
                fn = tl.load(feat_ptr + nidx[:, None] * KP + k[None, :], mask=nb[:, None],
                             other=0.0)
                d = fc - fn
                ws = tl.exp(-(tl.sum(d * d, axis=1) + e))
                ws = tl.where(nb & (ln == lc), ws, 0.0)
                for tau in range(-RT, RT + 1):
                    tt = t + tau
                    # the centre voxel is added by the epilogue with weight v_i
                    off_centre = (dx * dx + dy * dy + tau * tau) > 0
                    nbt = nb & (tt >= 0) & (tt < T) & off_centre
                    nvox = tt * H * W + nidx
                    f = tl.load(tfac_ptr + tau + RT)
                    w = tl.where(nbt, ws * f, 0.0)
                    if TEST > 0:
                        tn = tl.load(theta_ptr + nvox[:, None] * 4 + c4[None, :],
                                     mask=nbt[:, None], other=0.0)
                        vn = tl.load(var_ptr + nvox[:, None] * 4 + c4[None, :],
                                     mask=nbt[:, None], other=0.0)
                        dd = tc - tn
                        s = vc + vn
                        if TEST == 1:
                            ok = (dd * dd < g2 * s) | (dd == 0.0)
                        else:
                            nn = tl.load(nint_ptr + nvox[:, None] * 4 + c4[None, :],
                                         mask=nbt[:, None], other=0)
                            nu = tl.minimum(tl.maximum(nc + nn - 2, 0), table_last)
                            gt = tl.load(table_ptr + nu, mask=nbt[:, None], other=0.0)
                            ok = (dd * dd < gt * s) | (dd == 0.0)
                        fails = tl.sum(tl.where(ok, 0, 1), axis=1)
                        w = tl.where(fails == 0, w, 0.0)
                    pn = tl.load(plane_ptr + nvox[:, None] * PP + cp[None, :],
                                 mask=nbt[:, None], other=0.0)
                    wm = tl.where(cp[None, :] >= SQ, (w * w)[:, None], w[:, None])
                    acc += wm * pn
    # epilogue in float64, per voxel (the host merges its float32 band sums in float64), on the
    # unscaled values: a colour near the float32 maximum is only scaled down for the sums
    sc = tl.load(scale_ptr + cp)
    pc = tl.load(plane_ptr + vox[:, None] * PP + cp[None, :], mask=inside[:, None],
                 other=0.0).to(tl.float64) * sc[None, :]
    sums = acc.to(tl.float64) * sc[None, :]
    v = tl.sum(tl.where(cp[None, :] == 3, pc, 0.0), axis=1)
    a = tl.sum(tl.where(cp[None, :] == 3, sums, 0.0), axis=1)
    den = v + a
    seed = tl.where(den[:, None] > 0, (pc + sums) / tl.where(den > 0, den, 1.0)[:, None], 0.0)
    val = seed
    if SHRINK > 0:
        rgb = cp[None, :] < 3
        if SHRINK == 1:     # θ̄ is the colour's channel mean (identity transform)
            theta_i = tl.sum(tl.where(rgb, pc, 0.0), axis=1) / 3.0
            theta_sum = tl.sum(tl.where(rgb, sums, 0.0), axis=1) / 3.0
        else:
            theta_i = tl.sum(tl.where(cp[None, :] == 4, pc, 0.0), axis=1)
            theta_sum = tl.sum(tl.where(cp[None, :] == 4, sums, 0.0), axis=1)
        var_i = tl.sum(tl.where(cp[None, :] == SQ, pc, 0.0), axis=1)
        var2_sum = tl.sum(tl.where(cp[None, :] == SQ, sums, 0.0), axis=1)
        w2_sum = tl.sum(tl.where(cp[None, :] == SQ + 1, sums, 0.0), axis=1)
        a_safe = tl.where(a > 0, a, 1.0)
        theta_n = theta_sum / a_safe
        var_n = var2_sum / (a_safe * a_safe)
        var_c = tl.where(w2_sum > 0,
                         tl.maximum(var_i, var2_sum / tl.where(w2_sum > 0, w2_sum, 1.0)), var_i)
        dt = theta_i - theta_n
        b2 = tl.maximum(dt * dt - var_c - var_n, 0.0)
        total = var_c + var_n + b2
        beta = a_safe / (1.0 + a_safe)
        beta = tl.where(total > 0,
                        tl.minimum(beta, var_c / tl.where(total > 0, total, 1.0)), beta)
        shrunk = (1.0 - beta[:, None]) * pc + beta[:, None] * (sums / a_safe[:, None])
        # a centre with no accepted neighbour, or an invalid colour, keeps the seed's output
        use_shrunk = (den > 0) & (v != 0.0) & (a > 0)
        val = tl.where(use_shrunk[:, None], shrunk, seed)
    at = (idx[:, None].to(tl.int64) * T + t) * 3 + cp[None, :]
    tl.store(out_ptr + at, val.to(tl.float32), mask=inside[:, None] & (cp[None, :] < 3))


def window3d_filter(feat, labels, planes, scale, tfac, bins, out, *, radius: int,
                    radius_t: int,
                    inv_x: float, inv_y: float, disk: bool, e_cut: float, shrink: int = 0,
                    squared_from: int | None = None, theta=None, var=None, nint=None,
                    table=None) -> None:
    """Launch :func:`window3d_kernel` once over the bins ``bins`` (tensors on one device,
    contiguous).

    Args:
        feat: (H, W, KP) float32 pre-scaled features, KP a power of two; labels (H, W) int32.
        planes: (T, H, W, PP) float32, PP = 4 or 8 (zero-padded); scale: (PP,) float64
            factors the planes were divided by (a power of two where a plane's finite peak
            exceeds PLANE_MAX, dbench/methods/statistical/transient_device.py), all 1 for
            ordinary inputs.
        tfac: (2r_t+1,) float32 temporal factors; bins: (K,) int64 bins to write, K ≥ 1.
        out: (H, W, T, 3) float32, written at the bins ``bins`` only.
        shrink: 0 normalised sum, 1 / 2 the shrinkage with θ̄ from the colour / plane 4;
            squared_from: first plane summed with W² (None: none).
        theta, var: (T, H, W, 4) float64 (None: no membership test); ``table`` (L,) float64
            γ_t² by ν with nint (T, H, W, 4) int32 when γ_t² depends on ν, else the one γ_t²
            as a (1,) table and nint None.
    """
    t_, h, w, pp = planes.shape
    kp = feat.shape[2]
    test = 0 if theta is None else (1 if nint is None else 2)
    dummy_f64 = theta if theta is not None else tfac.new_zeros(1, dtype=_f64())
    dummy_i32 = nint if nint is not None else labels
    tab = table if table is not None else dummy_f64
    grid = (int(bins.shape[0]), cdiv(h, TILE_H), cdiv(w, TILE_W))
    window3d_kernel[grid](
        feat, labels, planes, scale, dummy_f64, var if var is not None else dummy_f64, dummy_i32, tab,
        tfac, bins, out, h, w, t_, float(inv_x), float(inv_y), int(tab.shape[0] - 1),
        float(e_cut), R=int(radius), RT=int(radius_t), KP=int(kp), PP=int(pp),
        SQ=int(pp if squared_from is None else squared_from), SHRINK=int(shrink),
        DISK=bool(disk), TEST=test, TH=TILE_H, TW=TILE_W)


def _f64():
    import torch
    return torch.float64


__all__ = ["window3d_filter", "window3d_kernel"]
