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

An integer array is stored in the narrowest integer type that holds its values (the per-bin
sample counts of 64 spp fit one byte, not four) and given back in its own type.

Stored names (in ``arrays.npz``): ``rows~mask`` (``np.packbits`` of the mask), ``rows~shape``
(the shape without the last axis), ``rows~<name>`` ((kept rows, channels) of ``<name>``, its
own dtype or a narrower integer one) and ``rows~dtype~<name>`` (the dtype ``<name>`` is given
back in, where it was narrowed); arrays not packed keep their own names.

:func:`save` writes that form into an ``.npz`` stream a chunk of rows at a time, so storing an
entry makes no second copy of it: on this project's virtual machines a fresh large NumPy array
is first touched at 0.11–0.36 GB/s (:mod:`dbench.memory`; docs/transient.md §6), so the packed
copy of a 56 MB entry, and NumPy's own copies of it in ``savez``, cost more than its render.
"""
from __future__ import annotations

import zipfile
from typing import BinaryIO, Iterator, Mapping, Sequence

import numpy as np

PREFIX = "rows~"
MASK = PREFIX + "mask"
SHAPE = PREFIX + "shape"
DTYPE = PREFIX + "dtype~"
#: rows a chunk of :meth:`Rows.chunks` holds (1.5 MB of float64 triples)
CHUNK_ROWS = 1 << 16


def _bits(a: np.ndarray) -> np.ndarray:
    """(rows, channels) unsigned integers with ``a``'s bit patterns (a view where possible)."""
    kinds = {1: np.uint8, 2: np.uint16, 4: np.uint32, 8: np.uint64}
    if a.dtype.itemsize not in kinds or a.dtype.kind not in "fiub":
        raise ValueError(f"sparse rows: cannot pack dtype {a.dtype}")
    flat = np.ascontiguousarray(a).reshape(-1, a.shape[-1])
    return flat.view(kinds[a.dtype.itemsize]) if a.dtype != bool else flat.view(np.uint8)


class Rows:
    """The kept rows of one array, not yet copied: ``(len(index), channels)`` of ``dtype``."""

    def __init__(self, array: np.ndarray, index: np.ndarray):
        a = np.ascontiguousarray(array)
        self.source = a.reshape(-1, a.shape[-1])
        self.index = index
        self.dtype = narrowest(a)
        self.shape = (index.size, self.source.shape[1])

    def chunks(self, rows: int | None = None) -> Iterator[np.ndarray]:
        """The rows in order, ``rows`` (default :data:`CHUNK_ROWS`) at a time, in one reused
        buffer (each valid until the next)."""
        rows = max(1, rows or CHUNK_ROWS)
        take = np.empty((min(rows, self.shape[0]), self.shape[1]), self.source.dtype)
        cast = take if self.dtype == self.source.dtype else np.empty(take.shape, self.dtype)
        for start in range(0, self.shape[0], rows):
            part = self.index[start:start + rows]
            np.take(self.source, part, axis=0, out=take[:part.size])
            if cast is not take:
                cast[:part.size] = take[:part.size]
            yield cast[:part.size]

    def array(self) -> np.ndarray:
        return self.source.take(self.index, axis=0).astype(self.dtype, copy=False)


def narrowest(a: np.ndarray) -> np.dtype:
    """The narrowest integer dtype holding every value of the integer array ``a`` (its own
    dtype if none is narrower, and for any other kind of array)."""
    if a.dtype.kind not in "iu" or a.size == 0:
        return a.dtype
    lo, hi = int(a.min()), int(a.max())
    for t in (np.uint8, np.int8, np.uint16, np.int16, np.uint32, np.int32):
        info = np.iinfo(t)
        if np.dtype(t).itemsize >= a.dtype.itemsize:
            break
        if info.min <= lo and hi <= info.max:
            return np.dtype(t)
    return a.dtype


def layout(arrays: Mapping[str, np.ndarray], names: Sequence[str]) -> dict:
    """What :func:`pack` stores, with each packed array's rows left as a :class:`Rows` (no
    copy yet): the form :func:`save` streams."""
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
        a = np.asarray(arrays[n])
        out[PREFIX + n] = rows = Rows(a, index)
        if rows.dtype != a.dtype:
            out[DTYPE + n] = np.asarray(a.dtype.str)
    return out


def pack(arrays: Mapping[str, np.ndarray], names: Sequence[str]) -> dict[str, np.ndarray]:
    """``arrays`` with those in ``names`` replaced by their non-zero rows and one mask.

    Args:
        arrays: name -> array; those in ``names`` share every axis but the last, e.g.
            (H, W, T, 3) colour and (H, W, T, 3) statistics; the others are stored as given.
        names: the arrays to pack (none: ``arrays`` is returned as a dict, unchanged).

    Returns:
        The arrays to store; :func:`unpack` gives back ``arrays`` bit for bit.
    """
    return {k: v.array() if isinstance(v, Rows) else v for k, v in layout(arrays, names).items()}


def save(fh: BinaryIO, arrays: Mapping[str, np.ndarray], names: Sequence[str] = (),
         compress: bool = False) -> None:
    """Write ``arrays`` (those in ``names`` packed, :func:`layout`) to ``fh`` as an ``.npz``
    archive that ``np.load`` reads (what ``np.savez`` / ``np.savez_compressed`` write), the
    packed rows a chunk at a time."""
    method = zipfile.ZIP_DEFLATED if compress else zipfile.ZIP_STORED
    with zipfile.ZipFile(fh, "w", compression=method, allowZip64=True) as zf:
        for name, value in layout(arrays, names).items():
            with zf.open(name + ".npy", "w", force_zip64=True) as member:
                if isinstance(value, Rows):
                    chunks, dtype, shape = value.chunks(), value.dtype, value.shape
                else:
                    a = np.asarray(value)  # (ascontiguousarray would make a 0-d array 1-d)
                    a = a if a.flags.c_contiguous else np.ascontiguousarray(a)
                    if a.dtype.hasobject:
                        raise ValueError(f"sparse rows: {name} is an object array")
                    # slices of the array itself, not NumPy's 16 MB copies of it
                    flat = a.reshape(-1).view(np.uint8)
                    step = CHUNK_ROWS * 24
                    chunks = (flat[i:i + step] for i in range(0, flat.size, step))
                    dtype, shape = a.dtype, a.shape
                np.lib.format.write_array_header_1_0(member, {
                    "descr": np.lib.format.dtype_to_descr(dtype), "fortran_order": False,
                    "shape": shape})
                for chunk in chunks:
                    member.write(chunk)


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
        if k in (MASK, SHAPE) or k.startswith(DTYPE):
            continue
        if not k.startswith(PREFIX):
            out[k] = v
            continue
        name = k[len(PREFIX):]
        if v.shape[0] != index.size:
            raise ValueError(f"sparse rows: {name} holds {v.shape[0]} rows, "
                             f"the mask {index.size}")
        dtype = np.dtype(np.asarray(stored[DTYPE + name]).item()) if DTYPE + name in stored else v.dtype
        full = np.zeros((n_rows, v.shape[1]), dtype)
        full[index] = v
        out[name] = full.reshape(rows_shape + (v.shape[1],))
    return out


__all__ = ["pack", "unpack", "save", "layout", "PREFIX"]
