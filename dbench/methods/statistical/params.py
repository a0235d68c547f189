"""Constants of the ``statistical`` method with their sources (docs/methods/statistical.md, the
"spec" of the section numbers; [dbench] marks choices made here), and the threshold of its test.

Threshold (docs/methods/statistical.md §5.1): γ given directly wins (γ_t² = 1/(2γ) − 1);
otherwise γ_t = t_{1−α/2, ν} (SciPy) with ν = n_i + n_j − 2; one value when n is uniform, a table
indexed by ν otherwise (ν ≤ 0, i.e. n_i = n_j = 1, gives γ_t = 0: only d == 0 passes).
:func:`resolve_threshold` gives the :class:`Threshold` every backend uses (the readable
reference, the Numba and PyTorch paths, the device paths of images and videos).

Example:
    >>> round(gamma_t_from_gamma(0.05), 6), gamma_from_gamma_t(2.0)
    (3.0, 0.1)
    >>> import numpy as np
    >>> thr = resolve_threshold(np.full((3, 4, 4), 32, np.int32))
    >>> thr.nu, round(thr.gamma_t, 4), thr.source
    (62, 2.911, 'alpha')
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...errors import DbenchInputError

#: Test level α of the steady default (docs/methods/statistical.md §5.1 "steady default").
DEFAULT_ALPHA = 0.005
#: Steady spatial radius (docs/methods/statistical.md §7).
STEADY_RADIUS = 20
#: Largest ν with its own γ_t in the non-uniform table; beyond it the ν = ∞ value is used.
NU_CAP = 1 << 20
#: γ_t² is clamped here so that γ_t²·S never becomes ∞·0.
G2_MAX = 1e300
BACKENDS = ("auto", "numba", "torch", "reference")

__all__ = ["BACKENDS", "DEFAULT_ALPHA", "G2_MAX", "NU_CAP", "STEADY_RADIUS", "Threshold",
           "check_alpha", "g2_from_gamma", "gamma_from_gamma_t", "gamma_t_from_gamma",
           "resolve_threshold", "student_gamma_t"]


def gamma_t_from_gamma(gamma: float) -> float:
    """γ_t = sqrt(1/(2γ) − 1), γ in (0, 0.5] (docs/methods/statistical.md §5): 0.05 → 3, 0.01 → 7, 0.1 → 2."""
    return math.sqrt(g2_from_gamma(gamma))


def gamma_from_gamma_t(gamma_t: float) -> float:
    """γ = 1 / (2(γ_t² + 1)) (docs/methods/statistical.md §5)."""
    return 1.0 / (2.0 * (float(gamma_t) ** 2 + 1.0))


def g2_from_gamma(gamma: Any) -> float:
    """γ_t² = 1/(2γ) − 1 (clamped to :data:`G2_MAX`) of a γ in (0, 0.5], else DbenchInputError
    naming ``gamma``."""
    try:
        g = float(gamma)
    except (TypeError, ValueError):
        raise DbenchInputError(f"gamma: expected a number in (0, 0.5], got {gamma!r}") from None
    if not (0.0 < g <= 0.5):
        raise DbenchInputError(f"gamma: expected a number in (0, 0.5], got {gamma!r}")
    return min(1.0 / (2.0 * g) - 1.0, G2_MAX)


def check_alpha(alpha: Any) -> float:
    """The test level α as a float in (0, 1), else DbenchInputError naming ``alpha``."""
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

    alpha = check_alpha(alpha)
    nu_arr = np.asarray(nu, np.float64)
    q = 1.0 - alpha / 2.0
    finite = np.isfinite(nu_arr) & (nu_arr > 0)
    out = np.where(np.isinf(nu_arr), float(sps.norm.ppf(q)), 0.0)
    if np.any(finite):
        out = np.where(finite, sps.t.ppf(q, np.where(finite, nu_arr, 1.0)), out)
    return float(out) if np.ndim(nu) == 0 else out


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
    """γ_t from ``gamma`` (wins) or from α and ν = n_i + n_j − 2 (docs/methods/statistical.md §5.1).

    Args:
        nint: integer sample counts, any shape (channel-first planes in practice).
        valid: optional mask of the same shape; only these counts decide whether n is uniform.
    """
    if gamma is not None:
        g2 = g2_from_gamma(gamma)
        return Threshold(g2, None, math.sqrt(g2), float(gamma), None,
                         None if alpha is None else float(alpha), "gamma")
    alpha = check_alpha(alpha)
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
