"""Reprojection and accumulation on a chosen backend, NumPy in and out: ``"reference"``,
``"numba"``, ``"torch"`` or ``"auto"`` (numba: the GPU runs the device path, docs/gpu.md)."""
from __future__ import annotations

import numpy as np

from ...errors import DbenchInputError
from .geometry import Geometry, expected_distance
from .numba_path import accumulate_fast, numba, reproject_fast
from .params import BACKENDS, EPS_F, N_MAX, TAU_D, TAU_N
from .reference import accumulate, reproject_reference
from .torch_path import accumulate_torch, reproject_torch, to_numpy


def resolve_backend(backend: str) -> str:
    """``"auto"`` → ``"numba"``, the host's compiled path (on a GPU the harness runs the method's
    device path instead, docs/gpu.md §3; the host ``"torch"`` path copied every frame across the
    bus and is kept only on request); other names pass through after validation
    (DbenchInputError naming ``backend``)."""
    if backend not in BACKENDS:
        raise DbenchInputError(f"backend: expected one of {BACKENDS}, got {backend!r}")
    if backend == "auto":
        return "numba"
    return backend


def reproject(history: np.ndarray, cur: Geometry, prev: Geometry, prev_ok: np.ndarray,
              tau_d: float = TAU_D, tau_n: float = TAU_N, eps_f: float = EPS_F,
              backend: str = "numba", out: np.ndarray | None = None
              ) -> tuple[np.ndarray, np.ndarray]:
    """Reproject the previous frame's ``history`` (C, H, W) into the current frame.

    ``backend``: one of :data:`BACKENDS` ("torch" runs :func:`reproject_torch` on CUDA when
    available, else on CPU, and converts back to NumPy).

    Args:
        history: (C, H, W) buffers of frame i−1 (colour, moments, history length, …).
        cur, prev: geometry of frames i and i−1; ``cur.motion`` gives p← (docs/methods/temporal.md §3.1).
        prev_ok: (H, W) bool, which previous pixels may be read (hit, finite, not empty).
        out: an optional (C, H, W) float32 array the compiled kernel writes into (and returns)
            instead of a new one; the other backends ignore it.
    Returns:
        (reprojected (C, H, W) float32, status (H, W) uint8: 0 reset, 1 bilinear, 2 fallback).
    """
    if cur.motion is None:
        raise DbenchInputError("motion: missing; expected an array of shape (H, W, 2)")
    if prev.shape != cur.shape or history.shape[1:] != cur.shape:
        raise DbenchInputError(f"history: expected shape (C, {cur.shape[0]}, {cur.shape[1]}), "
                               f"got {history.shape}")
    d_exp = expected_distance(cur, prev.origin)
    args = (history, cur.motion, cur.hit, cur.normal, d_exp, prev_ok & prev.hit, prev.depth,
            prev.normal, tau_d, tau_n, eps_f)
    backend = resolve_backend(backend)
    if backend == "torch":
        out, status = reproject_torch(*args)
        return to_numpy(out), to_numpy(status)
    if backend == "reference" or numba is None:
        out, status = reproject_reference(*args)
        return out.astype(np.float32), status
    return reproject_fast(*args, out=out)


def accumulate_any(backend: str, sample, history, n_hist, ok, alpha_min=0.0, n_max=N_MAX,
                   alpha=None, sample_ok=None, out=None
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`accumulate` on the resolved ``backend`` ("numba": :func:`accumulate_fast`,
    "torch": :func:`accumulate_torch`, "reference": :func:`accumulate`), NumPy float32 out.
    ``out``: optional (accumulated (C, H, W), N (H, W)) arrays the compiled kernel writes into
    (and returns); the other backends ignore it."""
    backend = resolve_backend(backend)
    args = (sample, history, n_hist, ok, alpha_min, n_max, alpha, sample_ok)
    if backend == "torch":
        return tuple(to_numpy(t) for t in accumulate_torch(*args))
    if backend == "numba" and numba is not None:
        return accumulate_fast(*args, out=out)
    return accumulate(*args)
