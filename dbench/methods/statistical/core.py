"""Welch-test statistical denoiser (spec/statistical.md): functional core, reference, fast paths.

w_ij = ρ_ij m_ij v_j / Σ_k ρ_ik m_ik v_k, out_i = Σ_j w_ij L_j          (spec §1, §8)

* ρ is the joint bilateral filter of spec/jbf.md, built by
  :func:`dbench.methods.kernels.bilateral.guide.make_guide` and evaluated by the same code as the
  ``jbf`` method (:func:`~dbench.methods.kernels.bilateral.reference.reference_weights` in the
  reference, the shared Numba kernel :func:`~dbench.methods.kernels.bilateral.numba2d.accumulate`
  or :func:`~dbench.methods.kernels.bilateral.torch_path.accumulate_torch` in the fast paths).
  Nothing is copied.
* m_ij = AND over the channels c of pass_c = (d² < γ_t² S) or (d == 0), with d = θ̂_i − θ̂_j and
  S = Var(θ̂_i) + Var(θ̂_j) of the transformed samples (spec §5, §5.2, §6); m_ii = 1.
* L is the linear noisy colour (Frame.color); v_j = 1 when L_j is finite (missing pixels get no
  weight, and their own output is the filtered value of their valid neighbours, or 0).
* A pixel whose θ̂, Var(θ̂) or n is not finite has no neighbours and is nobody's neighbour
  (spec §5.2 "[dbench] fails unless it is the centre"); its output is its own colour.

Threshold (spec §5.1): γ given directly wins (γ_t² = 1/(2γ) − 1); otherwise
γ_t = t_{1−α/2, ν} (SciPy) with ν = n_i + n_j − 2; one value when n is uniform, a table indexed by
ν otherwise (ν ≤ 0, i.e. n_i = n_j = 1, gives γ_t = 0: only d == 0 passes).

Shapes: colour and statistics are (H, W, 3); the kernels use channel-first (3, H, W) planes.

Example:
    >>> import numpy as np
    >>> from dbench.data import SampleStats
    >>> rng = np.random.default_rng(0)
    >>> y = rng.normal(1.0, 1.0, size=(16, 16, 3, 64))
    >>> stats = SampleStats(n=np.full((16, 16, 3), 64.0), mean=y.mean(-1),
    ...                     var_mean=y.var(-1, ddof=1) / 64,
    ...                     m3=((y - y.mean(-1, keepdims=True)) ** 3).mean(-1),
    ...                     transform="identity")
    >>> flat = np.zeros((16, 16, 3)); flat[..., 2] = 1
    >>> out, info = statistical_filter(y.mean(-1), stats, np.full((16, 16, 3), 0.5), flat,
    ...                                radius=3, backend="numba", return_info=True)
    >>> out.shape, round(info["gamma_t"], 4)
    ((16, 16, 3), 2.8573)
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...data import SampleStats, check_buffer
from ...errors import DbenchInputError
from ..checks import check_choice
from ..kernels.bilateral.guide import Guide, color_planes, image_shape, make_guide
from ..kernels.bilateral.numba2d import accumulate
from ..kernels.bilateral.params import SEED_SIGMA
from ..kernels.bilateral.reference import reference_weights, safe_divide, shift_slices
from ..kernels.bilateral.torch_path import accumulate_torch

DEFAULT_ALPHA = 0.005
#: Largest ν with its own γ_t in the non-uniform table; beyond it the ν = ∞ value is used.
NU_CAP = 1 << 20
#: γ_t² is clamped here so that γ_t²·S never becomes ∞·0.
G2_MAX = 1e300
BACKENDS = ("auto", "numba", "torch", "reference")


# ---------------------------------------------------------------------------------------------
# The pairwise test (spec §5)
# ---------------------------------------------------------------------------------------------

def welch_weight(d: Any, s: Any) -> np.ndarray:
    """Optimal symmetric pair weight w* = (2d² + S) / (2(d² + S)) (spec §5), without NaN.

    d = 0 and S = 0 gives 0.5; S = 0 and d ≠ 0 gives 1; |d| = ∞ gives 1.
    """
    d = np.asarray(d, np.float64)
    s = np.asarray(s, np.float64)
    d2 = d * d
    num = 2.0 * d2 + s
    den = 2.0 * (d2 + s)
    with np.errstate(invalid="ignore", over="ignore"):
        w = np.divide(num, den, out=np.full(np.broadcast(d2, den).shape, 0.5), where=den > 0)
    return np.where(np.isinf(d2), 1.0, w)


def welch_t(d: Any, s: Any) -> np.ndarray:
    """Welch statistic t = |d| / sqrt(S); 0 when d = 0, ∞ when S = 0 and d ≠ 0."""
    d = np.abs(np.asarray(d, np.float64))
    s = np.asarray(s, np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(s > 0, d / np.sqrt(np.where(s > 0, s, 1.0)), np.inf)
    return np.where(d == 0, 0.0, t)


def welch_t_from_weight(w: Any) -> np.ndarray:
    """t = sqrt(1/(2(1 − w*)) − 1) (spec §5); w* = 1 gives ∞."""
    w = np.asarray(w, np.float64)
    with np.errstate(divide="ignore"):
        x = np.where(w < 1, 1.0 / (2.0 * (1.0 - np.minimum(w, 1.0))) - 1.0, np.inf)
    return np.sqrt(np.maximum(x, 0.0))


def gamma_t_from_gamma(gamma: float) -> float:
    """γ_t = sqrt(1/(2γ) − 1), γ in (0, 0.5] (spec §5): 0.05 → 3, 0.01 → 7, 0.1 → 2."""
    return math.sqrt(_g2_from_gamma(gamma))


def gamma_from_gamma_t(gamma_t: float) -> float:
    """γ = 1 / (2(γ_t² + 1)) (spec §5)."""
    return 1.0 / (2.0 * (float(gamma_t) ** 2 + 1.0))


def _g2_from_gamma(gamma: Any) -> float:
    try:
        g = float(gamma)
    except (TypeError, ValueError):
        raise DbenchInputError(f"gamma: expected a number in (0, 0.5], got {gamma!r}") from None
    if not (0.0 < g <= 0.5):
        raise DbenchInputError(f"gamma: expected a number in (0, 0.5], got {gamma!r}")
    return min(1.0 / (2.0 * g) - 1.0, G2_MAX)


def _check_alpha(alpha: Any) -> float:
    try:
        a = float(alpha)
    except (TypeError, ValueError):
        raise DbenchInputError(f"alpha: expected a number in (0, 1), got {alpha!r}") from None
    if not (0.0 < a < 1.0):
        raise DbenchInputError(f"alpha: expected a number in (0, 1), got {alpha!r}")
    return a


def student_gamma_t(alpha: float, nu: Any) -> Any:
    """γ_t = t_{1−α/2, ν}, the two-sided Student-t quantile (SciPy); ν = ∞ gives the normal one.

    ν ≤ 0 (n_i = n_j = 1) gives 0: such a pair only passes with d == 0. t_{0.9975, 62} ≈ 2.911.
    """
    from scipy import stats as sps

    alpha = _check_alpha(alpha)
    nu_arr = np.asarray(nu, np.float64)
    q = 1.0 - alpha / 2.0
    finite = np.isfinite(nu_arr) & (nu_arr > 0)
    out = np.where(np.isinf(nu_arr), float(sps.norm.ppf(q)), 0.0)
    if np.any(finite):
        out = np.where(finite, sps.t.ppf(q, np.where(finite, nu_arr, 1.0)), out)
    return float(out) if np.ndim(nu) == 0 else out


def welch_pass(d: Any, s: Any, g2: Any) -> np.ndarray:
    """Per-channel predicate pass = (d² < γ_t² S) or (d == 0) (spec §5.2), float64, no NaN."""
    d = np.asarray(d, np.float64)
    return (d * d < np.asarray(g2, np.float64) * np.asarray(s, np.float64)) | (d == 0.0)


def membership(theta_i: Any, var_i: Any, theta_j: Any, var_j: Any, gamma_t: float,
               axis: int = -1) -> np.ndarray:
    """m_ij: every channel (along ``axis``) must pass the Welch test at threshold γ_t (spec §6)."""
    g2 = min(float(gamma_t) ** 2, G2_MAX)
    d = np.asarray(theta_i, np.float64) - np.asarray(theta_j, np.float64)
    s = np.asarray(var_i, np.float64) + np.asarray(var_j, np.float64)
    return np.all(welch_pass(d, s, g2), axis=axis)


# ---------------------------------------------------------------------------------------------
# Inputs: statistics and threshold
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class StatPlanes:
    """Channel-first statistics for the kernels (spec §2, §4).

    theta: (3, H, W) float64 θ̂; var: (3, H, W) float64 Var(θ̂); nint: (3, H, W) int32 n;
    bad: (H, W) bool pixels with non-finite statistics (values there are zeroed);
    transform, lam: as recorded in the SampleStats.
    """

    theta: np.ndarray
    var: np.ndarray
    nint: np.ndarray
    bad: np.ndarray
    transform: str
    lam: float


def stat_planes(stats: Any, shape: tuple[int, int] | None = None) -> StatPlanes:
    """Check a :class:`~dbench.data.SampleStats` (or any object with n, var_mean, theta) and
    return channel-first planes.

    Raises:
        DbenchInputError: wrong shape, negative variance or negative sample count.
    """
    if stats is None:
        raise DbenchInputError("stats: missing; expected SampleStats with arrays of shape "
                               f"{'(H, W, 3)' if shape is None else (*shape, 3)}")
    h, w = shape if shape is not None else np.asarray(stats.mean).shape[:2]
    theta = check_buffer("stats.theta", stats.theta, (h, w, 3), dtype=np.float64)
    var = check_buffer("stats.var_mean", stats.var_mean, (h, w, 3), dtype=np.float64)
    n = check_buffer("stats.n", np.broadcast_to(stats.n, (h, w, 3)), (h, w, 3), dtype=np.float64)
    with np.errstate(invalid="ignore"):
        if np.any(var < 0):
            raise DbenchInputError("stats.var_mean: negative values; expected Var(θ̂) ≥ 0")
        if np.any(n < 0):
            raise DbenchInputError("stats.n: negative sample counts")
    bad = ~(np.all(np.isfinite(theta), -1) & np.all(np.isfinite(var), -1)
            & np.all(np.isfinite(n), -1))
    if bad.any():
        theta = np.where(bad[..., None], 0.0, theta)
        var = np.where(bad[..., None], 0.0, var)
        n = np.where(bad[..., None], 0.0, n)
    nint = np.minimum(np.rint(n), 2 ** 30).astype(np.int32)
    return StatPlanes(np.ascontiguousarray(np.moveaxis(theta, -1, 0)),
                      np.ascontiguousarray(np.moveaxis(var, -1, 0)),
                      np.ascontiguousarray(np.moveaxis(nint, -1, 0)), bad,
                      str(getattr(stats, "transform", "unknown")),
                      float(getattr(stats, "lam", float("nan"))))


@dataclass(frozen=True)
class Threshold:
    """Resolved threshold of the test.

    g2: γ_t² when one value serves every pair (γ given, or uniform n), else None;
    table: (L,) γ_t² indexed by ν = n_i + n_j − 2 (clamped to L − 1, whose entry is ν = ∞);
    gamma_t, gamma, nu: for reports (nu None when n is not uniform); source: "gamma" | "alpha".
    """

    g2: float | None
    table: np.ndarray | None
    gamma_t: float | None
    gamma: float | None
    nu: int | None
    alpha: float | None
    source: str

    def g2_for(self, nu: np.ndarray) -> np.ndarray | float:
        """γ_t² for an array of ν (the reference's lookup, identical to the kernels')."""
        if self.table is None:
            return self.g2
        return self.table[np.clip(nu, 0, len(self.table) - 1)]


def resolve_threshold(nint: np.ndarray, alpha: float | None = DEFAULT_ALPHA,
                      gamma: float | None = None, valid: np.ndarray | None = None) -> Threshold:
    """γ_t from ``gamma`` (wins) or from α and ν = n_i + n_j − 2 (spec §5.1).

    Args:
        nint: integer sample counts, any shape (channel-first planes in practice).
        valid: optional mask of the same shape; only these counts decide whether n is uniform.
    """
    if gamma is not None:
        g2 = _g2_from_gamma(gamma)
        return Threshold(g2, None, math.sqrt(g2), float(gamma), None,
                         None if alpha is None else float(alpha), "gamma")
    alpha = _check_alpha(alpha)
    counts = nint if valid is None else nint[valid]
    if counts.size == 0:
        counts = np.zeros(1, np.int64)
    lo, hi = int(counts.min()), int(counts.max())
    if lo == hi:
        nu = 2 * lo - 2
        gt = float(student_gamma_t(alpha, nu))
        g2 = min(gt * gt, G2_MAX)
        return Threshold(g2, None, gt, gamma_from_gamma_t(gt), nu, alpha, "alpha")
    nu_max = min(2 * hi - 2, NU_CAP)
    nus = np.arange(nu_max + 2, dtype=np.float64)
    nus[-1] = np.inf
    table = np.minimum(np.asarray(student_gamma_t(alpha, nus)) ** 2, G2_MAX)
    return Threshold(None, table, None, None, None, alpha, "alpha")


# ---------------------------------------------------------------------------------------------
# Reference implementation (dense NumPy, float64)
# ---------------------------------------------------------------------------------------------

def statistical_reference(color: Any, sp: StatPlanes, guide: Guide, threshold: Threshold, *,
                          membership_on: bool = True, return_weights: bool = False):
    """Readable statistical denoiser: loop over offsets, whole shifted images (spec §8).

    For each offset o: ρ from
    :func:`~dbench.methods.kernels.bilateral.reference.reference_weights` (the JBF's own code),
    m from the per-channel Welch predicate, v from the colour's finiteness.

    Returns:
        (H, W, 3) float64; with ``return_weights`` also (O, H, W) normalised weights and the
        (O, H, W) bool memberships (True where the pair is in the image and passes).
    """
    guide = guide.isolate(sp.bad)
    h, w = guide.shape
    col, valid = color_planes(color, (h, w))
    theta = np.moveaxis(sp.theta, 0, -1)
    var = np.moveaxis(sp.var, 0, -1)
    nint = np.moveaxis(sp.nint, 0, -1).astype(np.int64)
    num = np.zeros((h, w, 3))
    den = np.zeros((h, w))
    stack, members = [], []
    for k in range(len(guide.dy)):
        dy, dx = int(guide.dy[k]), int(guide.dx[k])
        (ys, xs), (yn, xn) = shift_slices(dy, dx, h, w)
        rho = reference_weights(guide, k)
        m = np.zeros((h, w), bool)
        if dy == 0 and dx == 0:
            m[:] = True                                        # the centre always counts
        elif ys.start < ys.stop and xs.start < xs.stop and membership_on:
            d = theta[ys, xs] - theta[yn, xn]
            s = var[ys, xs] + var[yn, xn]
            g2 = threshold.g2_for(nint[ys, xs] + nint[yn, xn] - 2)
            m[ys, xs] = np.all(welch_pass(d, s, g2), axis=-1)
        elif ys.start < ys.stop and xs.start < xs.stop:
            m[ys, xs] = True
        wk = rho * m
        wk[ys, xs] *= valid[yn, xn]
        num[ys, xs] += wk[ys, xs, None] * col[yn, xn]
        den += wk
        if return_weights:
            stack.append(wk)
            members.append(m)
    out = np.divide(num, den[..., None], out=np.zeros_like(num), where=den[..., None] > 0)
    if return_weights:
        ws = np.stack(stack)
        return out, np.divide(ws, den, out=np.zeros_like(ws), where=den > 0), np.stack(members)
    return out


# ---------------------------------------------------------------------------------------------
# Fast paths
# ---------------------------------------------------------------------------------------------

def statistical_fast(color: Any, sp: StatPlanes, guide: Guide, threshold: Threshold, *,
                     backend: str = "numba", membership_on: bool = True, device: Any = None,
                     dtype: Any = None) -> np.ndarray:
    """Numba (default) or PyTorch statistical denoiser: (H, W, 3) float32.

    Uses the JBF's shared accumulation (float32 weights, float64 Welch test bit-identical to the
    reference, symmetric pairs, parallel row bands, O(H·W) memory). ``device``/``dtype`` apply to
    the PyTorch backend (default: CUDA if available, float32).
    """
    guide = guide.isolate(sp.bad)
    col, valid = color_planes(color, guide.shape)
    planes = np.concatenate([np.moveaxis(col, -1, 0), valid[None].astype(np.float64)], axis=0)
    test = {}
    if membership_on:
        test = dict(theta=sp.theta, var=sp.var)
        if threshold.table is None:
            test["g2"] = threshold.g2
        else:
            test.update(nint=sp.nint, g2_table=threshold.table)
    if backend == "torch":
        sums = accumulate_torch(guide, planes, device=device, dtype=dtype, **test)
    else:
        sums = accumulate(guide, planes, **test)
    sums += planes                                       # centre: ρ_ii = m_ii = 1, weight v_i
    out = safe_divide(sums[:3], sums[3:4])
    return np.ascontiguousarray(np.moveaxis(out, 0, -1), dtype=np.float32)


# ---------------------------------------------------------------------------------------------
# Public entry point
# ---------------------------------------------------------------------------------------------

def resolve_backend(backend: str) -> str:
    check_choice("backend", backend, BACKENDS)
    if backend == "auto":
        # on a GPU the harness runs the device path (docs/gpu.md §3); the host-side "torch"
        # path, which copied the frame across the bus inside every call, only on request
        return "numba"
    return backend


def statistical_filter(color: Any, stats: SampleStats, albedo: Any, normal: Any, depth: Any = None,
                       position: Any = None, *, radius: int = 20,
                       alpha: float | None = DEFAULT_ALPHA,
                       gamma: float | None = None, sigma=SEED_SIGMA,
                       sigma_convention: str = "variance", window: str = "square",
                       hit_mask: bool = True, features=("xy", "albedo", "normal"),
                       membership_on: bool = True, backend: str = "auto",
                       return_info: bool = False):
    """Statistical denoiser of spec/statistical.md on one steady image.

    Args:
        color: (H, W, 3) linear noisy colour (the image that is filtered).
        stats: SampleStats with (H, W, 3) n, mean, var_mean, m3 of the transformed samples
            (θ̂ = stats.theta, Var(θ̂) = stats.var_mean).
        albedo, normal: (H, W, 3); depth: (H, W, 1) or None (all pixels hit); position: (H, W, 3)
            when ``features`` include it.
        radius, sigma, sigma_convention, window, hit_mask, features: base filter ρ (spec/jbf.md).
        alpha: test level, γ_t = t_{1−α/2, n_i+n_j−2}; gamma: threshold given directly (wins).
        membership_on: False gives the plain JBF (every membership forced on; ablation).
        backend: "auto" (Numba), "numba", "torch", "reference".
        return_info: also return a dict of resolved settings (γ_t, ν, transform, backend...).

    Returns:
        (H, W, 3) float32 (and the info dict).
    """
    shape = image_shape(color)
    backend = resolve_backend(backend)
    guide = make_guide(albedo, normal, depth, position, radius=radius, sigma=sigma,
                       sigma_convention=sigma_convention, window=window, hit_mask=hit_mask,
                       features=features, shape=shape)
    sp = stat_planes(stats, shape)
    thr = resolve_threshold(sp.nint, alpha, gamma, valid=np.broadcast_to(~sp.bad, sp.nint.shape))
    if backend == "reference":
        out = statistical_reference(color, sp, guide, thr,
                                    membership_on=membership_on).astype(np.float32)
    else:
        out = statistical_fast(color, sp, guide, thr, backend=backend, membership_on=membership_on)
    if not return_info:
        return out
    info = dict(guide.settings, alpha=thr.alpha, gamma=thr.gamma, gamma_t=thr.gamma_t, nu=thr.nu,
                threshold_source=thr.source, uniform_n=thr.table is None,
                transform=sp.transform, lam=sp.lam, membership=bool(membership_on),
                backend=backend, n_bad_stats=int(sp.bad.sum()))
    return out, info
