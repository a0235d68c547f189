"""Arrays stored by their non-zero rows: the cache's form of mostly empty transient videos.

A transient video's streak film is mostly empty: a path adds to at most ``2·max_depth`` of a
pixel's time bins, so at 128² × 100 bins 54 % of the Cornell box's (pixel, bin) rows are zero,
and at 48² × 1000 bins 90 %. Its colour, reference and per-bin statistics are stored in the
cache (:mod:`dbench.datasets.cache`) as the rows where any of them is non-zero, with a bit mask
of those rows (README.md, "How renders work"; docs/transient.md §6).

A *row* is every value of an array's last axis (the channels) at one index of the others; the
arrays packed together share every axis but the last, and one mask serves them all. A row is
kept when any value of any of the arrays has a non-zero bit pattern, so ``-0.0``, NaN payloads,
infinities and subnormals come back bit for bit: :func:`unpack` of :func:`pack` is exactly the
input (tests/datasets/test_sparse_rows.py).

Stored names (in ``arrays.npz``): ``rows~mask`` (``np.packbits`` of the mask), ``rows~shape``
(the shape without the last axis) and ``rows~<name>`` ((kept rows, channels) of ``<name>``,
its own dtype); arrays not packed keep their own names.
"""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

PREFIX = "rows~"
MASK = PREFIX + "mask"
SHAPE = PREFIX + "shape"


def _bits(a: np.ndarray) -> np.ndarray:
    """(rows, channels) unsigned integers with ``a``'s bit patterns (a view where possible)."""
    kinds = {1: np.uint8, 2: np.uint16, 4: np.uint32, 8: np.uint64}
    if a.dtype.itemsize not in kinds or a.dtype.kind not in "fiub":
        raise ValueError(f"sparse rows: cannot pack dtype {a.dtype}")
    flat = np.ascontiguousarray(a).reshape(-1, a.shape[-1])
    return flat.view(kinds[a.dtype.itemsize]) if a.dtype != bool else flat.view(np.uint8)


def pack(arrays: Mapping[str, np.ndarray], names: Sequence[str]) -> dict[str, np.ndarray]:
    """``arrays`` with those in ``names`` replaced by their non-zero rows and one mask.

    Args:
        arrays: name -> array; those in ``names`` share every axis but the last, e.g.
            (H, W, T, 3) colour and (H, W, T, 3) statistics; the others are stored as given.
        names: the arrays to pack (none: ``arrays`` is returned as a dict, unchanged).

    Returns:
        The arrays to store; :func:`unpack` gives back ``arrays`` bit for bit.
    """
    names = [n for n in names if n in arrays]
    if not names:
        return dict(arrays)
    shapes = {n: np.shape(arrays[n]) for n in names}
    rows_shape = shapes[names[0]][:-1]
    if any(len(s) < 2 or s[:-1] != rows_shape for s in shapes.values()):
        raise ValueError(f"sparse rows: arrays must share every axis but the last, got {shapes}")
    keep = np.zeros(int(np.prod(rows_shape)), bool)
    for n in names:
        bits = _bits(np.asarray(arrays[n]))
        # column by column: NumPy's reduce along a short last axis is 5× slower than this
        for j in range(bits.shape[1]):
            keep |= bits[:, j] != 0
    index = np.flatnonzero(keep)
    out = {k: v for k, v in arrays.items() if k not in names}
    out[MASK] = np.packbits(keep)
    out[SHAPE] = np.asarray(rows_shape, np.int64)
    for n in names:
        a = np.ascontiguousarray(arrays[n])
        out[PREFIX + n] = a.reshape(-1, a.shape[-1]).take(index, axis=0)
    return out


def unpack(stored: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The arrays :func:`pack` was given, from what it returned (unpacked arrays pass as they
    are, so entries written without packing read the same way)."""
    if MASK not in stored:
        return dict(stored)
    rows_shape = tuple(int(s) for s in stored[SHAPE])
    n_rows = int(np.prod(rows_shape))
    index = np.flatnonzero(np.unpackbits(stored[MASK], count=n_rows))
    out = {}
    for k, v in stored.items():
        if k in (MASK, SHAPE):
            continue
        if not k.startswith(PREFIX):
            out[k] = v
            continue
        if v.shape[0] != index.size:
            raise ValueError(f"sparse rows: {k[len(PREFIX):]} holds {v.shape[0]} rows, "
                             f"the mask {index.size}")
        full = np.zeros((n_rows, v.shape[1]), v.dtype)
        full[index] = v
        out[k[len(PREFIX):]] = full.reshape(rows_shape + (v.shape[1],))
    return out


__all__ = ["pack", "unpack", "PREFIX"]
