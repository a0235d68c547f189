"""Sample transforms and moment accumulation (docs/methods/statistical.md §3-4).

Shared by steady and transient renders: every 1-spp pass yields the exact per-pixel (or
per-pixel-bin) sample values, which are transformed and added to float64 power sums of the
shifted value u = g(x) − K with K = g(0), so zero samples add exactly nothing.

Example:
    >>> import numpy as np
    >>> acc = PowerSums((1, 1, 1), "identity")
    >>> for v in (0.0, 0.0, 1.0, 4.0):
    ...     acc.add(np.full((1, 1, 1), v))
    >>> s = acc.finalize()
    >>> round(float(s.mean[0, 0, 0]), 6), round(float(s.var_mean[0, 0, 0]), 7)
    (1.25, 0.8958333)
"""
from __future__ import annotations

import numpy as np

from ..data import TRANSFORMS, SampleStats, check_transform
from ..errors import DbenchInputError

#: σ² is taken as exactly 0 when the biased variance is below this fraction of S2/n (§4.1).
ZERO_VARIANCE_RTOL = 1e-10


def transform_samples(x: np.ndarray, transform: str, lam: float = 0.5) -> np.ndarray:
    """g(x) elementwise in float64 (docs/methods/statistical.md §3). Box-Cox clamps negative x to 0 before
    transforming; non-finite x are the caller's business (see :class:`PowerSums`)."""
    check_transform(transform, lam)
    x = np.asarray(x, dtype=np.float64)
    if transform == "identity":
        return x.copy()
    if transform == "box-cox":
        return (np.power(np.maximum(x, 0.0), lam) - 1.0) / lam
    pos = x >= 0
    out = np.empty_like(x)
    xp, xn = x[pos], x[~pos]
    out[pos] = np.log1p(xp) if lam == 0 else (np.power(xp + 1.0, lam) - 1.0) / lam
    out[~pos] = (-np.log1p(-xn) if lam == 2
                 else -(np.power(1.0 - xn, 2.0 - lam) - 1.0) / (2.0 - lam))
    return out


def transform_of_zero(transform: str, lam: float = 0.5) -> float:
    """K = g(0): −1/λ for Box-Cox, 0 otherwise."""
    return float(transform_samples(np.zeros(1), transform, lam)[0])


class PowerSums:
    """Float64 power sums S1, S2, S3 of u = g(x) − g(0) and the count n, per element.

    ``add(x)`` takes one sample per element (one 1-spp pass); the sums merge by addition, so
    partial accumulators of several processes combine with :meth:`merge`.
    Non-finite samples are replaced by 0 and counted in ``n_nonfinite``; negative samples under
    Box-Cox are clamped to 0 and counted in ``n_clamped`` (docs/methods/statistical.md §3 edge cases).
    """

    def __init__(self, shape: tuple[int, ...], transform: str = "box-cox", lam: float = 0.5):
        check_transform(transform, lam)
        self.shape = tuple(shape)
        self.transform, self.lam = transform, float(lam)
        self.k = transform_of_zero(transform, lam)
        self.n = 0
        self.s1 = np.zeros(self.shape, np.float64)
        self.s2 = np.zeros(self.shape, np.float64)
        self.s3 = np.zeros(self.shape, np.float64)
        self.n_nonfinite = 0
        self.n_clamped = 0

    def add(self, x: np.ndarray) -> None:
        x = np.asarray(x)
        if x.shape != self.shape:
            raise DbenchInputError(f"samples: expected shape {self.shape}, got {x.shape}")
        x = x.astype(np.float64, copy=True)
        bad = ~np.isfinite(x)
        if bad.any():
            self.n_nonfinite += int(bad.sum())
            x[bad] = 0.0
        if self.transform == "box-cox":
            neg = x < 0
            if neg.any():
                self.n_clamped += int(neg.sum())
        u = transform_samples(x, self.transform, self.lam)
        u -= self.k
        u2 = u * u
        self.s1 += u
        self.s2 += u2
        u2 *= u
        self.s3 += u2
        self.n += 1

    def add_batch(self, samples: np.ndarray, axis: int) -> np.ndarray:
        """Add several samples per element at once; ``samples`` has them along ``axis``.

        Compiled fast path of :meth:`add` (one fused pass: transform, three power sums and the
        plain sum); tests prove it equal to calling :meth:`add` per sample. Returns the plain
        (untransformed) sum over the sample axis, float64, which the caller uses for the mean.
        """
        x = np.asarray(samples, np.float32)
        axis = axis % x.ndim
        if x.shape[:axis] + x.shape[axis + 1:] != self.shape:
            raise DbenchInputError(f"samples: expected shape {self.shape} with a sample axis "
                                   f"inserted at {axis}, got {x.shape}")
        outer = int(np.prod(x.shape[:axis]))
        m = x.shape[axis]
        x3 = np.ascontiguousarray(x).reshape(outer, m, -1)
        plain = np.zeros((outer, x3.shape[2]), np.float64)
        n_nonfinite, n_clamped = _accumulate(
            x3, TRANSFORMS.index(self.transform), float(self.lam), float(self.k),
            self.s1.reshape(outer, -1), self.s2.reshape(outer, -1), self.s3.reshape(outer, -1),
            plain)
        self.n += m
        self.n_nonfinite += int(n_nonfinite)
        self.n_clamped += int(n_clamped)
        return plain.reshape(self.shape)

    def add_sums(self, m: int, s1: np.ndarray, s2: np.ndarray, s3: np.ndarray,
                 n_nonfinite: int = 0, n_clamped: int = 0) -> None:
        """Add the power sums of ``m`` samples per element made elsewhere (the render kernel of
        :mod:`dbench.datasets.render_moments`), with the same shift, edge rules and counts."""
        for a in (s1, s2, s3):
            if np.shape(a) != self.shape:
                raise DbenchInputError(f"sums: expected shape {self.shape}, got {np.shape(a)}")
        self.s1 += s1
        self.s2 += s2
        self.s3 += s3
        self.n += int(m)
        self.n_nonfinite += int(n_nonfinite)
        self.n_clamped += int(n_clamped)

    def merge(self, other: "PowerSums") -> None:
        if (other.shape, other.transform, other.lam) != (self.shape, self.transform, self.lam):
            raise DbenchInputError("PowerSums.merge: accumulators differ in shape or transform")
        self.s1 += other.s1
        self.s2 += other.s2
        self.s3 += other.s3
        self.n += other.n
        self.n_nonfinite += other.n_nonfinite
        self.n_clamped += other.n_clamped

    def finalize(self) -> SampleStats:
        return stats_from_power_sums(self.n, self.s1, self.s2, self.s3, self.k, self.transform,
                                     self.lam, diagnostics={"n_nonfinite": self.n_nonfinite,
                                                            "n_clamped": self.n_clamped})


def stats_to_arrays(stats: SampleStats) -> dict[str, np.ndarray]:
    """The arrays of ``stats`` as a cache entry stores them. A count array whose every value
    has the same bits (the spp of dbench's own renders) is stored as that one value and
    ``n_shape``: uncompressed, it was a quarter of a steady entry (:func:`stats_from_arrays`
    gives the array back, bit for bit)."""
    n = stats.n
    out = {"n": n, "mean": stats.mean, "var_mean": stats.var_mean, "m3": stats.m3}
    if isinstance(n, np.ndarray) and n.ndim and n.size:
        if not any(n.strides):  # SampleStats' broadcast of one number: given back as such
            out["n"] = np.array(n.flat[0])
            return out
        flat = np.ascontiguousarray(n).reshape(-1)
        bits = flat.view({1: np.uint8, 2: np.uint16, 4: np.uint32, 8: np.uint64}.get(
            n.itemsize, np.uint8)).reshape(n.size, -1)  # each value's bits as one integer
        if (bits == bits[0]).all():
            out.update(n=np.array(n.flat[0]), n_shape=np.asarray(n.shape, np.int64))
    return out


def stats_from_arrays(arrays: dict[str, np.ndarray], transform: str, lam: float) -> SampleStats:
    """:class:`~dbench.data.SampleStats` from the arrays of a cache entry
    (:func:`stats_to_arrays`)."""
    n = arrays["n"]
    if "n_shape" in arrays:
        n = np.full(tuple(int(s) for s in arrays["n_shape"]), n, dtype=np.asarray(n).dtype)
    return SampleStats(n=n, mean=arrays["mean"], var_mean=arrays["var_mean"],
                       m3=arrays["m3"], transform=transform, lam=lam)


def stats_from_power_sums(n: int | np.ndarray, s1: np.ndarray, s2: np.ndarray, s3: np.ndarray,
                          k: float, transform: str, lam: float,
                          diagnostics: dict | None = None) -> SampleStats:
    """Moments from shifted power sums (docs/methods/statistical.md §4.1).

    a = S1/n, m2b = S2/n − a², σ² = m2b·n/(n−1), M3 = S3/n − 3a·m2b − a³ (biased m2b inside M3),
    σ² := 0 when m2b ≤ 1e-10·S2/n; n < 2 gives σ² = 0 and Var = 0 (docs/methods/statistical.md §4.1 rules).
    """
    n_arr = np.broadcast_to(np.asarray(n, dtype=np.float64), np.shape(s1))
    safe_n = np.maximum(n_arr, 1.0)
    a = s1 / safe_n
    s2n = s2 / safe_n
    m2b = s2n - a * a
    zero = (m2b <= ZERO_VARIANCE_RTOL * s2n) | (n_arr < 2)
    m2b = np.where(zero, 0.0, m2b)
    m3 = s3 / safe_n - 3.0 * a * m2b - a ** 3
    # Constant samples leave float64 residue in S3; their third moment is 0 by definition.
    m3 = np.where(zero, 0.0, m3)
    sigma2 = np.where(n_arr >= 2, m2b * n_arr / np.maximum(n_arr - 1.0, 1.0), 0.0)
    var_mean = sigma2 / safe_n
    mean = np.where(n_arr > 0, a + k, 0.0)
    diagnostics = dict(diagnostics or {})
    # Moments that overflowed are counted, never passed on silently as "0 non-finite".
    diagnostics["n_nonfinite_moments"] = int(sum((~np.isfinite(x)).sum()
                                                 for x in (mean, var_mean, m3)))
    return SampleStats(n=np.array(n_arr), mean=mean, var_mean=var_mean, m3=m3,
                       transform=transform, lam=float(lam), diagnostics=diagnostics)


def stats_from_samples(samples: np.ndarray, transform: str = "box-cox", lam: float = 0.5,
                       axis: int = 0) -> SampleStats:
    """Two-pass statistics from stacked samples (the slow, obvious definition, docs/methods/statistical.md §4).

    ``samples`` has the sample axis at ``axis``; used by tests and small synthetic data.
    """
    y = transform_samples(np.moveaxis(np.asarray(samples, np.float64), axis, 0), transform, lam)
    n = y.shape[0]
    mu = y.mean(axis=0)
    dev = y - mu
    sigma2 = (dev ** 2).sum(axis=0) / (n - 1) if n > 1 else np.zeros_like(mu)
    m3 = (dev ** 3).mean(axis=0)
    return SampleStats(n=np.full(mu.shape, float(n)), mean=mu, var_mean=sigma2 / n, m3=m3,
                       transform=transform, lam=lam)


def _accumulate_py(x, code, lam, k, s1, s2, s3, plain):  # pragma: no cover - jitted
    """x: (A, m, B) float32 samples; s1, s2, s3, plain: (A, B) float64 running sums."""
    n_nonfinite = 0
    n_clamped = 0
    for a in prange(x.shape[0]):
        for j in range(x.shape[1]):
            for b in range(x.shape[2]):
                v = np.float64(x[a, j, b])
                if not np.isfinite(v):
                    n_nonfinite += 1
                    v = 0.0
                plain[a, b] += v
                if code == 0:
                    y = v
                elif code == 1:
                    if v < 0.0:
                        n_clamped += 1
                        v = 0.0
                    y = (np.sqrt(v) - 1.0) / lam if lam == 0.5 else (v ** lam - 1.0) / lam
                elif v >= 0.0:
                    y = np.log1p(v) if lam == 0.0 else ((v + 1.0) ** lam - 1.0) / lam
                else:
                    y = (-np.log1p(-v) if lam == 2.0
                         else -((1.0 - v) ** (2.0 - lam) - 1.0) / (2.0 - lam))
                u = y - k
                u2 = u * u
                s1[a, b] += u
                s2[a, b] += u2
                s3[a, b] += u2 * u
    return n_nonfinite, n_clamped


def _moments_py(n, s1, s2, s3, k, rtol, mean, var_mean, m3):  # pragma: no cover - jitted
    """Fused, parallel form of :func:`dbench.datasets.stats.stats_from_power_sums` for one
    sample count ``n`` (every voxel of a transient render has n = spp samples)."""
    safe_n = max(n, 1.0)
    denom = max(n - 1.0, 1.0)
    for i in prange(s1.size):
        a = s1[i] / safe_n
        s2n = s2[i] / safe_n
        m2b = s2n - a * a
        zero = (m2b <= rtol * s2n) or (n < 2.0)
        if zero:
            m2b = 0.0
            m3[i] = 0.0
        else:
            m3[i] = s3[i] / safe_n - 3.0 * a * m2b - a * a * a
        sigma2 = m2b * n / denom if n >= 2.0 else 0.0
        var_mean[i] = sigma2 / safe_n
        mean[i] = a + k if n > 0 else 0.0


try:
    from numba import njit, prange

    _accumulate = njit(parallel=True, cache=True)(_accumulate_py)
    _moments = njit(parallel=True, cache=True)(_moments_py)
except ImportError:  # pragma: no cover - numba is a dependency; keep a slow but exact path
    prange = range
    _accumulate = _accumulate_py
    _moments = _moments_py


def stats_from_sums(n: int, s1: np.ndarray, s2: np.ndarray, s3: np.ndarray, transform: str,
                    lam: float, diagnostics: dict | None = None,
                    shape: tuple[int, ...] | None = None) -> SampleStats:
    """SampleStats from float64 power sums of u = g(x) − g(0) with one count ``n`` for every
    voxel: the formulas of docs/methods/statistical.md §4.1 exactly as
    :func:`~dbench.datasets.stats.stats_from_power_sums` (tests compare them), fused into one
    parallel pass (the numpy version costs about as much as the render at 64²×200 voxels).
    1-D inputs (strided views allowed) are read in place; ``shape`` is then the output shape."""
    shape = np.shape(s1) if shape is None else tuple(shape)
    flat = [a if np.ndim(a) == 1 and np.asarray(a).dtype == np.float64
            else np.ascontiguousarray(a, np.float64).reshape(-1) for a in (s1, s2, s3)]
    out = [np.empty(flat[0].size) for _ in range(3)]
    _moments(float(n), *flat, float(transform_of_zero(transform, lam)),
             float(ZERO_VARIANCE_RTOL), *out)
    mean, var_mean, m3 = (a.reshape(shape) for a in out)
    return SampleStats(n=float(n), mean=mean, var_mean=var_mean, m3=m3, transform=transform,
                       lam=float(lam), diagnostics=dict(diagnostics or {}))


def variance_of_mean(n: int, s1: np.ndarray, s2: np.ndarray) -> np.ndarray | None:
    """Var of the mean of ``n`` plain (identity) samples from their float64 sums Σx and Σx², with
    the rules of :func:`stats_from_sums` (docs/methods/statistical.md §4.1: zero-variance tolerance, the
    n/(n−1) factor), or None below 2 samples (the spread is unknown, not zero). Used for the
    transient noisy totals (``TransientFrame.total_var``) of both collectors, (H, W, 3) in and
    out: NumPy's form of the rules, because the fused :func:`stats_from_sums` would load Numba's
    compiled code (about 0.5 s, the first time in a process) for a per-pixel image."""
    if n < 2:
        return None
    s1 = np.asarray(s1, np.float64)
    stats = stats_from_power_sums(n, s1, np.asarray(s2, np.float64), np.zeros_like(s1), 0.0,
                                  "identity", 0.5)
    return np.asarray(stats.var_mean, np.float64)
