"""The Wiener hand-back of a temporal filter's residual [dbench] (docs/temporal.md §9).

A regression or a spatial filter fed a temporally accumulated signal z returns y, which is
biased where its model cannot follow the image (BMFR's block fit across a contact shadow, a
highlight inside a 32-px block). On a static scene the accumulated z keeps converging while that
bias stays: fed the reference itself, BMFR's output had twice plain accumulation's error on
``orbit``. The hand-back returns to y the part of the residual r = z − y that is not noise,
with the split of :mod:`dbench.methods.kernels.handback` (the ProDen gate's Wiener rule):

    low  = G*r / G*1                   (G: Gaussian of σ = 2 px truncated at the 7×7 window,
                                        zero padding; the local bias)
    high = r − low
    s²   = max(B(high²) − B(var), 0)    (B: mean over the 7×7 window inside the image)
    λ    = s² / (s² + var)              (1 where both are 0)
    out  = y + low + λ · high           where ``mask``; y elsewhere

``var`` is the variance of z itself (of the accumulated mean, per channel). Where y is right, r
is z's noise: λ ≈ 0 and only its local mean goes back. Where y errs at the pixel scale the
window's energy exceeds the noise's and λ → 1: z. As var → 0 (a converged history) out → z,
so the filter converges with its own accumulation instead of keeping its bias. The 7×7 window
is SVGF's variance window (docs/methods/svgf.md §3); r and var are 0 outside ``mask``.

With ``signed`` (docs/temporal.md §17) a value whose high part is negative (z below the fit)
takes the larger of that λ and one that weighs each pixel's negative part against its own
noise, the variance around it:

    V3    = the 3×3 mean of var around the pixel (SIGNED_NOISE_RADIUS = 1)
    λ_neg = max(1 − n / (2 Σ min(high, 0)² / V3), 0)   (Σ over the window's n fit pixels;
                                                      ½ for a pixel with V3 = 0)
    λ     = max(λ, λ_neg)               where high < 0

1-spp radiance is non-negative with a long bright tail. A firefly's excess is positive and
inflates its own pixel's variance estimate only in part, so the positive side keeps the pooled
test above, which counts the firefly's variance across the window. Below the fit no firefly can
reach, and there a pixel's own noise is the right scale: a dark contact shadow beside a lit,
noisy floor has a residual far beyond its own noise and far below the floor's, which the pooled
test takes for noise. Under symmetric noise E[min(high, 0)²] = var / 2, so λ_neg ≈ 0 where y
is right: it is the Wiener gain of the window's mean of min(high, 0)² / V3. The noise is the
3×3 mean rather than the pixel's own variance because z and var come from the same samples: a
pixel whose recent samples were all low has a low z and a low variance estimate at once, which
a per-pixel ratio takes for a bias (with noise as skewed as 1-spp radiance, on static cameras);
its neighbours' estimates do not share that streak. Each ratio is capped at :data:`RATIO_CAP`
so that a near-zero variance keeps every sum finite.

* :func:`residual_handback_reference` — the readable form (SciPy, float64; the split is
  :func:`~dbench.methods.kernels.handback.wiener_handback` with α_gate = 0).
* :func:`residual_handback_fast` — compiled (Numba, parallel over rows, float32 images, float64
  sums), equal to the reference within float32 rounding (tests).
* :func:`window_variance_reference` / :func:`pixel_window_variance` — the per-channel variance
  of this frame's samples over the 7×7 window (``valid`` pixels only), the estimate a pixel with
  a short history takes instead of its temporal one (as SVGF's §3 does below 4 frames); the
  compiled form is one pixel's, inlined into BMFR's fused moments pass.

A kernel imports no method and nothing of the harness.
"""
from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit, prange

from .handback import wiener_handback
from .variance_floor import window_mean

#: Radius of the window of the energies and of the Gaussian's support: 7×7.
HANDBACK_RADIUS = 3
#: σ of the Gaussian that takes the residual's local mean, in pixels.
HANDBACK_SIGMA = 2.0
#: Cap of one pixel's min(high, 0)² / V3 in the signed rule: past it λ_neg is 1 to 1e-4
#: whatever the rest of the window holds, and every sum stays finite in float32.
RATIO_CAP = 1e6
#: The signed rule divides by at least VAR_TINY: a normal float32, so that neither a ratio nor
#: its reciprocal overflows for a subnormal variance.
VAR_TINY = 1e-30
#: Radius of the signed rule's noise estimate: each pixel's variance is the 3×3 mean around it
#: (docs/temporal.md §17: its own estimate shares z's streaks of low samples).
SIGNED_NOISE_RADIUS = 1


def handback_taps(sigma: float = HANDBACK_SIGMA, radius: int = HANDBACK_RADIUS) -> np.ndarray:
    """The normalised 1-D Gaussian (2·radius + 1,) float64 of the local mean."""
    ax = np.arange(-radius, radius + 1, dtype=np.float64)
    g = np.exp(-0.5 * (ax / sigma) ** 2)
    return g / g.sum()


def _check(z, y, var, mask):
    z, y, var = (np.asarray(a) for a in (z, y, var))
    if z.ndim != 3 or y.shape != z.shape or var.shape != z.shape:
        raise ValueError(f"z, y, var: expected equal (C, H, W) shapes, got {z.shape}, {y.shape}, "
                         f"{var.shape}")
    mask = np.asarray(mask, bool)
    if mask.shape != z.shape[1:]:
        raise ValueError(f"mask: expected shape {z.shape[1:]}, got {mask.shape}")
    return z, y, var, mask


def residual_handback_reference(z: Any, y: Any, var: Any, mask: Any,
                                sigma: float = HANDBACK_SIGMA,
                                radius: int = HANDBACK_RADIUS,
                                clamp: bool = False, signed: bool = False) -> np.ndarray:
    """out = y + low + λ·high of the module docstring (readable form).

    Args:
        z: (C, H, W) accumulated signal; y: (C, H, W) the filter's output; var: (C, H, W)
        variance of z, ≥ 0; mask: (H, W) bool, where the residual is handed back;
        clamp: every output value below 0 becomes 0 (the residual's local mean can take a
        non-negative y below 0; NaN stays NaN); signed: the signed rule's λ.

    Returns:
        (C, H, W) float64.
    """
    from scipy.ndimage import correlate1d

    z, y, var, mask = _check(z, y, var, mask)
    z, y = np.asarray(z, np.float64), np.asarray(y, np.float64)
    r = np.where(mask, z - y, 0.0)
    var0 = np.where(mask, np.asarray(var, np.float64), 0.0)
    g = handback_taps(sigma, radius)

    def blur(img):
        img = correlate1d(img, g, axis=-1, mode="constant")
        return correlate1d(img, g, axis=-2, mode="constant")

    low = blur(r) / blur(np.ones(z.shape[1:]))
    cl = (lambda a: np.moveaxis(a, 0, -1))
    if not signed:
        # wiener_handback(hdr = y + r, den = y, α_gate = 0, α = 1) = y + low + λ·high
        out = wiener_handback(cl(y + r), cl(y), 0.0, cl(low), cl(var0), 1.0, radius)
    else:
        high = r - low
        out = cl(y + low + signed_gain(high, var0, mask, radius) * high)
    out = np.where(mask, np.moveaxis(out, -1, 0), y)
    return np.maximum(out, 0.0) if clamp else out


def signed_gain(high: Any, var: Any, mask: Any, radius: int = HANDBACK_RADIUS) -> np.ndarray:
    """λ of the signed rule (module docstring), readable form: (C, H, W) float64 from (C, H, W)
    ``high`` and ``var`` (0 outside ``mask``) and the (H, W) bool ``mask``."""
    high = np.asarray(high, np.float64)
    var = np.asarray(var, np.float64)
    box = (lambda a: window_mean(np.moveaxis(a, 0, -1), radius).transpose(2, 0, 1))
    noise = box(var)
    excess = np.maximum(box(high * high) - noise, 0.0)
    total = excess + var
    with np.errstate(invalid="ignore", divide="ignore"):
        lam = np.where(total > 0, excess / np.where(total > 0, total, 1.0), 1.0)
        inside = mask[None]
        neg2 = np.where(inside, np.minimum(high, 0.0) ** 2, 0.0)
        v3 = np.where(inside, noise_mean_3x3(var), 0.0)
        ratio = np.minimum(neg2 / np.maximum(v3, VAR_TINY), RATIO_CAP)
        ratio = np.where(inside, np.where(v3 > 0, ratio, 0.5), 0.0)  # no estimate: noise
        energy = box(ratio)
        voters = box(np.broadcast_to(inside, ratio.shape).astype(np.float64))
        lam_neg = np.where(2.0 * energy > voters,
                           1.0 - voters / (2.0 * np.where(energy > 0, energy, 1.0)), 0.0)
    return np.where(high < 0, np.maximum(lam, lam_neg), lam)


def noise_mean_3x3(var: Any) -> np.ndarray:
    """V3 of the signed rule: the mean of (C, H, W) ``var`` over the 3×3 window inside the image,
    float64, by direct sums (a window of zeros gives exactly 0, as in the compiled pass; SciPy's
    running box filter can leave a residue of rounding there)."""
    from scipy.ndimage import correlate1d

    var = np.asarray(var, np.float64)
    taps = np.ones(2 * SIGNED_NOISE_RADIUS + 1)
    sums = correlate1d(correlate1d(var, taps, axis=-1, mode="constant"), taps, axis=-2,
                       mode="constant")
    h, w = var.shape[-2:]
    counts = np.outer(_inside_counts(h, SIGNED_NOISE_RADIUS),
                      _inside_counts(w, SIGNED_NOISE_RADIUS))
    return sums / counts


def _inside_counts(n: int, radius: int) -> np.ndarray:
    """How many of the window's 2r + 1 positions along an axis of length n lie inside."""
    idx = np.arange(n)
    return (np.minimum(idx + radius, n - 1) - np.maximum(idx - radius, 0) + 1).astype(np.float64)


def _gauss_norm(n: int, g: np.ndarray) -> np.ndarray:
    """G*1 along an axis of length n (zero padding)."""
    from scipy.ndimage import correlate1d

    return correlate1d(np.ones(n), g, mode="constant")


#: Output rows per task of the compiled hand-back: each task keeps its intermediate rows (the
#: band and 2R rows either side) in buffers small enough for the cache instead of five
#: full-size intermediate images. (Measured at 720p on the 2-core machine: the three-pass form
#: with full-size images 13.7 ms, the band form 13 ms with its tap loops innermost and 8 ms with
#: x innermost, which vectorises.)
BAND_ROWS = 64


@njit(cache=True, parallel=True, fastmath=True)
def _handback_bands(z, y, var, mask, g, radius, inv_norm_x, norm_y, inv_x, inv_y, inv_x3,
                    inv_y3, band, clamp, signed, ratio_cap, out):  # pragma: no cover - compiled
    """:func:`residual_handback_reference` over bands of ``band`` output rows, in float32 (the
    inputs' magnitudes are bounded by the methods' input guard,
    :data:`dbench.methods.guards.RADIANCE_MAX`, so the 49 squares of a window stay finite;
    λ's division is in float64, so subnormal variances cannot make it overflow).

    Per band and channel: the rows of r and of its x-blur G_x*r from 2R above to 2R below
    the band (``rr``, ``rx``), then from R above to R below the local mean (G_y of rx over G*1,
    ``lo``), the x-sums of high² and of the masked variance (``hx``, ``vx``), then the
    band's output rows from their y-sums. With ``signed`` the a-rows also keep the masked
    variance and its 3-tap x-sums (``vr``, ``v3``), the b-rows add the x-sums of
    min(high, 0)² / V3 (``qx``; V3 the 3×3 mean of the variance), and the window's fit-pixel
    counts at the output rows are summed once for all channels (``mc``). Rows
    are padded with R zeros either side so the tap loops have no branches, and run x innermost
    so that they vectorise."""
    c_n, h, w = z.shape
    r = radius
    taps = 2 * r + 1
    n_bands = (h + band - 1) // band
    inv_cap = np.float32(1.0 / ratio_cap)
    var_tiny = np.float32(VAR_TINY)
    for b in prange(n_bands):
        y_lo = b * band
        y_hi = min(y_lo + band, h)
        a0, a1 = max(y_lo - 2 * r, 0), min(y_hi + 2 * r, h)
        b0, b1 = max(y_lo - r, 0), min(y_hi + r, h)
        rr = np.empty((a1 - a0, w), np.float32)
        rx = np.empty((a1 - a0, w), np.float32)
        lo = np.empty((b1 - b0, w), np.float32)
        hx = np.empty((b1 - b0, w), np.float32)
        vx = np.empty((b1 - b0, w), np.float32)
        vr = np.empty((a1 - a0, w), np.float32)
        v3 = np.empty((a1 - a0, w), np.float32)
        qx = np.empty((b1 - b0, w), np.float32)
        mc = np.empty((y_hi - y_lo, w), np.float32)
        pr = np.zeros(w + 2 * r, np.float32)
        pv = np.zeros(w + 2 * r, np.float32)
        pq = np.zeros(w + 2 * r, np.float32)
        acc = np.empty(w, np.float32)
        eh = np.empty(w, np.float32)
        ev = np.empty(w, np.float32)
        eq = np.empty(w, np.float32)
        en = np.empty(w, np.float32)
        lam_neg = np.empty(w, np.float32)
        if signed:  # the window's fit-pixel counts at the output rows, shared by the channels
            for yb in range(b0, b1):  # x-sums of the mask rows (in qx, free until then)
                for x in range(w):
                    pq[x + r] = np.float32(1.0) if mask[yb, x] else np.float32(0.0)
                en[:] = 0.0
                for k in range(taps):
                    for x in range(w):
                        en[x] += pq[x + k]
                qx[yb - b0, :] = en
            for yo in range(y_lo, y_hi):
                en[:] = 0.0
                for y2 in range(max(yo - r, 0), min(yo + r + 1, h)):
                    for x in range(w):
                        en[x] += qx[y2 - b0, x]
                mc[yo - y_lo, :] = en
        for c in range(c_n):
            for ya in range(a0, a1):
                i = ya - a0
                for x in range(w):
                    d = z[c, ya, x] - y[c, ya, x]
                    pr[x + r] = d if mask[ya, x] else np.float32(0.0)
                    rr[i, x] = pr[x + r]
                acc[:] = 0.0
                for k in range(taps):  # x innermost: this loop vectorises
                    gk = g[k]
                    for x in range(w):
                        acc[x] += gk * pr[x + k]
                rx[i, :] = acc
                if signed:  # the masked variance and its 3-tap x-sums, for V3
                    for x in range(w):
                        pv[x + r] = var[c, ya, x] if mask[ya, x] else np.float32(0.0)
                        vr[i, x] = pv[x + r]
                    for x in range(w):
                        v3[i, x] = pv[x + r - 1] + pv[x + r] + pv[x + r + 1]
            for yb in range(b0, b1):
                j = yb - b0
                acc[:] = 0.0
                for k in range(taps):
                    y2 = yb + k - r
                    if 0 <= y2 < h:
                        gk = g[k]
                        for x in range(w):
                            acc[x] += gk * rx[y2 - a0, x]
                inv_ny = np.float32(1.0) / norm_y[yb]
                if signed:  # the loop twice rather than a branch inside it: it vectorises
                    eq[:] = 0.0  # V3 at this row: the 3-row sum of the 3-tap x-sums
                    for y2 in range(max(yb - 1, 0), min(yb + 2, h)):
                        for x in range(w):
                            eq[x] += v3[y2 - a0, x]
                    inv_y3_b = inv_y3[yb]
                    for x in range(w):
                        low = acc[x] * (inv_ny * inv_norm_x[x])
                        lo[j, x] = low
                        hv = rr[yb - a0, x] - low
                        pr[x + r] = hv * hv
                        inside = mask[yb, x]
                        pv[x + r] = vr[yb - a0, x]
                        neg = min(hv, np.float32(0.0))
                        n2 = neg * neg if inside else np.float32(0.0)
                        noise = eq[x] * (inv_x3[x] * inv_y3_b)
                        # min(n2 / V3, cap) without a division that can overflow; a pixel
                        # without a noise estimate (V3 = 0) counts as noise: ½
                        ratio = n2 / max(max(noise, n2 * inv_cap), var_tiny)
                        pq[x + r] = (ratio if noise > 0.0 else np.float32(0.5)) if inside \
                            else np.float32(0.0)
                    eq[:] = 0.0
                    for k in range(taps):
                        for x in range(w):
                            eq[x] += pq[x + k]
                    qx[j, :] = eq
                else:
                    for x in range(w):
                        low = acc[x] * (inv_ny * inv_norm_x[x])
                        lo[j, x] = low
                        hv = rr[yb - a0, x] - low
                        pr[x + r] = hv * hv
                        pv[x + r] = var[c, yb, x] if mask[yb, x] else np.float32(0.0)
                eh[:] = 0.0
                ev[:] = 0.0
                for k in range(taps):
                    for x in range(w):
                        eh[x] += pr[x + k]
                        ev[x] += pv[x + k]
                hx[j, :] = eh
                vx[j, :] = ev
            for yo in range(y_lo, y_hi):
                eh[:] = 0.0
                ev[:] = 0.0
                eq[:] = 0.0
                for y2 in range(max(yo - r, 0), min(yo + r + 1, h)):
                    for x in range(w):
                        eh[x] += hx[y2 - b0, x]
                        ev[x] += vx[y2 - b0, x]
                    if signed:
                        for x in range(w):
                            eq[x] += qx[y2 - b0, x]
                inv_y_o = inv_y[yo]
                if signed:  # λ_neg = 1 − n / (2 Σ n2/V3) where positive (then Σ > n/2 ≥ ½)
                    for x in range(w):
                        n_fit = mc[yo - y_lo, x]
                        e2 = np.float32(2.0) * eq[x]
                        lam_neg[x] = (np.float32(1.0) - n_fit / e2 if e2 > n_fit
                                      else np.float32(0.0))
                for x in range(w):
                    excess = max(eh[x] - ev[x], np.float32(0.0)) * (inv_x[x] * inv_y_o)
                    # λ in float64: fastmath may divide as excess · (1 / total), and 1 / a
                    # subnormal float32 total (variances near 1e-38 in dark regions) is +Inf,
                    # so 0 · Inf gave NaN where the reference gives 0
                    total = np.float64(excess) + np.float64(var[c, yo, x])
                    lam = np.float32(excess / total) if total > 0.0 else np.float32(1.0)
                    low = lo[yo - b0, x]
                    high = rr[yo - a0, x] - low
                    if signed and high < 0.0:
                        lam = max(lam, lam_neg[x])
                    back = low + lam * high
                    value = y[c, yo, x] + back if mask[yo, x] else y[c, yo, x]
                    if clamp and value < 0.0:  # NaN compares False: kept, as np.maximum
                        value = np.float32(0.0)
                    out[c, yo, x] = value


def residual_handback_fast(z: np.ndarray, y: np.ndarray, var: np.ndarray, mask: np.ndarray,
                           out: np.ndarray | None = None, sigma: float = HANDBACK_SIGMA,
                           radius: int = HANDBACK_RADIUS, band: int = BAND_ROWS,
                           clamp: bool = False, signed: bool = False) -> np.ndarray:
    """:func:`residual_handback_reference`, compiled; float32 (C, H, W) out (any ``band`` height
    gives the same values to float32 rounding). ``clamp`` and ``signed`` as there, in the same
    pass.

    ``out``: an optional (C, H, W) float32 array to write into (not z, y or var).
    """
    z, y, var, mask = _check(z, y, var, mask)
    shape = z.shape
    if out is None:
        out = np.empty(shape, np.float32)
    elif out.shape != shape or out.dtype != np.float32:
        raise ValueError(f"out: expected float32 of shape {shape}, got {out.dtype} {out.shape}")
    g = handback_taps(sigma, radius)
    h, w = shape[1:]
    f32 = (lambda a: np.ascontiguousarray(a, np.float32))
    _handback_bands(f32(z), f32(y), f32(var), np.ascontiguousarray(mask), f32(g), radius,
                    f32(1.0 / _gauss_norm(w, g)), f32(_gauss_norm(h, g)),
                    f32(1.0 / _inside_counts(w, radius)), f32(1.0 / _inside_counts(h, radius)),
                    f32(1.0 / _inside_counts(w, 1)), f32(1.0 / _inside_counts(h, 1)),
                    max(int(band), 1), bool(clamp), bool(signed), RATIO_CAP, out)
    return out


def window_variance_reference(x: Any, valid: Any, radius: int = HANDBACK_RADIUS) -> np.ndarray:
    """Per-channel variance E[x²] − E[x]² of (C, H, W) ``x`` over the ``valid`` (H, W) pixels of
    the (2r + 1)² window around each pixel (0 where the window holds none); float64."""
    from scipy.ndimage import uniform_filter

    x = np.asarray(x, np.float64)
    valid = np.asarray(valid, bool)
    xv = np.where(valid, x, 0.0)
    size = (1, 2 * radius + 1, 2 * radius + 1)
    cnt = uniform_filter(valid.astype(np.float64), size[1:], mode="constant")
    m1 = uniform_filter(xv, size, mode="constant")
    m2 = uniform_filter(xv * xv, size, mode="constant")
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(cnt > 0, m1 / np.where(cnt > 0, cnt, 1.0), 0.0)
        mean2 = np.where(cnt > 0, m2 / np.where(cnt > 0, cnt, 1.0), 0.0)
    return np.maximum(mean2 - mean * mean, 0.0)


@njit(inline="always")
def pixel_window_variance(x, c, yy, xx, radius, valid_a, valid_b):  # pragma: no cover
    """E[x²] − E[x]² (float64, ≥ 0) of channel c of planar (C, H, W) ``x`` over the pixels of
    the (2r + 1)² window around (yy, xx) where both (H, W) masks hold; 0 when there are none
    (the compiled form of :func:`window_variance_reference` at one pixel)."""
    h, w = x.shape[1], x.shape[2]
    n = 0
    s1 = 0.0
    s2 = 0.0
    for y2 in range(max(yy - radius, 0), min(yy + radius + 1, h)):
        for x2 in range(max(xx - radius, 0), min(xx + radius + 1, w)):
            if valid_a[y2, x2] and valid_b[y2, x2]:
                v = np.float64(x[c, y2, x2])
                n += 1
                s1 += v
                s2 += v * v
    if n == 0:
        return 0.0
    m = s1 / n
    return max(s2 / n - m * m, 0.0)


__all__ = ["HANDBACK_RADIUS", "HANDBACK_SIGMA", "RATIO_CAP", "SIGNED_NOISE_RADIUS",
           "handback_taps", "pixel_window_variance", "residual_handback_fast",
           "noise_mean_3x3", "residual_handback_reference", "signed_gain",
           "window_variance_reference"]
