"""Constants of the temporal machinery with their sources (docs/methods/temporal.md; [dbench] marks values
chosen here, [S001] values of seed 001), the reprojection status codes and the backends."""
from __future__ import annotations

import numpy as np


LUMA = np.array([0.2126, 0.7152, 0.0722], np.float32)  # Rec. 709 [dbench]
N_MAX = 256          # history cap [S001]
TAU_D = 0.05         # relative depth tolerance (§3.2) [dbench]
TAU_N = 0.9          # normal cosine (§3.2) [dbench]
EPS_F = 1e-3         # minimum bilinear weight (§3.3) [dbench]
#: §3.4 fallback kernel exactly as printed in the seed (sums to 0.9997; normalised in use).
FALLBACK_KERNEL = np.array([[0.0778, 0.1233, 0.0778],
                            [0.1233, 0.1953, 0.1233],
                            [0.0778, 0.1233, 0.0778]])
#: reprojection status codes
RESET, BILINEAR, FALLBACK = 0, 1, 2
#: "auto" resolves to "numba" (:func:`resolve_backend`; on a GPU the device path runs, docs/gpu.md).
BACKENDS = ("auto", "numba", "torch", "reference")


#: Below this many pixels the compiled kernels run on one thread: a parallel region costs
#: more than the work, and on a shared machine each one waits for a descheduled second thread.
SMALL_IMAGE = 1 << 16
