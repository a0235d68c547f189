"""Centre-versus-neighbourhood shrinkage of the spatio-temporal statistical denoiser [dbench].

Why (results/transient_statistical.md §6): the Welch test of docs/methods/statistical.md §5 is pairwise, but the
output is a normalised sum over every neighbour that passed. A voxel whose own variance is
large, such as a directly seen light in a time bin reached by a few paths (its samples are
0 or L_e), passes the test against almost any dim neighbour (t = |d|/√S ≈ √hits < γ_t), so
dozens of dim neighbours are accepted and its output collapses towards them: at 128 spp a
fog-transient light voxel of 2.81 (reference 5.23) came out at 0.39. Spec §5's own optimal
pairwise weight says such a neighbour deserves 1 − w* = 1/(2(t² + 1)) ≈ 0.07, not a share of
1 − 1/N.

The rule applies docs/methods/statistical.md §5's MSE argument once more, between the centre voxel i and the
combination of the neighbours its test accepted. With the seed's weights w_j = ρ_ij m_ij v_j
(j ≠ i, centre weight 1), V̄ = mean_c Var(θ̂_c) and θ̄ the channel mean of the values whose
bias is measured (one β per voxel: the channels of a rendered sample move together, and one β
keeps the kernel at 6-7 planes instead of 13, which halved its speed):

    A = Σ w_j,  L_N = Σ w_j L_j / A,  θ_N = Σ w_j θ̄_j / A,  V_N = Σ w_j² V̄_j / A²
    V_i' = max(V̄_i, V_N · A² / Σ w_j²)     (a voxel no path reached has variance 0 but an
                                             unknown, not a zero, spread: take the accepted
                                             neighbours' variance per effective sample)
    b² = max((θ̄_i − θ_N)² − V_i' − V_N, 0) (positive-part estimate of the squared bias)
    β* = V_i' / (V_i' + V_N + b²)           (minimises (1 − β)² V_i' + β² (V_N + b²))
    β  = min(A / (1 + A), β*)              (never more smoothing than the seed's own weights)
    out_c = (1 − β) L_i,c + β L_N,c

Which θ̄ (:func:`bias_from_colour`): the MSE above is that of the mixed linear colour L, so its
bias is measured on L wherever the variances are those of L, i.e. for the identity transform
(transient data's default: Var(θ̂) is then the variance of the sample mean L; θ̂ only adds the
skewness correction of docs/methods/statistical.md §4, which is not in the output). The kernel then needs no θ̄
plane (Σ w θ̄ is the channel mean of the colour sums), which saves one of seven planes. For
the other transforms the variances are those of the transformed θ̂, and θ̄ is θ̂'s channel
mean, as the test sees it.

Where the accepted neighbours agree with the centre (b² ≈ 0) and have its variance, β* ≈
A/(1 + A) and the output is the seed's; where they are significantly brighter or darker in
aggregate, the centre keeps the weight its precision earns. A centre with no accepted
neighbour, non-finite colour or bad statistics gets the seed's output. The positive-part
estimate of b² is itself noisy: in homogeneous noise it gives up part of the seed's variance
reduction (tests/methods/test_statistical_shrink.py states the measured cost).

Kernel planes (:func:`shrink_layout`; written by
:func:`dbench.methods.statistical.transient_inputs.prepare_video` in its one pass): 0-2
colour·v, 3 v (summed with w); then, when the bias is measured on θ̂, θ̄·v (summed with w);
then V̄·v and v (summed with w²). Shapes: planes (K, P, H, W) float32 with P = 6 or 7; band
accumulators of :func:`dbench.methods.kernels.bilateral.numba3d.accumulate3d` (``bands=True``);
out (H, W, T, 3) float32.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from ...data import check_buffer
from ..kernels.bilateral.numba3d import add_band_rows


def bias_from_colour(transform: str) -> bool:
    """True when the shrinkage measures the bias on the linear colour (identity transform: the
    variances are those of the colour), False when on θ̂ (module docstring)."""
    return str(transform) == "identity"


def shrink_layout(colour_bias: bool) -> tuple[int, int, int]:
    """(planes, first plane summed with w², θ̄ plane or −1) of the kernel (module docstring)."""
    return (6, 4, -1) if colour_bias else (7, 5, 4)


@njit(cache=True)
def shrink_beta(theta_i, var_i, a, theta_sum, var2_sum, w2_sum):
    """β of one voxel (module docstring); ``a`` = Σ w_j > 0, the sums Σ w_j θ̄_j,
    Σ w_j² V̄_j and Σ w_j² over the accepted neighbours."""
    theta_n = theta_sum / a
    var_n = var2_sum / (a * a)
    var_c = var_i
    if w2_sum > 0:
        var_c = max(var_i, var2_sum / w2_sum)
    d = theta_i - theta_n
    b2 = max(d * d - var_c - var_n, 0.0)
    total = var_c + var_n + b2
    beta = a / (1.0 + a)
    if total > 0:
        beta = min(beta, var_c / total)
    return beta


@njit(parallel=True, cache=True)
def merge_shrink3d(acc, band, scale, planes, active, bins, theta_plane, out):
    """Shrunk outputs of the active bins written into ``out`` (H, W, T, 3) float32.

    ``acc`` (nbands, K, P, band + halo, W) float32 are the band accumulators of the 3D kernel
    (neighbour sums without the centre term), summed here in float64 per voxel and multiplied
    by ``scale`` (P,) float64, the factors the kernel's planes were divided by (1 for ordinary
    planes; a colour near the float32 maximum is scaled down so that its float32 sums stay
    finite); ``band`` rows per band. ``planes`` are the unscaled (K, P, H, W) values, the centre
    terms. ``theta_plane`` is the θ̄ plane, or −1 when θ̄ is the colour's channel mean.
    """
    K = planes.shape[0]
    P = planes.shape[1]
    H = planes.shape[2]
    W = planes.shape[3]
    vi = P - 2                                    # V̄·v, then v, both summed with w²
    for y in prange(H):
        s = np.zeros((P, W), np.float64)
        for k in range(K):
            if not active[k]:
                continue
            s[:] = 0.0
            add_band_rows(acc, k, y, band, s)
            for p in range(P):
                if scale[p] != 1.0:
                    for x in range(W):
                        s[p, x] *= scale[p]
            t = bins[k]
            for x in range(W):
                v = planes[k, 3, y, x]
                a = s[3, x]
                if v + a <= 0:
                    for c in range(3):
                        out[y, x, t, c] = 0.0
                    continue
                if v == 0 or a <= 0:                   # the seed's output
                    for c in range(3):
                        out[y, x, t, c] = (planes[k, c, y, x] + s[c, x]) / (v + a)
                    continue
                if theta_plane < 0:
                    theta_i = (np.float64(planes[k, 0, y, x]) + np.float64(planes[k, 1, y, x])
                               + np.float64(planes[k, 2, y, x])) / 3.0
                    theta_sum = (s[0, x] + s[1, x] + s[2, x]) / 3.0
                else:
                    theta_i = planes[k, theta_plane, y, x]
                    theta_sum = s[theta_plane, x]
                beta = shrink_beta(theta_i, planes[k, vi, y, x], a, theta_sum, s[vi, x],
                                   s[vi + 1, x])
                for c in range(3):
                    out[y, x, t, c] = ((1.0 - beta) * planes[k, c, y, x]
                                       + beta * s[c, x] / a)


def shrink_reference(col, theta, var, valid, num, den, theta_num, var2_num, w2_num):
    """Readable float64 NumPy version of the rule on whole arrays.

    col: (..., 3) centre colour; theta, var: (...) centre θ̄, V̄; valid: (...) centre colour
    finite; num: (..., 3) Σ w L; den, theta_num, var2_num, w2_num: (...) Σ w, Σ w θ̄,
    Σ w² V̄, Σ w² over the accepted neighbours.
    """
    v = valid.astype(np.float64)
    a = np.asarray(den, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        seed = np.where((v + a > 0)[..., None], (col * v[..., None] + num) / (v + a)[..., None],
                        0.0)
        theta_n = theta_num / a
        var_n = var2_num / (a * a)
        var_c = np.where(w2_num > 0, np.maximum(var, var2_num / w2_num), var)
        b2 = np.maximum((theta - theta_n) ** 2 - var_c - var_n, 0.0)
        total = var_c + var_n + b2
        beta = a / (1.0 + a)
        beta = np.where(total > 0, np.minimum(beta, var_c / total), beta)
        shrunk = (1.0 - beta[..., None]) * col + beta[..., None] * num / a[..., None]
    use = (v > 0) & (a > 0)
    return np.where(use[..., None], shrunk, seed)


def mass_shrink_reference(video: np.ndarray, color: np.ndarray, total_var: np.ndarray) -> tuple:
    """Per-pixel time integral of a denoised video shrunk towards the noisy one [dbench].

    Why (results/transient_statistical.md §6): each voxel's small bias, harmless in its own
    bin, adds up coherently over the T bins of a pixel, while the noisy pixel total is a plain
    n-sample mean whose variance ``total_var`` (of the per-path sums over the window's bins) is
    far below the sum of the per-bin variances (the bins of a path are anti-correlated: a
    directly seen light lands in one bin or the next, its total is exact). Per pixel and
    channel, with M_n = Σ_t color, M_d = Σ_t video and V_M = ``total_var``:

        β = V_M / (V_M + (M_d − M_n)²)   (1 where both are 0)
        M = M_n + β (M_d − M_n),          video ← video · M / M_d  (where M_d > 0)

    This is the MSE-optimal mix of an unbiased estimate (variance V_M) and a precise one whose
    bias is b, β = V_M/(V_M + b²), with the whole observed difference taken as the bias. The
    voxel rule subtracts the noise from d² because its two sides are independent; here M_d
    contains the pixel's own samples, so the noise share of (M_d − M_n)² is below V_M by an
    unknown amount, and counting it all as bias errs towards the unbiased total (measured in
    results/transient_statistical.md §6: subtracting V_M left the integrated error of
    cornell-transient at 16-64 spp 7-12 % above the noisy input's). A difference small against
    the noise keeps the denoised total; a large one (bias) moves it to the noisy one. The
    temporal profile stays the denoiser's.

    Args:
        video: (H, W, T, 3) denoised; color: (H, W, T, 3) noisy; total_var: (H, W, 3) variance
            of the noisy total's mean. Pixels whose noisy total is not finite are left alone.
    Returns:
        ((H, W, T, 3) float32 video, (H, W, 3) float64 β).
    """
    out = np.asarray(video, np.float64)
    # non-finite totals (an Inf or NaN voxel) are expected here and left alone below
    with np.errstate(invalid="ignore", over="ignore"):
        m_d = out.sum(axis=2)
        m_n = np.asarray(color, np.float64).sum(axis=2)
        v_m = np.maximum(np.asarray(total_var, np.float64), 0.0)
        den = v_m + (m_d - m_n) ** 2
        beta = np.divide(v_m, den, out=np.ones_like(den), where=den > 0)
        target = m_n + beta * (m_d - m_n)
    # a pixel with a non-finite noisy total (or none to rescale) keeps the denoiser's total
    ok = (m_d > 0) & np.isfinite(target) & np.isfinite(m_d)
    scale = np.divide(target, m_d, out=np.ones_like(m_d), where=ok)
    return (out * scale[:, :, None, :]).astype(np.float32), beta


@njit(parallel=True, cache=True)
def _mass_shrink_kernel(video, color, total_var, out, beta):
    """One pass per pixel of :func:`mass_shrink_reference`'s rule, float64 sums."""
    H = video.shape[0]
    W = video.shape[1]
    T = video.shape[2]
    for y in prange(H):
        m_d = np.empty(3, np.float64)
        m_n = np.empty(3, np.float64)
        for x in range(W):
            m_d[:] = 0.0
            m_n[:] = 0.0
            for t in range(T):
                for c in range(3):
                    m_d[c] += video[y, x, t, c]
                    m_n[c] += color[y, x, t, c]
            for c in range(3):
                v_m = total_var[y, x, c]
                if not np.isnan(v_m):
                    v_m = max(v_m, 0.0)
                d = m_d[c] - m_n[c]
                den = v_m + d * d
                b = v_m / den if den > 0 else 1.0
                beta[y, x, c] = b
                target = m_n[c] + b * d
                scale = 1.0
                if m_d[c] > 0 and np.isfinite(target) and np.isfinite(m_d[c]):
                    scale = target / m_d[c]
                for t in range(T):
                    out[y, x, t, c] = np.float64(video[y, x, t, c]) * scale


def mass_shrink(video: np.ndarray, color: np.ndarray, total_var: np.ndarray) -> tuple:
    """The pixel-total rule of :func:`mass_shrink_reference` in one parallel pass (Numba);
    equal to it within float32 rounding (tests). Same arguments and returns."""
    h, w, t = np.shape(video)[:3]

    def exact_float(a):                  # float32 or float64 as given, anything else float32
        dt = np.asarray(a).dtype
        return dt if dt in (np.float32, np.float64) else np.float32

    video = check_buffer("video", video, (h, w, t, 3), dtype=exact_float(video))
    color = check_buffer("color", color, (h, w, t, 3), dtype=exact_float(color))
    total_var = check_buffer("total_var", total_var, (h, w, 3), dtype=np.float64)
    out = np.empty((h, w, t, 3), np.float32)
    beta = np.empty((h, w, 3), np.float64)
    _mass_shrink_kernel(video, color, total_var, out, beta)
    return out, beta
