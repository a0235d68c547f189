"""Pixel-wise metrics on linear HDR values: MSE, RMSE, relMSE, SMAPE, rMAE (docs/metrics.md §1)."""
from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np

from .checks import _check_eps, _finite, check_pair
from .params import RELMSE_EPS, RMAE_EPS, SMAPE_EPS


def pixel_mean(x: np.ndarray) -> np.ndarray:
    """(H, W, C) or (H, W, T, C) → (H, W) mean over the trailing axes: a per-value map made a
    per-pixel one (every pixel holds the same number of values, so whole-image means stay)."""
    return x.reshape(x.shape[0], x.shape[1], -1).mean(axis=-1)


# Per-value error maps (float64, the shape of the inputs): each metric's formula, written once
# and read through its record in records.py (metrics.compute, per_bin and the judge's maps).

def _err_sq(o: np.ndarray, r: np.ndarray) -> np.ndarray:
    d = o - r
    return d * d


def _err_rel_sq(o: np.ndarray, r: np.ndarray, eps: float) -> np.ndarray:
    d = o - r
    return d * d / (r * r + eps)


def _err_smape(o: np.ndarray, r: np.ndarray, eps: float) -> np.ndarray:
    return np.abs(o - r) / (np.abs(o) + np.abs(r) + eps)


def _err_rmae(o: np.ndarray, r: np.ndarray, eps: float) -> np.ndarray:
    return np.abs(o - r) / (np.abs(r) + eps)


# Per-value variance of an error map's estimate that the reference's own noise adds (v_r, the
# variance of the reference mean): E[(x − r)²] = E[(x − t)²] + v_r, and to first order in
# v_r/(r² + ε) the same over r² + ε (README.md, "Metrics").

def _var_sq(v: np.ndarray, r: np.ndarray) -> np.ndarray:
    return v


def _var_rel_sq(v: np.ndarray, r: np.ndarray, eps: float) -> np.ndarray:
    return v / (r * r + eps)


def _mean_error(o: np.ndarray, r: np.ndarray, error_map: Callable[..., np.ndarray],
                *eps: float) -> float:
    """mean of ``error_map(o, r, *eps)`` over every value; NaN when ``o`` is not finite."""
    if not _finite(o):
        return float("nan")
    return float(np.mean(error_map(o, r, *eps)))


def mse(output: Any, reference: Any) -> float:
    """Mean squared error, mean((x − r)²), on linear values (docs/metrics.md §1).

    Args:
        output, reference: (H, W, C) or (H, W, T, C), same shape; transient: the whole tensor.

    Returns:
        float (NaN if ``output`` holds NaN/Inf).
    """
    o, r = check_pair(output, reference)
    return _mean_error(o, r, _err_sq)


def rmse(output: Any, reference: Any) -> float:
    """Root mean squared error, sqrt(mean((x − r)²)), on linear values (docs/metrics.md §1).

    Shapes as :func:`mse`. The only metric of seed 000 (per inset, linear).
    """
    o, r = check_pair(output, reference)
    return math.sqrt(_mean_error(o, r, _err_sq))


def relmse(output: Any, reference: Any, eps: float = RELMSE_EPS) -> float:
    """Relative MSE, mean((x − r)² / (r² + ε)), ε = 1e-2 by default (docs/metrics.md §1).

    Shapes as :func:`mse`.
    """
    o, r = check_pair(output, reference)
    return _mean_error(o, r, _err_rel_sq, _check_eps(eps))


def smape(output: Any, reference: Any, eps: float = SMAPE_EPS) -> float:
    """SMAPE, mean(|x − r| / (|x| + |r| + ε)), ε = 1e-2, no factor 2 (docs/metrics.md §1, as ProDen).

    Shapes as :func:`mse`.
    """
    o, r = check_pair(output, reference)
    return _mean_error(o, r, _err_smape, _check_eps(eps))


def rmae(output: Any, reference: Any, eps: float = RMAE_EPS) -> float:
    """Relative mean absolute error, mean(|x − r| / (|r| + 0.01)) (docs/metrics.md §1).

    noisebase divides this by 3 for no stated reason; dbench does not. Shapes as :func:`mse`.
    """
    o, r = check_pair(output, reference)
    return _mean_error(o, r, _err_rmae, _check_eps(eps))
