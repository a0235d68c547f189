"""The BMFR steps on a chosen backend, NumPy in and out: ``"reference"`` (:mod:`.reference`),
``"numba"`` (:mod:`.numba_path`) or ``"torch"`` (:mod:`.torch_path`: every block of a grid in one
batch, QR by ``torch.linalg.qr(mode="r")``, CUDA when available, else CPU)."""
from __future__ import annotations

import numpy as np

from ...errors import DbenchInputError
from ..temporal import to_numpy
from .numba_path import HAVE_NUMBA, bmfr_fit_fast, householder_lstsq_fast
from .params import RCOND
from .reference import bmfr_fit_reference, householder_lstsq_reference
from .torch_path import bmfr_fit_torch, householder_lstsq_torch


def householder_lstsq(A: np.ndarray, B: np.ndarray, rcond: float = RCOND,
                      backend: str = "numba", return_dropped: bool = False):
    """Solve min ‖A X − B‖ for batches A (K, m, n), B (K, m, c) by Householder QR without
    forming Q, R shared by the c right-hand sides (docs/methods/bmfr.md §5) on ``backend`` ("numba",
    "torch" or "reference"). Returns X (K, n, c)
    float64 (and the per-batch count of columns zeroed by the rank safeguard when
    ``return_dropped``). 2-D inputs (m, n), (m, c) are treated as one batch.

    >>> import numpy as np
    >>> A = np.random.default_rng(0).random((4, 50, 3)); X = np.ones((4, 3, 2))
    >>> bool(np.allclose(householder_lstsq(A, A @ X), X))
    True
    """
    A = np.asarray(A)
    B = np.asarray(B)
    single = A.ndim == 2
    if single:
        A, B = A[None], B[None]
    if A.ndim != 3 or B.ndim != 3 or B.shape[:2] != A.shape[:2]:
        raise DbenchInputError(f"A, B: expected shapes (K, m, n) and (K, m, c) with the same K "
                               f"and m, got {A.shape} and {B.shape}")
    if backend == "torch":
        X, dropped = (to_numpy(t) for t in householder_lstsq_torch(A, B, rcond))
    elif backend == "reference" or not HAVE_NUMBA:
        X, dropped = householder_lstsq_reference(A, B, rcond)
    elif backend == "numba":
        X, dropped = householder_lstsq_fast(A, B, rcond)
    else:
        raise DbenchInputError(f"backend: expected 'numba', 'torch' or 'reference', "
                               f"got {backend!r}")
    if single:
        X, dropped = X[0], dropped[0]
    return (X, dropped) if return_dropped else X


def bmfr_fit(backend: str, *args, **kw):
    """Arguments of :func:`~.reference.bmfr_fit_reference` on ``backend``; (y (3, H, W) float32
    NumPy, dropped)."""
    if backend == "torch":
        y, dropped = bmfr_fit_torch(*args, **kw)
        return to_numpy(y), dropped
    if backend == "reference" or not HAVE_NUMBA:
        return bmfr_fit_reference(*args, **kw)
    return bmfr_fit_fast(*args, **kw)
