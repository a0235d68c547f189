"""Pixel-wise metrics on linear HDR values: MSE, RMSE, relMSE, SMAPE, rMAE (spec anchors.md §1)."""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from .checks import _check_eps, _finite, check_pair
from .params import RELMSE_EPS, RMAE_EPS, SMAPE_EPS


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


def _pixel_map(name: str, o: np.ndarray, r: np.ndarray, eps: float | None) -> np.ndarray:
    if name in ("mse", "rmse"):
        return _err_sq(o, r)
    if name == "relmse":
        return _err_rel_sq(o, r, RELMSE_EPS if eps is None else eps)
    if name == "smape":
        return _err_smape(o, r, SMAPE_EPS if eps is None else eps)
    if name == "rmae":
        return _err_rmae(o, r, RMAE_EPS if eps is None else eps)
    raise AssertionError(name)


def _pixel_value(name: str, o: np.ndarray, r: np.ndarray, eps: float | None = None) -> float:
    if not _finite(o):
        return float("nan")
    value = float(np.mean(_pixel_map(name, o, r, eps)))
    return math.sqrt(value) if name == "rmse" else value


def mse(output: Any, reference: Any) -> float:
    """Mean squared error, mean((x − r)²), on linear values (spec anchors.md §1).

    Args:
        output, reference: (H, W, C) or (H, W, T, C), same shape; transient: the whole tensor.

    Returns:
        float (NaN if ``output`` holds NaN/Inf).
    """
    o, r = check_pair(output, reference)
    return _pixel_value("mse", o, r)


def rmse(output: Any, reference: Any) -> float:
    """Root mean squared error, sqrt(mean((x − r)²)), on linear values (anchors.md §1).

    Shapes as :func:`mse`. The only metric of seed 000 (per inset, linear).
    """
    o, r = check_pair(output, reference)
    return _pixel_value("rmse", o, r)


def relmse(output: Any, reference: Any, eps: float = RELMSE_EPS) -> float:
    """Relative MSE, mean((x − r)² / (r² + ε)), ε = 1e-2 by default (anchors.md §1).

    Shapes as :func:`mse`.
    """
    o, r = check_pair(output, reference)
    return _pixel_value("relmse", o, r, _check_eps(eps))


def smape(output: Any, reference: Any, eps: float = SMAPE_EPS) -> float:
    """SMAPE, mean(|x − r| / (|x| + |r| + ε)), ε = 1e-2, no factor 2 (anchors.md §1, as ProDen).

    Shapes as :func:`mse`.
    """
    o, r = check_pair(output, reference)
    return _pixel_value("smape", o, r, _check_eps(eps))


def rmae(output: Any, reference: Any, eps: float = RMAE_EPS) -> float:
    """Relative mean absolute error, mean(|x − r| / (|r| + 0.01)) (anchors.md §1).

    noisebase divides this by 3 for no stated reason; dbench does not. Shapes as :func:`mse`.
    """
    o, r = check_pair(output, reference)
    return _pixel_value("rmae", o, r, _check_eps(eps))
