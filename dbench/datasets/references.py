"""Reference settings shared by the steady, sequence and transient loaders: the default spp
(``DBENCH_REF_SPP``), the reference seed and the reference entries of a frame's ``meta``."""
from __future__ import annotations

import os

import numpy as np

from ..errors import DbenchInputError

DEFAULT_REFERENCE_SPP = 4096


def reference_spp() -> int:
    return int(os.environ.get("DBENCH_REF_SPP", DEFAULT_REFERENCE_SPP))


def check_ref_seed(ref_seed: int | None) -> int:
    """The reference seed: 0 for None, else a non-negative integer (DbenchInputError)."""
    if ref_seed is None:
        return 0
    if isinstance(ref_seed, (bool, np.bool_)) or not isinstance(ref_seed, (int, np.integer)) \
            or ref_seed < 0:
        raise DbenchInputError(f"ref_seed: expected an integer >= 0 or None, got {ref_seed!r}")
    return int(ref_seed)


def reference_meta(ref_spp: int, ref_seed: int, reference_var) -> dict:
    """``ref_spp``, ``ref_seed`` and ``ref_rmse`` = sqrt(mean(reference_var)) for ``meta``
    (``reference_var`` one array or a list of them, e.g. a sequence's frames)."""
    if isinstance(reference_var, (list, tuple)):
        total = sum(float(np.asarray(v, np.float64).sum()) for v in reference_var)
        count = sum(int(np.asarray(v).size) for v in reference_var)
        mean_var = total / max(count, 1)
    else:
        mean_var = float(np.mean(np.asarray(reference_var, np.float64)))
    return {"ref_spp": int(ref_spp), "ref_seed": int(ref_seed),
            "ref_rmse": float(np.sqrt(max(mean_var, 0.0)))}
