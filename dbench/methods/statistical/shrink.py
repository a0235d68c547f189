"""Centre-versus-neighbourhood shrinkage of the spatio-temporal statistical denoiser [dbench].

Why (results/transient_statistical.md §6): the Welch test of spec §5 is pairwise, but the
output is a normalised sum over every neighbour that passed. A voxel whose own variance is
large, such as a directly seen light in a time bin reached by a few paths (its samples are
0 or L_e), passes the test against almost any dim neighbour (t = |d|/√S ≈ √hits < γ_t), so
dozens of dim neighbours are accepted and its output collapses towards them: at 128 spp a
fog-transient light voxel of 2.81 (reference 5.23) came out at 0.39. Spec §5's own optimal
pairwise weight says such a neighbour deserves 1 − w* = 1/(2(t² + 1)) ≈ 0.07, not a share of
1 − 1/N.

The rule applies spec §5's MSE argument once more, between the centre voxel i and the
combination of the neighbours its test accepted. With the seed's weights w_j = ρ_ij m_ij v_j
(j ≠ i, centre weight 1) and the channel means θ̄ = mean_c θ̂_c, V̄ = mean_c Var(θ̂_c) (one β
per voxel: the channels of a rendered sample move together, and one β keeps the kernel at 7
planes instead of 13, which halved its speed):

    A = Σ w_j,  L_N = Σ w_j L_j / A,  θ_N = Σ w_j θ̄_j / A,  V_N = Σ w_j² V̄_j / A²
    V_i' = max(V̄_i, V_N · A² / Σ w_j²)     (a voxel no path reached has variance 0 but an
                                             unknown, not a zero, spread: take the accepted
                                             neighbours' variance per effective sample)
    b² = max((θ̄_i − θ_N)² − V_i' − V_N, 0) (positive-part estimate of the squared bias)
    β* = V_i' / (V_i' + V_N + b²)           (minimises (1 − β)² V_i' + β² (V_N + b²))
    β  = min(A / (1 + A), β*)              (never more smoothing than the seed's own weights)
    out_c = (1 − β) L_i,c + β L_N,c

Where the accepted neighbours agree with the centre (b² ≈ 0) and have its variance, β* ≈
A/(1 + A) and the output is the seed's; where they are significantly brighter or darker in
aggregate, the centre keeps the weight its precision earns. θ̂ and variances are those of the
test (transformed samples, spec §3-4), the mixing applies to the linear colour L as in spec §2.
A centre with no accepted neighbour, non-finite colour or bad statistics gets the seed's output.
The positive-part estimate of b² is itself noisy: in homogeneous noise it gives up part of the
seed's variance reduction (tests/methods/test_statistical_shrink.py states the measured cost).

Shapes: sums (K, 7, H, W) float64 neighbour sums (planes below, without the centre term);
planes (K, 7, H, W) float32 centre values; out (H, W, T, 3) float32.

Planes (:func:`shrink_planes`): 0-2 colour·v, 3 v, 4 θ̄·v (summed with w), 5 V̄·v and 6 v
(summed with w²).
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

#: Number of planes of the shrinkage path and the first one summed with squared weights.
SHRINK_PLANES = 7
SQUARED_FROM = 5


def shrink_planes(planes: np.ndarray, theta: np.ndarray, var: np.ndarray) -> np.ndarray:
    """(K, 7, H, W) float32 kernel planes from the seed's (K, 4, H, W) planes (colour·v, v)
    and the (K, 3, H, W) θ̂ (NaN at bad voxels, which are nobody's neighbours: 0 here) and
    Var(θ̂): 4 θ̄·v (summed with w), 5 V̄·v and 6 v (both summed with w²)."""
    k, _, h, w = planes.shape
    out = np.empty((k, SHRINK_PLANES, h, w), np.float32)
    out[:, :4] = planes
    v = planes[:, 3]
    out[:, 4] = np.nan_to_num(theta.mean(axis=1), nan=0.0, posinf=0.0, neginf=0.0) * v
    out[:, 5] = var.mean(axis=1) * v
    out[:, 6] = v
    return out


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
def merge_shrink3d(sums, planes, active, bins, out):
    """Shrunk outputs of the active bins written into ``out`` (H, W, T, 3) float32."""
    K = planes.shape[0]
    H = planes.shape[2]
    W = planes.shape[3]
    for y in prange(H):
        for k in range(K):
            if not active[k]:
                continue
            t = bins[k]
            for x in range(W):
                v = planes[k, 3, y, x]
                a = sums[k, 3, y, x]
                if v + a <= 0:
                    for c in range(3):
                        out[y, x, t, c] = 0.0
                    continue
                if v == 0 or a <= 0:                   # the seed's output
                    for c in range(3):
                        out[y, x, t, c] = (planes[k, c, y, x] + sums[k, c, y, x]) / (v + a)
                    continue
                beta = shrink_beta(planes[k, 4, y, x], planes[k, 5, y, x], a,
                                   sums[k, 4, y, x], sums[k, 5, y, x], sums[k, 6, y, x])
                for c in range(3):
                    out[y, x, t, c] = ((1.0 - beta) * planes[k, c, y, x]
                                       + beta * sums[k, c, y, x] / a)


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


def mass_shrink(video: np.ndarray, color: np.ndarray, total_var: np.ndarray) -> tuple:
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
