"""The Welch pair tests of docs/methods/statistical.md §5.2 as inlined Numba row kernels: zero a row of
weights where the test fails in any channel. pass_c = (d² < γ_t² S) or (d == 0), computed in
float64 exactly as the NumPy reference does, so decisions are identical to it. Used inside the
bilateral accumulation loops (2-D and 3-D) by ``statistical``."""
from __future__ import annotations

import numpy as np
from numba import njit

F0 = np.float32(0.0)


@njit(inline="always", cache=True)
def row_welch(theta, var, g2, y, yy, x0, x1, dx, w):
    """Zero w where the Welch test fails in any channel (constant threshold γ_t² = g2).

    pass_c = (d² < γ_t² S) or (d == 0), computed in float64 exactly as the reference does
    (docs/methods/statistical.md §5.2), so decisions are identical to it.
    """
    # the 3D kernel's pair form with both ends in the same planes; w·1.0 == w exactly
    row_welch_pair(theta, var, theta, var, g2, y, yy, x0, x1, dx, w, 1.0, w)


@njit(inline="always", cache=True)
def row_welch_table(theta, var, nint, table, y, yy, x0, x1, dx, w):
    """As row_welch with γ_t² looked up per channel from ν = n_i + n_j − 2 (non-uniform n)."""
    row_welch_pair_table(theta, var, nint, theta, var, nint, table, y, yy, x0, x1, dx, w)


@njit(inline="always", cache=True)
def row_welch_pair(ta, va, tb, vb, g2, y, yy, x0, x1, dx, ro, f, w):
    """w = ro·f where the Welch test passes, else 0, with the centres in bin planes (ta, va), row
    y, and the neighbours in (tb, vb), row yy: the float64 predicate of :func:`row_welch`, so
    decisions equal the reference's."""
    n = x1 - x0
    ta0 = ta[0, y, x0:x1]
    tb0 = tb[0, yy, x0 + dx:x1 + dx]
    ta1 = ta[1, y, x0:x1]
    tb1 = tb[1, yy, x0 + dx:x1 + dx]
    ta2 = ta[2, y, x0:x1]
    tb2 = tb[2, yy, x0 + dx:x1 + dx]
    va0 = va[0, y, x0:x1]
    vb0 = vb[0, yy, x0 + dx:x1 + dx]
    va1 = va[1, y, x0:x1]
    vb1 = vb[1, yy, x0 + dx:x1 + dx]
    va2 = va[2, y, x0:x1]
    vb2 = vb[2, yy, x0 + dx:x1 + dx]
    for i in range(n):
        d0 = ta0[i] - tb0[i]
        d1 = ta1[i] - tb1[i]
        d2 = ta2[i] - tb2[i]
        ok = (((d0 * d0 < g2 * (va0[i] + vb0[i])) | (d0 == 0.0))
              & ((d1 * d1 < g2 * (va1[i] + vb1[i])) | (d1 == 0.0))
              & ((d2 * d2 < g2 * (va2[i] + vb2[i])) | (d2 == 0.0)))
        w[i] = ro[i] * f if ok else F0


@njit(inline="always", cache=True)
def row_welch_pair_table(ta, va, na, tb, vb, nb, table, y, yy, x0, x1, dx, w):
    """As :func:`row_welch_table` for centres in bin (ta, va, na) and neighbours in (tb, vb, nb)."""
    n = x1 - x0
    last = table.shape[0] - 1
    for c in range(3):
        a = ta[c, y, x0:x1]
        b = tb[c, yy, x0 + dx:x1 + dx]
        sa = va[c, y, x0:x1]
        sb = vb[c, yy, x0 + dx:x1 + dx]
        ca = na[c, y, x0:x1]
        cb = nb[c, yy, x0 + dx:x1 + dx]
        for i in range(n):
            nu = min(max(ca[i] + cb[i] - 2, 0), last)
            d = a[i] - b[i]
            ok = (d * d < table[nu] * (sa[i] + sb[i])) | (d == 0.0)
            w[i] = w[i] if ok else F0
