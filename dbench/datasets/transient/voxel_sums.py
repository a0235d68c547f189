"""The per-voxel statistics state of collector (b): power sums S1, S2, S3 and the ``non_zero``
counts per (voxel, channel) (docs/methods/statistical.md §11.1-11.2).

``n`` entries = H·W·T·3 (voxel, channel), in one of two layouts, chosen once per render state:

* **packets** (LLVM, when 32 B · n · worker threads fit :data:`EXPAND_BYTES`): (S1, S2, S3, N)
  as four neighbouring float64 per entry, 32 B. A flush is one four-wide scatter per channel,
  which Dr.Jit's ``ReduceMode.Expand`` turns into a packet write into the thread's own copy of
  the array, without atomics; the copies are summed when the render ends (cornell-transient,
  64², 64 spp: the collector's render from 1.5× to 1.2-1.3× a plain one).
* **compact** (everywhere else: CUDA, and states too large to copy per thread): S1, S2, S3
  interleaved (24 B) and one uint64 per voxel packing its three counts in 21 bits each (8/3 B),
  added with atomics; at most :data:`MAX_SAMPLES` samples per pixel.

With 1-spp passes a voxel gets at most one flush per pass, so both layouts give bit-identical
sums; in one call of many spp only the order of the float64 additions differs
(tests/datasets/test_transient.py).
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

#: largest packet state × worker threads that scatters in Dr.Jit's Expand mode (LLVM)
EXPAND_BYTES = 1 << 30
#: bits per channel of the compact layout's packed counts (a voxel counts 2²¹ − 1 samples)
NZ_BITS = 21
MAX_SAMPLES = (1 << NZ_BITS) - 1


class VoxelSums:
    """The state for ``n`` (voxel, channel) entries (a multiple of 3), zero-filled."""

    def __init__(self, n: int):
        self.n = int(n)
        threads = max(dr.thread_count(), 1)
        self.packets = (mi.variant().startswith("llvm")
                        and 32 * self.n * threads <= EXPAND_BYTES)
        self.stride = 4 if self.packets else 3
        self.sums = dr.zeros(mi.Float64, self.stride * self.n)
        self.nz = None if self.packets else dr.zeros(mi.UInt64, self.n // 3)

    @property
    def layout(self) -> str:
        """"packets" or "compact" (the module docstring), as reports name it."""
        return "packets" if self.packets else "compact"

    @property
    def max_samples(self) -> int | None:
        """The most samples per pixel the counts hold (None: exact in float64 up to 2⁵³)."""
        return None if self.packets else MAX_SAMPLES

    def arrays(self) -> list:
        """The device arrays (to evaluate, to measure)."""
        return [self.sums] if self.nz is None else [self.sums, self.nz]

    def add(self, voxel, us, nonzero, active) -> None:
        """Flush one value per lane and channel: ``us`` (3 Float64, u = g(x) − g(0)) and
        ``nonzero`` (3 Bool, x ≠ 0) into voxel ``voxel`` (UInt32) where ``active``."""
        if self.packets:
            for c in range(3):
                u, u2 = us[c], us[c] * us[c]
                packet = dr.llvm.ad.Array4f64(u, u2, u2 * u, dr.select(nonzero[c], 1.0, 0.0))
                # flattened C-style: entries 4·(3·voxel + c) + (0, 1, 2, 3)
                dr.scatter_reduce(dr.ReduceOp.Add, self.sums, packet, voxel * 3 + c, active,
                                  mode=dr.ReduceMode.Expand)
            return
        nz = mi.UInt64(0)
        for c in range(3):
            u, u2 = us[c], us[c] * us[c]
            j = (voxel * 3 + c) * 3
            dr.scatter_reduce(dr.ReduceOp.Add, self.sums, u, j, active)
            dr.scatter_reduce(dr.ReduceOp.Add, self.sums, u2, j + 1, active)
            dr.scatter_reduce(dr.ReduceOp.Add, self.sums, u2 * u, j + 2, active)
            nz |= dr.select(nonzero[c], mi.UInt64(1) << NZ_BITS * c, mi.UInt64(0))
        dr.scatter_reduce(dr.ReduceOp.Add, self.nz, nz, voxel, active & (nz != 0))

    def gather(self, idx):
        """Device (S1, S2, S3 (Float64), non_zero (Int32)) of the entries ``idx`` (UInt32)."""
        F, st = type(self.sums), self.stride
        if self.packets:
            # one packet gather of the entry's four neighbouring float64 (the layout add()
            # writes): the moments' kernel from 19.5 to about 8 ms at 128² × 100 bins (2-core
            # CPU), where four strided gathers loaded the same cache line four times
            s1, s2, s3, nz = dr.gather(dr.llvm.ad.Array4f64, self.sums, idx)
            return s1, s2, s3, mi.Int32(nz)
        s1, s2, s3 = (dr.gather(F, self.sums, st * idx + k) for k in range(3))
        packed = dr.gather(type(self.nz), self.nz, idx // 3)
        shift = mi.UInt64(idx % 3) * NZ_BITS
        return s1, s2, s3, mi.Int32((packed >> shift) & MAX_SAMPLES)

    def host(self, counts: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """((n, stride) float64 with S1, S2, S3 in its first columns, (n,) int32 counts or None
        when ``counts`` is False); on LLVM the sums are a zero-copy view."""
        sums = host_array(self.sums).reshape(-1, self.stride)
        if not counts:
            return sums, None
        if self.packets:
            return sums, sums[:, 3].astype(np.int32)
        packed = host_array(self.nz)
        mask = np.uint64(MAX_SAMPLES)
        nz = np.stack([((packed >> np.uint64(NZ_BITS * c)) & mask).astype(np.int32)
                       for c in range(3)], axis=-1)
        return sums, nz.reshape(-1)


def host_array(array) -> np.ndarray:
    """A NumPy view of an LLVM (host memory) Dr.Jit array; a copy on other backends."""
    return np.asarray(array) if mi.variant().startswith("llvm") else np.array(array)


def dr_nbytes(array) -> int:
    """Bytes of a flat Dr.Jit array."""
    item = 8 if "64" in type(array).__name__ else 4
    return int(dr.width(array) * item)
