"""The (pixel, bin) rows of collector (b)'s videos that the cache stores, found and gathered on
the device (docs/transient.md §6; :mod:`dbench.datasets.sparse_rows` stores them).

A row is kept when any value of any of an entry's arrays has a non-zero bit pattern (-0.0 and
NaN count). The moments' kernel (:meth:`.collector.StatsCollector.moments`) also writes one
flag per value from the values it holds in registers (:func:`value_flags`), and a small kernel
over the rows joins each row's three flags (:func:`row_masks`): no host pass over the 137 MB
of a 128² × 100-bin video, nor a second read of the values on the device (9.6 ms, against
about 2 for the flags; 2-core CPU, LLVM). :func:`kept` then gathers the kept rows in order,
in Dr.Jit's threads, where the cache's host gather took them a chunk at a time in one thread.
"""
from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from .voxel_sums import host_array


def value_flags(mean, var_mean, m3, non_zero, color):
    """Per (voxel, channel) (Bool, lazy): whether any of the statistics, and whether the
    colour (:func:`colour_flags`), holds a non-zero bit pattern."""
    bits = mi.UInt64(0)
    for a in (mean, var_mean, m3):
        bits |= dr.reinterpret_array(mi.UInt64, a)
    return (bits != 0) | (non_zero != 0), colour_flags(color)


def colour_flags(color):
    """Whether each float32 value of ``color`` has a non-zero bit pattern (Bool, lazy)."""
    return dr.reinterpret_array(mi.UInt32, color) != 0


def any_in_row(flag, channels: int = 3):
    """Whether any of the ``channels`` values of each row of ``flag`` (Bool per value,
    evaluated) is set (Bool per row, lazy)."""
    row = dr.arange(mi.UInt32, dr.width(flag) // channels) * channels
    found = dr.gather(mi.Bool, flag, row)
    for c in range(1, channels):
        found |= dr.gather(mi.Bool, flag, row + c)
    return found


def row_masks(*flags):
    """The evaluated row masks (:func:`any_in_row`) of the evaluated per-value ``flags``."""
    rows = tuple(any_in_row(f) for f in flags)
    dr.eval(*rows)
    return rows


def kept(mask, channels: int = 3, **arrays) -> dict[str, np.ndarray]:
    """{name: the rows ``mask`` (Bool per row, evaluated) keeps of the flat
    (rows · ``channels``) device array, in order, as a (kept rows, ``channels``) host array}:
    what the cache stores of it (:func:`dbench.datasets.sparse_rows.layout`'s ``kept``)."""
    index = dr.compress(mask)
    k = dr.width(index)
    if k == 0:
        return {n: host_array(a)[:0].reshape(0, channels) for n, a in arrays.items()}
    j = dr.arange(mi.UInt32, channels * k)
    source = dr.gather(mi.UInt32, index, j // channels) * channels + j % channels
    out = {n: dr.gather(type(a), a, source) for n, a in arrays.items()}
    dr.eval(*out.values())
    return {n: host_array(a).reshape(k, channels) for n, a in out.items()}
