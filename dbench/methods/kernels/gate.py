"""ProDen's t-test gate (docs/methods/statistical.md §12): mix a denoised image back towards the noisy one
where they differ by many standard errors of the noisy mean, so any denoiser's output converges
to the noisy input's limit as the variance of the mean vanishes.

    G      = 11×11 Gaussian, σ_b = max(100 · sqrt(clamp(mean(var), 0, 1)), 1e-3)
    t      = |G*(hdr + α(den − hdr)) − G*hdr| / (sqrt(G²*var) + 1e-6)      (per channel)
    α_gate = α · Φ(−k (t − t0)),  k = 2, t0 = 4.2
    out    = hdr + α_gate (den − hdr)

Shapes: ``hdr``, ``den`` and ``var`` are (H, W, 3); ``var`` is the variance of the *linear*
noisy mean (:func:`~dbench.methods.kernels.variance_floor.linear_variance` derives it from
dbench's statistics). Zero-padded borders.

* :func:`~dbench.methods.kernels.gate_reference.proden_gate` — the readable reference (SciPy
  2-D correlation, float64; its own module).
* :func:`proden_gate_fast` — the same numbers in one compiled pass over bands of rows: G is
  separable (G = g gᵀ, G² = g² g²ᵀ) and G*(hdr + α(den − hdr)) − G*hdr = α G*(den − hdr), so
  two separable blurs replace three 2-D ones; each band blurs its rows along x into a ring of
  11 rows that the blur along y reads while it is in the cache, and Φ comes from a table
  (:func:`gate_table`). Equal to the reference within 1e-6 · |den − hdr| (test), and the same
  whatever the rows per band (test).
* :func:`proden_gate_stats` — the same passes fed directly from a frame's colour, the method's
  output and dbench's statistics (non-finite substitutions and the linear variance formed as
  each row is read), which is what ``NAME+gate`` runs.
* ``pool_radius`` r > 0 (all three; default 0, the spec's gate) [dbench]: the variance is first
  floored at its mean over the (2r + 1)² window (:mod:`~dbench.methods.kernels.variance_floor`,
  the reason there), which ``NAME+gate`` does with r = 5.

A kernel imports no method and nothing of the harness.
"""
from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np
from numba import get_num_threads, njit, prange

from ..checks import check_choice
from .gate_reference import (GATE_K, GATE_T0, GATE_TAPS, gate_taps, proden_gate_factor,
                             sigma_from_mean)
from .arrays import kernel_input
from .handback import HANDBACKS, WIENER_RADIUS, wiener_row
from .variance_floor import (SUM_ANCHOR, advance_column_sums, floor_row, linear_value,
                             linear_variance, window_mean_row)

#: The compiled passes' radius, a constant so that their tap loops are unrolled (the column
#: pass is written out for it: :func:`_column_gate`).
_RADIUS = GATE_TAPS // 2
assert _RADIUS == 5, "_column_gate's two passes are written for 11 taps"


#: The gate factor is read from a table of Φ(−k(t − t0)) on [0, LUT_T_MAX] with linear
#: interpolation: spacing 10/8192 bounds the error by h²/8 · max|Φ''| ≈ 1.8e-7 for k = 2,
#: and it is 4-5x faster than evaluating erfc per value.
LUT_SIZE = 8192
LUT_T_MAX = 10.0


@functools.lru_cache(maxsize=16)
def gate_table(k: float = GATE_K, t0: float = GATE_T0) -> np.ndarray:
    """(LUT_SIZE + 1,) values of Φ(−k(t − t0)) at t = i · LUT_T_MAX / LUT_SIZE; beyond the
    table the last value (≈ Φ(−11.6) ≈ 0) holds. Kept per (k, t0), read-only: the erf of its
    8193 points cost 0.12 ms a frame, 0.6 % of the gate at 720p."""
    table = proden_gate_factor(np.linspace(0.0, LUT_T_MAX, LUT_SIZE + 1), k, t0)
    table.flags.writeable = False
    return table


#: Fast-math flags of the gate passes: everything but "no NaN / no Inf", so that the finiteness
#: tests of the inputs are not optimised away.
_FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}


@njit(inline="always")
def _pair(color, den, fix, y, i):  # pragma: no cover - compiled
    """(hdr, den) of one value, float64: with ``fix`` a non-finite noisy value takes the
    method's and a non-finite method value the noisy one (as :func:`gate_output` does)."""
    a = np.float64(color[y, i])
    d = np.float64(den[y, i])
    if fix:
        if not np.isfinite(a):
            a = d
        if not np.isfinite(d):
            d = a
    return a, d


@njit(inline="always")
def _inputs(color, den, var, x, box_cox_half, fix, y, i):  # pragma: no cover - compiled
    """(hdr, den, linear variance) of one value (:func:`_pair`); the variance is ``var``
    (box_cox_half False) or var · max(x, 0) (Box-Cox ½, x the noisy colour), 0 where it is not
    finite (:func:`linear_variance`; the rule of ``variance_floor.linear_value``)."""
    a, d = _pair(color, den, fix, y, i)
    return a, d, linear_value(var, x, box_cox_half, y, i)


@njit(parallel=True, cache=True, fastmath=_FASTMATH)
def _mean_variance(color, den, var, x, box_cox_half, fix, positive
                   ):  # pragma: no cover - compiled
    """Mean of the linear variance over the image (σ_b of docs/methods/statistical.md §12), float64; ``positive[y]``
    is True where every value of ``var``'s row y is > 0 (NaN is not), counted as it is read."""
    h, wc = var.shape
    sums = np.zeros(h, np.float64)
    for row in prange(h):
        y = np.int64(row)
        s = 0.0
        above = 0
        for i in range(wc):
            s += _inputs(color, den, var, x, box_cox_half, fix, y, i)[2]
            above += var[y, i] > 0.0
        sums[y] = s
        positive[y] = above == wc
    return sums.sum() / max(h * wc, 1)


@njit(inline="always")
def _window_cols(xp, r, w):  # pragma: no cover - compiled
    """Columns of the (2r + 1)-wide window around column xp inside a W-wide image."""
    return min(xp + r, w - 1) - max(xp - r, 0) + 1


@njit(inline="always")
def _row_blur(color, den, var, x, box_cox_half, fix, g, g2, pool, h, y, pd, pv, sums, inv_cols,
              prefix, mean_row, lin_row, keep, out_d, out_v):  # pragma: no cover - compiled
    """Row y of the blur along x, zero-padded, of interleaved (W·C) values, C = 3 (a neighbour
    is 3 values away): out_d = g * (den − hdr), out_v = g² * var, float64, from the zero-padded
    copies ``pd`` and ``pv`` of the row; the taps are symmetric, so each pair adds
    g_j (f[i − 3j] + f[i + 3j]). With ``pool`` r > 0, var is first floored from the window's
    column ``sums`` (variance_floor.floor_row), and the window's mean is left in ``mean_row``;
    with ``keep`` the row's unfloored variance is copied to ``lin_row`` (W·C,) as well."""
    wc = out_d.shape[0]
    r = _RADIUS  # a compile-time constant: the tap loop below is unrolled
    c = 3 * r
    for i in range(wc):
        a, d, v = _inputs(color, den, var, x, box_cox_half, fix, y, i)
        pd[i + c] = d - a
        pv[i + c] = v
    if keep:
        for i in range(wc):
            lin_row[i] = pv[i + c]
    if pool > 0:  # sums: the window's column sums of row y (advance_column_sums)
        rows_in = min(y + pool, h - 1) - max(y - pool, 0) + 1
        floor_row(pv[c:c + wc], sums, rows_in, pool, 3, inv_cols, prefix, mean_row)
    for i in range(wc):  # the sums stay in registers: one store per value, not r + 1
        sd = g[r] * pd[i + c]
        sv = g2[r] * pv[i + c]
        for j in range(1, r + 1):
            sd += g[r + j] * (pd[i + c - 3 * j] + pd[i + c + 3 * j])
            sv += g2[r + j] * (pv[i + c - 3 * j] + pv[i + c + 3 * j])
        out_d[i] = sd
        out_v[i] = sv


@njit(inline="always")
def _column_gate(ring_d, ring_v, color, den, fix, g, g2, alpha, table, scale, h, y, rd, rv,
                 wiener, inv_norm_y, inv_norm_x, out_row, c_row, high2_row
                 ):  # pragma: no cover - compiled
    """Row y of the gate: the blur along y of the x-blurred rows y − r … y + r held in the
    rings (row yy in slot yy mod 2r + 1; rows outside the image read the rings' last row, kept
    at 0: zero padding), t = α|G*(den − hdr)| / (√(G²*var) + 1e-6) and α_gate = α Φ(−k(t − t0))
    with Φ read from ``table``. Then out = hdr + α_gate (den − hdr) into ``out_row``, and for
    the Wiener hand-back c = (α − α_gate) high into ``c_row`` (which holds low on the way) and
    high² into ``high2_row``, high = hdr − den − low, low = G*(hdr − den) / G*1
    (G*1 = 1 / (inv_norm_y · inv_norm_x))."""
    wc = out_row.shape[0]
    r = _RADIUS
    taps = 2 * r + 1
    last = table.shape[0] - 1
    sl = np.empty(taps, np.int64)  # sl[r + j]: the ring row of image row y + j
    for j in range(-r, r + 1):
        sl[r + j] = (y + j) % taps if 0 <= y + j <= h - 1 else taps
    # two passes of three taps each (r = 5: the centre and pairs 1-2, then pairs 3-5), so rd and
    # rv are stored twice, not r + 1 times
    a0, a1, a2, a3, a4 = (ring_d[sl[5]], ring_d[sl[4]], ring_d[sl[6]], ring_d[sl[3]],
                          ring_d[sl[7]])
    b0, b1, b2, b3, b4 = (ring_v[sl[5]], ring_v[sl[4]], ring_v[sl[6]], ring_v[sl[3]],
                          ring_v[sl[7]])
    for i in range(wc):
        rd[i] = g[5] * a0[i] + g[6] * (a1[i] + a2[i]) + g[7] * (a3[i] + a4[i])
        rv[i] = g2[5] * b0[i] + g2[6] * (b1[i] + b2[i]) + g2[7] * (b3[i] + b4[i])
    a1, a2, a3, a4, a5, a6 = (ring_d[sl[2]], ring_d[sl[8]], ring_d[sl[1]], ring_d[sl[9]],
                              ring_d[sl[0]], ring_d[sl[10]])
    b1, b2, b3, b4, b5, b6 = (ring_v[sl[2]], ring_v[sl[8]], ring_v[sl[1]], ring_v[sl[9]],
                              ring_v[sl[0]], ring_v[sl[10]])
    # the second pass ends in t (into rd); the table reads that follow have a loop of their
    # own, because a table read keeps a loop from being vectorised
    for i in range(wc):
        sd = rd[i] + g[8] * (a1[i] + a2[i]) + g[9] * (a3[i] + a4[i]) + g[10] * (a5[i] + a6[i])
        sv = rv[i] + g2[8] * (b1[i] + b2[i]) + g2[9] * (b3[i] + b4[i]) + g2[10] * (b5[i] + b6[i])
        rd[i] = min(alpha * abs(sd) / (math.sqrt(max(sv, 0.0)) + 1e-6) * scale, last - 1.0)
        if wiener:
            c_row[i] = -sd * (inv_norm_y * inv_norm_x[i])  # low, for now
    for i in range(wc):
        u = rd[i]
        m = int(u)
        rd[i] = table[m] + (u - m) * (table[m + 1] - table[m])
    if wiener:  # what the output row needs: the spec's output, (α − α_gate) high and high²
        for i in range(wc):
            hv, dv = _pair(color, den, fix, y, i)
            a = alpha * rd[i]
            out_row[i] = hv + a * (dv - hv)
            high = (hv - dv) - c_row[i]
            c_row[i] = (alpha - a) * high
            high2_row[i] = high * high
    else:
        for i in range(wc):
            hv, dv = _pair(color, den, fix, y, i)
            out_row[i] = hv + alpha * rd[i] * (dv - hv)


@njit(inline="always")
def _wiener_output(var, x, box_cox_half, ring_spec, ring_c, ring_h2, h, y, fresh, shared,
                   ring_lin, ring_mean, noise_sums, high_sums, lin, mean_v, inv_cols_w, prefix_w,
                   out_row):  # pragma: no cover - compiled
    """Output row y of the Wiener hand-back (handback.wiener_row) from the rings of the
    spec's output, (α − α_gate) high and high² (row yy in slot yy mod 2R + 2, R =
    WIENER_RADIUS; :func:`_column_gate`), the window column sums of high², slid from anchor
    rows (``fresh`` at a band's first row, which is one), and the variance's window means.
    With ``shared`` (the variance floor's window is the Wiener window) the row's variance and
    its window means are those the floor left in ``ring_lin`` and ``ring_mean`` (row yy in slot
    yy mod their rows) when row y was blurred; otherwise they are formed here, from column sums
    slid as the high² ones."""
    wc = out_row.shape[0]
    rw = WIENER_RADIUS
    nw = ring_h2.shape[0]  # 2R + 2 rows: the row that leaves the window is still there
    rows_in = min(y + rw, h - 1) - max(y - rw, 0) + 1
    if fresh or y % SUM_ANCHOR == 0:  # afresh at anchor rows (a band starts at one)
        for i in range(wc):
            high_sums[i] = 0.0
        for yy in range(max(y - rw, 0), min(y + rw, h - 1) + 1):
            src = ring_h2[yy % nw]
            for i in range(wc):
                high_sums[i] += src[i]
    else:  # slid by one row, as the variance's sums
        if y + rw <= h - 1:
            src = ring_h2[(y + rw) % nw]
            for i in range(wc):
                high_sums[i] += src[i]
        if y - rw - 1 >= 0:
            src = ring_h2[(y - rw - 1) % nw]
            for i in range(wc):
                high_sums[i] -= src[i]
    if shared:
        lin_row = ring_lin[y % ring_lin.shape[0]]
        mean_row = ring_mean[y % ring_mean.shape[0]]
    else:
        advance_column_sums(var, x, box_cox_half, y, fresh, h, rw, noise_sums)
        window_mean_row(noise_sums, rows_in, rw, 3, inv_cols_w, prefix_w, mean_v)
        for i in range(wc):
            lin[i] = linear_value(var, x, box_cox_half, y, i)
        lin_row = lin
        mean_row = mean_v
    wiener_row(ring_spec[y % nw], ring_c[y % nw], lin_row, high_sums, mean_row, rows_in,
               inv_cols_w, prefix_w, out_row)


@njit(parallel=True, cache=True, fastmath=_FASTMATH)
def _gate_bands(color, den, var, x, box_cox_half, fix, g, g2, pool, alpha, table, t_max, band,
                wiener, out):  # pragma: no cover - compiled
    """The whole gate on interleaved (H, W·C) rows, one band of ``band`` output rows per task:
    each band x-blurs its rows and the rows either side it needs into rings of 2r + 1 rows, and
    finishes a row as soon as the rows below it are ready, so no intermediate image leaves the
    cache. With the Wiener hand-back the gate's rows (the spec's output, (α − α_gate) high and
    high²) go to three more rings of 2R + 2 rows, R = WIENER_RADIUS, which the output rows read
    R rows later. Where the variance floor's window is the Wiener window (``pool`` = R, as
    ``NAME+gate`` runs it) each blurred row's variance and window means go to two rings that the
    output row reads, instead of summing the variance's window again. Every row's sums run in
    the same order whatever the band (window column sums slide from fixed anchor rows:
    variance_floor.advance_column_sums), so the result does not depend on ``band`` (test)."""
    h, wc = color.shape
    r = _RADIUS
    taps = 2 * r + 1
    rw = WIENER_RADIUS
    nw = 2 * rw + 2  # the gate's rows R above and below an output row, and the one leaving
    lag = rw if wiener else 0  # the gate's rows needed beyond a band, each side
    shared = wiener and pool == rw
    scale = (table.shape[0] - 1) / t_max
    w = wc // 3
    inv_cols = np.empty(wc, np.float64)  # 1 / the floor window's columns inside the image
    inv_cols_w = np.empty(wc, np.float64)  # the same for the Wiener window
    inv_norm_x = np.empty(wc, np.float64)  # 1 / Σ of the taps inside the image, along x
    for i in range(wc):
        xp = i // 3
        inv_cols[i] = 1.0 / _window_cols(xp, pool, w)
        inv_cols_w[i] = 1.0 / _window_cols(xp, rw, w)
        sx = 0.0
        for j in range(-r, r + 1):
            if 0 <= xp + j <= w - 1:
                sx += g[r + j]
        inv_norm_x[i] = 1.0 / sx
    n_bands = (h + band - 1) // band
    for b in prange(n_bands):
        y0 = np.int64(b) * band  # signed: prange may hand out unsigned indices
        y1 = min(y0 + band, h)
        ring_d = np.zeros((taps + 1, wc), np.float64)  # the last row stays 0 (padding)
        ring_v = np.zeros((taps + 1, wc), np.float64)
        pd = np.zeros(wc + 6 * r, np.float64)
        pv = np.zeros(wc + 6 * r, np.float64)
        sums = np.empty(wc, np.float64)
        prefix = np.empty(wc + 3 * (2 * pool + 1), np.float64)  # floor_row's scratch
        rd = np.empty(wc, np.float64)
        rv = np.empty(wc, np.float64)
        nr = nw if wiener else 1
        ring_spec = np.empty((nr, wc), np.float32)  # an output: float32 holds it
        ring_c = np.empty((nr, wc), np.float64)
        ring_h2 = np.empty((nr, wc), np.float64)
        # the floor's window means and the unfloored variance of the rows from an output row
        # to the last one blurred before it (r + R rows below it), when the Wiener hand-back
        # reads them (shared); else one row of scratch for the floor's means
        nl = r + rw + 2 if shared else 1
        ring_mean = np.empty((nl, wc), np.float64)
        ring_lin = np.empty((nl, wc if shared else 1), np.float64)
        alone = wiener and not shared  # the Wiener hand-back forms its own window means
        noise_sums = np.empty(wc if alone else 1, np.float64)
        lin = np.empty(wc if alone else 1, np.float64)
        mean_v = np.empty(wc if alone else 1, np.float64)
        high_sums = np.empty(wc if wiener else 1, np.float64)
        prefix_w = np.empty(wc + 3 * (2 * rw + 1) if wiener else 1, np.float64)
        first = max(y0 - r - lag, 0)
        top = min(y1 + r + lag, h)  # rows [first, top) are blurred along x
        next_g = max(y0 - lag, 0)  # the next row of the gate, and the last one + 1
        end_g = min(y1 + lag, h)
        next_o = y0  # the next output row (Wiener)
        for yy in range(first, top):
            if pool > 0:
                advance_column_sums(var, x, box_cox_half, yy, yy == first, h, pool, sums)
            slot = yy % nl
            _row_blur(color, den, var, x, box_cox_half, fix, g, g2, pool, h, yy, pd, pv, sums,
                      inv_cols, prefix, ring_mean[slot], ring_lin[slot], shared,
                      ring_d[yy % taps], ring_v[yy % taps])
            # a gate row needs the x-blurred rows to r below it (or to the image's last row)
            while next_g < end_g and yy >= min(next_g + r, h - 1):
                yg = next_g
                if wiener:
                    gy = 0.0  # Σ of the taps inside the image, along y
                    for j in range(-r, r + 1):
                        if 0 <= yg + j <= h - 1:
                            gy += g[r + j]
                    _column_gate(ring_d, ring_v, color, den, fix, g, g2, alpha, table, scale,
                                 h, yg, rd, rv, True, 1.0 / gy, inv_norm_x, ring_spec[yg % nw],
                                 ring_c[yg % nw], ring_h2[yg % nw])
                elif yg >= y0 and yg < y1:
                    _column_gate(ring_d, ring_v, color, den, fix, g, g2, alpha, table, scale,
                                 h, yg, rd, rv, False, 1.0, inv_norm_x, out[yg], rd, rd)
                next_g += 1
                # an output row needs the gate's rows to R below it (or to the last row)
                while wiener and next_o < y1 and next_g - 1 >= min(next_o + rw, h - 1):
                    _wiener_output(var, x, box_cox_half, ring_spec, ring_c, ring_h2, h, next_o,
                                   next_o == y0, shared, ring_lin, ring_mean, noise_sums,
                                   high_sums, lin, mean_v, inv_cols_w, prefix_w, out[next_o])
                    next_o += 1


def _band_rows(h: int, r: int) -> int:
    """Output rows per task: two tasks per thread (the halo of blurred rows per band costs
    about 2r / band extra), a multiple of SUM_ANCHOR, so that every band starts at an anchor
    row of the sliding window sums (the same sums whatever the bands)."""
    return _anchored(max(2 * r + 1, -(-h // (2 * get_num_threads()))))


def _anchored(rows: int) -> int:
    """``rows`` rounded up to a multiple of SUM_ANCHOR (bands start at anchor rows)."""
    return -(-int(rows) // SUM_ANCHOR) * SUM_ANCHOR


def _gate_passes(color, den, var, x, box_cox_half: bool, fix: bool, alpha: float, k: float,
                 t0: float, pool: int = 0, band: int | None = None, handback: str = "pixel",
                 rows_positive: np.ndarray | None = None) -> np.ndarray:
    """The compiled gate on (H, W, 3) arrays (see :func:`proden_gate_fast`): the mean variance
    (σ_b), then one pass of bands (:func:`_gate_bands`), with the variance floor of radius
    ``pool`` and the ``handback`` rule fused into it; ``band`` output rows per task (default
    :func:`_band_rows`). ``rows_positive`` (H,) bool, when given, receives whether every
    value of ``var``'s row is > 0 (read in the mean's pass)."""
    check_choice("handback", handback, HANDBACKS)
    h, w, c = color.shape
    # one argument type: colours float32 (as frames hold them; the output is float32), the
    # variance float64, every input read-only and C-ordered, since each other combination (a
    # float64 colour, a read-only broadcast variance) is another specialisation of the
    # kernels, each about 30 s to compile
    color = kernel_input(color, np.float32).reshape(h, w * c)
    den = kernel_input(den, color.dtype).reshape(h, w * c)
    var = kernel_input(var, np.float64).reshape(h, w * c)
    x = color if x is None else kernel_input(x, color.dtype).reshape(h, w * c)
    positive = np.empty(h, np.bool_) if rows_positive is None else rows_positive
    g = gate_taps(sigma_from_mean(_mean_variance(color, den, var, x, box_cox_half, fix,
                                                 positive)))
    out = np.empty((h, w * c), np.float32)
    band = _band_rows(h, len(g) // 2) if band is None else _anchored(band)
    _gate_bands(color, den, var, x, box_cox_half, fix, g, g * g, int(pool), float(alpha),
                gate_table(k, t0), LUT_T_MAX, band, handback == "wiener", out)
    return out.reshape(h, w, c)


def proden_gate_fast(hdr: Any, den: Any, var: Any, *, alpha: float = 1.0, k: float = GATE_K,
                     t0: float = GATE_T0, pool_radius: int = 0, handback: str = "pixel"
                     ) -> np.ndarray:
    """:func:`proden_gate` through one compiled pass over bands of interleaved rows (separable
    blurs with float64 sums, the gate factor from :func:`gate_table`); (H, W, 3) float32. Equal
    to the reference within float32 rounding (tests: 1e-6 relative)."""
    hdr = np.ascontiguousarray(hdr)
    return _gate_passes(hdr, den, var, None, False, False, alpha, k, t0, pool_radius,
                        handback=handback)


def proden_gate_stats(color: Any, den: Any, stats: Any, *, alpha: float = 1.0,
                      k: float = GATE_K, t0: float = GATE_T0, pool_radius: int = 0,
                      handback: str = "pixel", rows_positive: np.ndarray | None = None
                      ) -> np.ndarray:
    """The gate of a method output ``den`` on a noisy ``color`` with dbench's ``stats``, in the
    same compiled pass: non-finite noisy values take the method's and non-finite method values
    the noisy ones, and the linear variance (:func:`linear_variance`) is formed as each row is
    read for the identity transform and Box-Cox ½ (any other transform is prepared by
    :func:`linear_variance` first). Equal to ``proden_gate_fast(hdr, den',
    linear_variance(stats, color), pool_radius=r)`` with those substitutions (tests); with
    ``pool_radius`` r > 0 the variance is floored inside the pass
    (:mod:`~dbench.methods.kernels.variance_floor`); (H, W, 3) float32. ``rows_positive``
    (H,) bool, when given, receives whether every value of the row's variance is > 0 (the
    statistics' variance of the mean, or for transforms other than the identity and Box-Cox ½
    its linear form, which is 0 wherever the first is): ``SampleStats`` stores 0 where n < 2,
    so only the other rows can hold a pixel of unknown variance."""
    color = np.ascontiguousarray(color)
    shape = color.shape
    transform = getattr(stats, "transform", "identity")
    var = np.broadcast_to(np.asarray(stats.var_mean, np.float64), shape)
    rule = dict(handback=handback, rows_positive=rows_positive)
    if transform == "identity":
        return _gate_passes(color, den, var, None, False, True, alpha, k, t0, pool_radius,
                            **rule)
    if transform == "box-cox" and float(stats.lam) == 0.5:
        return _gate_passes(color, den, var, color, True, True, alpha, k, t0, pool_radius,
                            **rule)
    return _gate_passes(color, den, linear_variance(stats, color), None, False, True, alpha,
                        k, t0, pool_radius, **rule)


__all__ = ["gate_table", "proden_gate_fast", "proden_gate_stats"]
