"""Collector (b) on the device: the state its moments read (VoxelSums.gather), and the rows
the cache stores (docs/transient.md §6): the per-value flags it takes in the moments' own
kernel and reduces per (pixel, bin) row keep exactly the rows a host scan of the bit patterns
keeps (datasets/sparse_rows.py), -0.0, NaN and subnormals in any one channel included."""
from __future__ import annotations

import numpy as np


def test_device_rows_equal_the_host_scan_of_the_bits(tr):
    import drjit as dr
    from dbench.datasets import sparse_rows
    from dbench.datasets.mitsuba_env import mitsuba
    from dbench.datasets.transient import stored_rows

    mi = mitsuba()
    shape = (2, 3, 5, 3)
    mean, var_mean, m3 = (np.zeros(shape) for _ in range(3))
    non_zero, color = np.zeros(shape, np.int32), np.zeros(shape, np.float32)
    mean[0, 0, 0, 2] = -0.0           # the last channel only, a zero that is not +0.0
    var_mean[0, 1, 3, 1] = 5e-324     # a subnormal
    m3[1, 0, 4, 0] = np.nan
    non_zero[1, 2, 2, 1] = 1          # a count alone
    mean[1, 1, 1] = (0.5, 0.25, 0.0)  # an ordinary row
    color[0, 2, 4, 2] = -0.0
    color[1, 1, 1] = (0.5, 0.25, 0.0)
    F = mi.Float64
    device = {"mean": F(mean.ravel()), "var_mean": F(var_mean.ravel()), "m3": F(m3.ravel()),
              "non_zero": mi.Int32(non_zero.ravel()), "color": mi.Float32(color.ravel())}
    flags = stored_rows.value_flags(*device.values())
    dr.eval(*flags)
    stat, colour = stored_rows.row_masks(*flags)
    for found, arrays in ((stat, {"mean": mean, "var_mean": var_mean, "m3": m3,
                                  "non_zero": non_zero}), (colour, {"color": color})):
        packed = sparse_rows.pack(arrays, list(arrays))
        host = np.unpackbits(packed[sparse_rows.MASK], count=30).astype(bool)
        assert np.array_equal(np.array(found, dtype=bool), host)
        assert 0 < host.sum() < 30
        # the kept rows gathered on the device are the host's, bit for bit, in their own dtype
        kept = stored_rows.kept(found, **{n: device[n] for n in arrays})
        for n, a in arrays.items():
            rows = a.reshape(-1, 3)[host]
            assert kept[n].dtype == a.dtype and kept[n].tobytes() == rows.tobytes(), n
    nothing = stored_rows.kept(mi.Bool(np.zeros(30, bool)), color=device["color"])
    assert nothing["color"].shape == (0, 3) and nothing["color"].dtype == np.float32


def test_state_gather_gives_each_entrys_sums_and_count(tr):
    """VoxelSums.gather (the moments' input) reads S1, S2, S3 and the count of each entry from
    the layout add() writes: one packet per entry, as host() sees it."""
    import drjit as dr
    from dbench.datasets.mitsuba_env import mitsuba
    from dbench.datasets.transient.voxel_sums import VoxelSums

    mi = mitsuba()
    state = VoxelSums(6)
    assert state.packets
    state.sums = mi.Float64(np.arange(24.0) * 1.5)
    idx = [5, 0, 3, 3]
    got = state.gather(mi.UInt32(idx))
    dr.eval(*got)
    flat, counts = state.host()
    for k in range(3):
        assert np.array_equal(np.array(got[k]), flat[idx, k])
    assert np.array(got[3]).dtype == np.int32 and np.array_equal(np.array(got[3]), counts[idx])
