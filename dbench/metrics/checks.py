"""Input checks shared by the metrics: the (output, reference) pair, ε values, transient
integration over time."""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..data import check_buffer
from ..errors import DbenchInputError


def check_pair(output: Any, reference: Any) -> tuple[np.ndarray, np.ndarray]:
    """Validate an (output, reference) pair and return both as float64 arrays.

    ``reference`` must be (H, W, C) or (H, W, T, C), non-empty and finite; ``output`` must have
    exactly its shape (it may hold NaN/Inf; the metrics turn that into NaN).

    Raises:
        DbenchInputError: naming ``output`` or ``reference`` and the expected shape.
    """
    ref = _as_real_array("reference", reference)
    if ref.ndim not in (3, 4):
        raise DbenchInputError("reference: expected shape (H, W, C) or (H, W, T, C), "
                               f"got {tuple(ref.shape)}")
    layout = "(H, W, C)" if ref.ndim == 3 else "(H, W, T, C)"
    ref = check_buffer("reference", ref, tuple(ref.shape), dtype=np.float64)
    if not np.all(np.isfinite(ref)):
        raise DbenchInputError(f"reference: contains NaN or Inf; expected finite values of shape "
                               f"{layout} = {tuple(ref.shape)}")
    out = _as_real_array("output", output)
    if tuple(out.shape) != tuple(ref.shape):
        raise DbenchInputError(f"output: expected shape {layout} = {tuple(ref.shape)} (the shape "
                               f"of reference), got {tuple(out.shape)}")
    out = check_buffer("output", out, tuple(ref.shape), dtype=np.float64)
    return out, ref


def _as_real_array(name: str, value: Any) -> np.ndarray:
    if value is None:
        raise DbenchInputError(f"{name}: missing; expected an array of shape (H, W, C) "
                               "or (H, W, T, C)")
    arr = np.asarray(value)
    if np.iscomplexobj(arr):
        raise DbenchInputError(f"{name}: expected a real array of shape (H, W, C) or "
                               f"(H, W, T, C), got dtype {arr.dtype}")
    return arr


def _finite(x: np.ndarray) -> bool:
    return bool(np.isfinite(x).all())


def _integrate(x: np.ndarray) -> np.ndarray:
    """(H, W, T, C) -> (H, W, C) by summing over T; (H, W, C) unchanged."""
    return x.sum(axis=2) if x.ndim == 4 else x


def _check_eps(eps: Any, name: str = "eps") -> float:
    try:
        value = float(eps)
    except (TypeError, ValueError):
        raise DbenchInputError(f"{name}: expected a finite number > 0, got {eps!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise DbenchInputError(f"{name}: expected a finite number > 0, got {eps!r}")
    return value
