"""A float32 ``exp`` that LLVM vectorises inside Numba loops (Cephes ``expf``, ≈ 1 ulp), exactly 0
for arguments ≤ −87, the cut-off the label planes rely on (:data:`.params.EXP_CUTOFF`).

Kept instead of Numba's SVML-backed vector ``exp``: the pinned llvmlite wheel is built without
SVML (``llvmlite.binding.config.has_svml`` is False), so Intel's runtime packages would not switch
it on, and SVML's ``expf`` differs in the last ulps and is not exactly 0 below −87."""
from __future__ import annotations

import llvmlite.ir as llvm_ir
import numpy as np
from numba import njit
from numba.core import types as nb_types
from numba.extending import intrinsic

from .params import EXP_CUTOFF


@intrinsic
def _bits_to_float32(typingctx, bits):
    """Reinterpret an int32 as float32 (vectorisable, unlike ldexp)."""
    sig = nb_types.float32(nb_types.int32)

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], llvm_ir.FloatType())

    return sig, codegen


F0 = np.float32(0.0)
F1 = np.float32(1.0)
_F_HALF = np.float32(0.5)
F_CUT = np.float32(EXP_CUTOFF)
_F_HI = np.float32(88.0)
_F_LOG2E = np.float32(1.44269504088896341)
_F_C1 = np.float32(0.693359375)
_F_C2 = np.float32(-2.12194440e-4)
_P0 = np.float32(1.9875691500e-4)
_P1 = np.float32(1.3981999507e-3)
_P2 = np.float32(8.3334519073e-3)
_P3 = np.float32(4.1665795894e-2)
_P4 = np.float32(1.6666665459e-1)
_P5 = np.float32(5.0000001201e-1)


@njit(inline="always", cache=True)
def exp32(x):
    """float32 exp(x) (Cephes expf, ≈ 1 ulp), exactly 0 for x ≤ −87.

    Written out so that LLVM vectorises it: Numba has no vector exp without Intel SVML.
    """
    xc = min(max(x, -F_CUT), _F_HI)
    fx = np.floor(xc * _F_LOG2E + _F_HALF)
    r = xc - fx * _F_C1 - fx * _F_C2
    p = _P0
    p = p * r + _P1
    p = p * r + _P2
    p = p * r + _P3
    p = p * r + _P4
    p = p * r + _P5
    p = p * r * r + r + F1
    scale = _bits_to_float32((np.int32(fx) + np.int32(127)) << np.int32(23))
    return p * scale if x > -F_CUT else F0
