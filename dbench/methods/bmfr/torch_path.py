"""PyTorch backend of the BMFR core (docs/methods/bmfr.md): features, the batched least-squares
fit of every block at once, and the reconstruction.

All blocks of a grid become one batch: block k's pixels are the rows of a (K, B², ·) tensor
gathered with flat index tensors; rows outside the image or outside the fit set are zero rows,
which leave the least-squares solution — and |R_kk| of the rank safeguard — unchanged, so every
block has the same m = B² and no Python loop runs over blocks or pixels. The QR is LAPACK's /
cuSOLVER's Householder (``torch.linalg.qr(mode="r")``) of the augmented matrix [A | B]: Q is
never formed and the first n rows of R's right part are Qᵀ B (docs/methods/bmfr.md §5), as in
:func:`~dbench.methods.bmfr.reference.householder_lstsq_reference`. The fit is float64 like the
other backends; images are float32.

Functions take NumPy arrays or tensors and return tensors on the device of ``z`` / ``A`` when
it is a tensor, else CUDA when available, else CPU. The NumPy-facing dispatchers of ``core``
(``householder_lstsq``, ``bmfr_fit``) convert at their boundary.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ...errors import DbenchInputError
from ..temporal import as_tensor, torch_device
from .params import _GOLD, _M1, _M2, FEATURE_PRESETS, NORMAL_SOURCES, RCOND, normal_column
from .reference import block_origins


def _dev(a: Any, device: Any):
    return torch_device(a) if device is None else device


def householder_lstsq_torch(A, B, rcond: float = RCOND, device=None):
    """min ‖A X − B‖ for batches A (K, m, n), B (K, m, c): (X (K, n, c) float64 tensor,
    dropped (K,) int64 tensor of columns zeroed by the rank safeguard |R_kk| < rcond·max|R_jj|).
    Fewer than n + c rows are padded with zero rows (no effect on the solution)."""
    import torch
    dev = _dev(A, device)
    A = as_tensor(A, dev, torch.float64)
    B = as_tensor(B, dev, torch.float64)
    k_, m, n = A.shape
    c = B.shape[2]
    M = torch.cat([A, B], dim=2)
    if m < n + c:
        M = torch.cat([M, M.new_zeros((k_, n + c - m, n + c))], dim=1)
    R = torch.linalg.qr(M, mode="r").R
    return back_substitute_torch(R[:, :n, :n], R[:, :n, n:], rcond)


def back_substitute_torch(Rt, r, rcond: float = RCOND):
    """Solve the upper-triangular Rt (K, n, n) X = r (K, n, c) with the rank safeguard of
    docs/methods/bmfr.md §5 (dropped columns get X_k = 0); loops over the n ≤ 10 columns, batched over K."""
    import torch
    k_, n, _ = Rt.shape
    diag = Rt.diagonal(dim1=1, dim2=2).abs()
    thr = rcond * diag.amax(1).clamp(min=0.0) if n else diag.new_zeros(k_)
    keep = diag > thr[:, None]
    X = torch.zeros(r.shape, dtype=r.dtype, device=r.device)
    for k in range(n - 1, -1, -1):
        rhs = r[:, k, :] - torch.einsum("kj,kjc->kc", Rt[:, k, k + 1:], X[:, k + 1:, :])
        piv = torch.where(keep[:, k], Rt[:, k, k], 1.0)
        X[:, k, :] = torch.where(keep[:, k, None], rhs / piv[:, None], 0.0)
    return X, (~keep).sum(1)


def feature_stack_torch(normal, position, preset: str = "paper", device=None):
    """Raw feature columns (M, H, W) float32 tensor of a preset from planar stacked normals
    (3·k, H, W) and position (3, H, W) (:func:`~dbench.methods.bmfr.reference.feature_stack`)."""
    import torch
    if preset not in FEATURE_PRESETS:
        raise DbenchInputError(f"features: expected one of {tuple(FEATURE_PRESETS)}, "
                               f"got {preset!r}")
    dev = _dev(normal, device)
    n = as_tensor(normal, dev, torch.float32)
    p = as_tensor(position, dev, torch.float32)
    cols = []
    for name in FEATURE_PRESETS[preset]:
        if name == "1":
            cols.append(torch.ones_like(n[0]))
        elif name[0] in NORMAL_SOURCES:
            cols.append(n[normal_column(preset, name)])
        else:
            v = p["xyz".index(name[1])]
            cols.append(v * v if name.endswith("2") else v)
    return torch.stack(cols)


def _signed(v: int) -> int:
    """A uint64 bit pattern as the int64 of the same bits (torch has no wrapping uint64 maths)."""
    v &= (1 << 64) - 1
    return v - (1 << 64) if v >= 1 << 63 else v


def _lsr(z, s: int):
    """Logical right shift of int64 bit patterns (``>>`` is arithmetic on int64)."""
    return z if s == 0 else (z >> s) & ((1 << (64 - s)) - 1)


def uniform_hash_torch(seed: int, index, column: int):
    """:func:`~dbench.methods.bmfr.reference.uniform_hash` on an int64 index tensor: the same
    splitmix64 bits with int64 wrap-around arithmetic, float64 uniforms in (0, 1)."""
    g, m1, m2 = int(_GOLD), int(_M1), int(_M2)
    z = index * _signed(m1) + _signed(seed * g + (column // 4) * m2)
    z = (z ^ _lsr(z, 30)) * _signed(m1)
    z = (z ^ _lsr(z, 27)) * _signed(m2)
    z = z ^ _lsr(z, 31)
    chunk = _lsr(z, 16 * (column % 4)) & 0xFFFF
    return (chunk.double() + 0.5) / 65536.0


def bmfr_fit_torch(z, feats, scaled, fit, recon, block, offset, noise_amount=0.01,
                   noise_seed=0, rcond=RCOND, clamp=True, device=None):
    """:func:`~dbench.methods.bmfr.reference.bmfr_fit_reference` with all blocks in one batch.

    Args: as the reference — z (3, H, W), feats (M, H, W), scaled (M,) bool, fit/recon (H, W)
    bool, block size and grid offset (x, y), noise amplitude and seed, rcond, clamp.
    Returns:
        (y (3, H, W) float32 tensor: the fit at ``recon`` pixels of fitted blocks, ``z``
        elsewhere; number of columns zeroed by the rank safeguard over the fitted blocks).
    """
    import torch
    dev = _dev(z, device)
    zt = as_tensor(z, dev, torch.float32)
    c, h, w = zt.shape
    f = as_tensor(feats, dev, torch.float32)
    m_ = f.shape[0]
    out = zt.clone()
    origins = torch.as_tensor(block_origins(h, w, block, offset), device=dev)
    if len(origins) == 0:
        return out, 0
    r = torch.arange(block * block, device=dev)
    yy = origins[:, :1] + r // block
    xx = origins[:, 1:] + r % block
    inside = (yy >= 0) & (yy < h) & (xx >= 0) & (xx < w)
    idx = torch.where(inside, yy * w + xx, 0)  # (K, B²) flat pixel index of every block row
    fitm = inside & as_tensor(fit, dev, torch.bool).reshape(-1)[idx]
    recm = inside & as_tensor(recon, dev, torch.bool).reshape(-1)[idx]
    F = f.reshape(m_, -1)[:, idx].permute(1, 2, 0).double()  # (K, B², M)

    # §2.1: position columns scaled per block over its fit pixels; blocks without fit get
    # (0, 1) so that no inf reaches the batch (they are not written back)
    sc = as_tensor(np.asarray(scaled, bool), dev, torch.bool)
    lo = torch.where(fitm[..., None], F, torch.inf).amin(1)
    hi = torch.where(fitm[..., None], F, -torch.inf).amax(1)
    usable = sc & torch.isfinite(lo)
    shift = torch.where(usable, lo, 0.0)
    span = torch.where(usable, (hi - lo).clamp(min=1.0), 1.0)
    Fs = (F - shift[:, None, :]) / span[:, None, :]

    A = Fs.clone()
    if noise_amount:
        for j in range(1, m_):  # §4: noise on every column but the constant
            A[..., j] += noise_amount * (2.0 * uniform_hash_torch(int(noise_seed), idx, j) - 1.0)
    A = torch.where(fitm[..., None], A, 0.0)
    Bm = torch.where(fitm[..., None], zt.reshape(c, -1)[:, idx].permute(1, 2, 0).double(), 0.0)
    X, dropped = householder_lstsq_torch(A, Bm, rcond)
    y = Fs @ X  # noise-free features reconstruct (K, B², c)
    if clamp:
        y = y.clamp(min=0.0)
    active = fitm.any(1) & recm.any(1)
    write = recm & active[:, None]
    out.reshape(c, -1)[:, idx[write]] = y[write].T.float()
    return out, int(dropped[active].sum())


__all__ = ["back_substitute_torch", "bmfr_fit_torch", "feature_stack_torch",
           "householder_lstsq_torch", "uniform_hash_torch"]
