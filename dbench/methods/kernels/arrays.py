"""How arrays reach the compiled (Numba) kernels: one argument type per input.

Numba compiles a kernel once for every combination of its arguments' types, and a NumPy array's
type includes whether it may be written. The same call made on a frame the harness handed out
read-only (dbench/run/inputs.py) and on one a caller built compiled a kernel twice, up to four
times where several inputs vary (the bilateral accumulation: 8-10 s a specialisation on 2 cores,
the gate: about 32 s). Inputs a kernel only reads pass through :func:`kernel_input`, so each
kernel compiles once per dtype.
"""
from __future__ import annotations

import numpy as np


def kernel_input(a, dtype=None) -> np.ndarray:
    """``a`` as a read-only C-contiguous array of ``dtype`` (default: its own): a view where it
    already is one, else one copy."""
    view = np.ascontiguousarray(a, dtype=dtype).view()
    view.flags.writeable = False
    return view


__all__ = ["kernel_input"]
