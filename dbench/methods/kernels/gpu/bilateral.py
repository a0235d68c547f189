"""The joint bilateral window of ``jbf`` and ``statistical`` as one Triton kernel launch
(docs/gpu.md §2; the maths in the docstrings of :mod:`dbench.methods.jbf` and
:mod:`dbench.methods.statistical.reference`, the readable references the tests hold it to).

For every pixel i the kernel sums, over the whole (2r+1)² window including the centre,
W_ij · planes_j with W_ij = exp(−(e_o + Σ_k (F_i,k − F_j,k)²)) · [label_i = label_j] · m_ij,
where F are the pre-scaled, centred feature planes of :mod:`.guide`, e_o the spatial exponent of
the offset, and m_ij the Welch membership (every channel passes d² < γ_t² S or d = 0, in float64,
the predicate of the reference). The planes are the colour premultiplied by its validity and the
validity itself, so the output is Σ W·L / Σ W·v, written interleaved (H, W, 3); a pixel whose sum
of weights is 0 gets 0, as :func:`~dbench.methods.kernels.bilateral.reference.safe_divide` does.

It differs from the Numba path in arithmetic only: each pixel sums its whole window itself
(no symmetric half window: a GPU thread would otherwise race with its neighbour's), in float32
with the hardware ``exp``; the tests bound the difference to the float64 reference
(tests/methods/test_gpu_bilateral.py).
"""
from __future__ import annotations

from functools import lru_cache

import triton
import triton.language as tl
from triton.language import core as tl_core  # noqa: F401 - patched by the interpreter (runtime)

from .runtime import cdiv, kernel

#: Pixels of one program: a tile of TILE_H rows × TILE_W columns (neighbour loads along a row are
#: contiguous).
TILE_H, TILE_W = 8, 32


@kernel(do_not_specialize=("table_last",))
def window_kernel(feat_ptr, lab_ptr, plane_ptr, scale_ptr, theta_ptr, var_ptr, nint_ptr,
                  table_ptr, out_ptr, H, W, ix, iy, table_last, e_cut,
                  R: tl.constexpr, KP: tl.constexpr, DISK: tl.constexpr, TEST: tl.constexpr,
                  TH: tl.constexpr, TW: tl.constexpr):
    """feat (H, W, KP) f32, zero-padded; lab (H, W) i32; planes (H, W, 4) f32 (r·v, g·v, b·v, v);
    scale (4,) f32; theta, var (H, W, 4) f64 and nint (H, W, 4) i32, the 4th channel zero;
    table (L,) f64; out (H, W, 3) f32. Every pixel's features, planes and statistics are one
    contiguous vector, read with one wide load per neighbour; the zero padding makes the padded
    channels drop out by themselves (a zero difference adds nothing to the exponent and passes the
    test as d = 0). TEST: 0 no membership, 1 one γ_t², table[0], 2 γ_t² looked up by
    ν = n_i + n_j − 2. γ_t² is read from the float64 table in both, so the float64 test compares
    with the host's value (a float scalar argument is compiled as float32 and would move the
    threshold by up to 3e-8 relative). The radius R is a compile-time constant: one compiled kernel per radius,
    a plain loop bound (no unrolling)."""
    pid_y = tl.program_id(0)
    pid_x = tl.program_id(1)
    i = tl.arange(0, TH * TW)
    y = pid_y * TH + i // TW
    x = pid_x * TW + i % TW
    inside = (y < H) & (x < W)
    idx = y * W + x
    k = tl.arange(0, KP)
    c4 = tl.arange(0, 4)
    fc = tl.load(feat_ptr + idx[:, None] * KP + k[None, :], mask=inside[:, None], other=0.0)
    lc = tl.load(lab_ptr + idx, mask=inside, other=-1)
    if TEST > 0:
        if TEST == 1:
            g2 = tl.load(table_ptr)
        tc = tl.load(theta_ptr + idx[:, None] * 4 + c4[None, :], mask=inside[:, None], other=0.0)
        vc = tl.load(var_ptr + idx[:, None] * 4 + c4[None, :], mask=inside[:, None], other=0.0)
        if TEST == 2:
            nc = tl.load(nint_ptr + idx[:, None] * 4 + c4[None, :], mask=inside[:, None],
                         other=0)
    acc = tl.zeros((TH * TW, 4), dtype=tl.float32)
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
                w = tl.exp(-(tl.sum(d * d, axis=1) + e))
                w = tl.where(nb & (ln == lc), w, 0.0)
                if TEST > 0:
                    tn = tl.load(theta_ptr + nidx[:, None] * 4 + c4[None, :], mask=nb[:, None],
                                 other=0.0)
                    vn = tl.load(var_ptr + nidx[:, None] * 4 + c4[None, :], mask=nb[:, None],
                                 other=0.0)
                    dd = tc - tn
                    s = vc + vn
                    if TEST == 1:
                        ok = (dd * dd < g2 * s) | (dd == 0.0)
                    else:
                        nn = tl.load(nint_ptr + nidx[:, None] * 4 + c4[None, :],
                                     mask=nb[:, None], other=0)
                        nu = tl.minimum(tl.maximum(nc + nn - 2, 0), table_last)
                        gt = tl.load(table_ptr + nu, mask=nb[:, None], other=0.0)
                        ok = (dd * dd < gt * s) | (dd == 0.0)
                    fails = tl.sum(tl.where(ok, 0, 1), axis=1)
                    w = tl.where(fails == 0, w, 0.0)
                pn = tl.load(plane_ptr + nidx[:, None] * 4 + c4[None, :], mask=nb[:, None],
                             other=0.0)
                acc += w[:, None] * pn
    scale = tl.load(scale_ptr + c4)
    den = tl.sum(tl.where(c4[None, :] == 3, acc, 0.0), axis=1)
    safe = tl.where(den > 0, den, 1.0)
    val = tl.where(den[:, None] > 0, (acc / safe[:, None]) * scale[None, :], 0.0)
    tl.store(out_ptr + idx[:, None] * 3 + c4[None, :], val,
             mask=inside[:, None] & (c4[None, :] < 3))


def window_filter(feat, labels, planes, scale, out, *, radius: int, inv_x: float, inv_y: float,
                  disk: bool, theta=None, var=None, nint=None, g2: float = 0.0, table=None,
                  e_cut: float) -> None:
    """Launch :func:`window_kernel` once over the image (tensors on one device, contiguous).

    Args:
        feat: (H, W, KP) float32 pre-scaled features, KP a power of two, zero-padded;
            labels: (H, W) int32.
        planes: (H, W, 4) float32; scale: (4,) float32 factors the sums are multiplied by.
        out: (H, W, 3) float32, written.
        theta, var: (H, W, 4) float64 (None: no membership test); nint: (H, W, 4) int32 and
            ``table`` (L,) float64 when γ_t² depends on ν, else ``g2`` (handed to the kernel
            as a (1,) float64 table, :func:`g2_tensor`); 4th channels zero.
    """
    h, w, kp = feat.shape
    test = 0 if theta is None else (1 if nint is None else 2)
    if test == 1:
        table = g2_tensor(float(g2), str(theta.device))
    dummy_f64 = theta if theta is not None else scale.new_zeros(1, dtype=_f64())
    dummy_i32 = nint if nint is not None else labels
    tab = table if table is not None else dummy_f64
    grid = (cdiv(h, TILE_H), cdiv(w, TILE_W))
    window_kernel[grid](
        feat, labels, planes, scale, dummy_f64, var if var is not None else dummy_f64,
        dummy_i32, tab, out, h, w, float(inv_x), float(inv_y), int(tab.shape[0] - 1), float(e_cut), R=int(radius),
        KP=int(kp), DISK=bool(disk), TEST=test, TH=TILE_H, TW=TILE_W)


@lru_cache(maxsize=16)
def g2_tensor(g2: float, device: str):
    """The one γ_t² as a (1,) float64 tensor on ``device``, made once: the window kernels read it
    from memory so that their float64 Welch test uses the host's value (a float argument would
    be compiled as float32)."""
    import torch
    return torch.tensor([g2], dtype=torch.float64, device=device)


def _f64():
    import torch
    return torch.float64


__all__ = ["TILE_H", "TILE_W", "g2_tensor", "window_filter", "window_kernel"]
