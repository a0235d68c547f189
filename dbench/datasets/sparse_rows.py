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

Stored names (files of an entry's ``arrays/``, :mod:`.array_files`, or members of its
``arrays.npz``): ``rows~mask`` (``np.packbits`` of the mask), ``rows~shape``
(the shape without the last axis), ``rows~<name>`` ((kept rows, channels) of ``<name>``, its
own dtype or a narrower integer one) and ``rows~dtype~<name>`` (the dtype ``<name>`` is given
back in, where it was narrowed); arrays not packed keep their own names.

:func:`members` gives that form a chunk of rows at a time (:func:`save` writes it into an
``.npz`` stream, :mod:`.array_files` into files; :class:`Unpacker` reads it back the same way),
so storing an entry makes no second copy of it: on this project's virtual machines a fresh
large NumPy array is first touched at 0.11–0.36 GB/s (:mod:`dbench.memory`; docs/transient.md
§6), so the packed copy of a 56 MB entry, and NumPy's own copies of it in ``savez``, cost more
than its render.
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
#: bytes of a chunk of an array that is not packed, written or read a chunk at a time
CHUNK_BYTES = CHUNK_ROWS * 24


def _bits(a: np.ndarray) -> np.ndarray:
    """(rows, channels) unsigned integers with ``a``'s bit patterns (a view where possible)."""
    kinds = {1: np.uint8, 2: np.uint16, 4: np.uint32, 8: np.uint64}
    if a.dtype.itemsize not in kinds or a.dtype.kind not in "fiub":
        raise ValueError(f"sparse rows: cannot pack dtype {a.dtype}")
    flat = np.ascontiguousarray(a).reshape(-1, a.shape[-1])
    return flat.view(kinds[a.dtype.itemsize]) if a.dtype != bool else flat.view(np.uint8)


class Rows:
    """The kept rows of one array, not yet copied: ``(len(index), channels)`` of ``dtype``.
    ``kept``: those rows already gathered (in their own dtype), where the caller has them."""

    def __init__(self, array: np.ndarray, index: np.ndarray, kept: np.ndarray | None = None):
        a = np.ascontiguousarray(array)
        self.source = a.reshape(-1, a.shape[-1])
        self.index = index
        self.dtype = narrowest(a)
        self.shape = (index.size, self.source.shape[1])
        if kept is not None and (np.shape(kept) != self.shape or kept.dtype != a.dtype):
            raise ValueError(f"sparse rows: the kept rows must be {a.dtype} {self.shape}, got "
                             f"{np.asarray(kept).dtype} {np.shape(kept)}")
        self.kept = None if kept is None else np.ascontiguousarray(kept)

    def chunks(self, rows: int | None = None) -> Iterator[np.ndarray]:
        """The rows in order, ``rows`` (default :data:`CHUNK_ROWS`) at a time, in one reused
        buffer (each valid until the next)."""
        rows = max(1, rows or CHUNK_ROWS)
        shape = (min(rows, self.shape[0]), self.shape[1])
        take = np.empty(shape, self.source.dtype) if self.kept is None else None
        cast = None if self.dtype == self.source.dtype else np.empty(shape, self.dtype)
        for start in range(0, self.shape[0], rows):
            if take is None:  # gathered already: slices of them
                got = self.kept[start:start + rows]
            else:
                part = self.index[start:start + rows]
                got = take[:part.size]
                np.take(self.source, part, axis=0, out=got)
            if cast is not None:
                cast[:len(got)] = got
                got = cast[:len(got)]
            yield got

    def array(self) -> np.ndarray:
        rows = self.source.take(self.index, axis=0) if self.kept is None else self.kept
        return rows.astype(self.dtype, copy=False)


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


def layout(arrays: Mapping[str, np.ndarray], names: Sequence[str],
           keep: np.ndarray | None = None,
           kept: Mapping[str, np.ndarray] | None = None) -> dict:
    """What :func:`pack` stores, with each packed array's rows left as a :class:`Rows` (no
    copy yet): the form :func:`save` streams. ``keep``: the rows to keep (bool, the shape of
    the arrays but the last axis) where the caller already knows them, e.g. the transient
    collector, which finds them on the device; every row it leaves out must be zero, or its
    values are lost. None: the rows where any of the arrays has a non-zero bit pattern.
    ``kept``: {name: (kept rows, channels)}, the rows ``keep`` keeps of some of the arrays,
    already gathered in order (the transient collector gathers them on the device, in two
    threads, faster than a host gather of them; needs ``keep``)."""
    names = [n for n in names if n in arrays]
    if kept and (keep is None or set(kept) - set(names)):
        raise ValueError(f"sparse rows: gathered rows {sorted(kept)} need the rows kept and "
                         f"packed arrays of those names ({sorted(names)})")
    if not names:
        return dict(arrays)
    shapes = {n: np.shape(arrays[n]) for n in names}
    rows_shape = shapes[names[0]][:-1]
    if any(len(s) < 2 or s[:-1] != rows_shape for s in shapes.values()):
        raise ValueError(f"sparse rows: arrays must share every axis but the last, got {shapes}")
    if keep is not None:
        if np.shape(keep) != rows_shape or np.asarray(keep).dtype != bool:
            raise ValueError(f"sparse rows: the rows to keep must be bool {rows_shape}, got "
                             f"{np.asarray(keep).dtype} {np.shape(keep)}")
        keep = np.asarray(keep).reshape(-1)
    else:
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
        out[PREFIX + n] = rows = Rows(a, index, (kept or {}).get(n))
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


def members(arrays: Mapping[str, np.ndarray], names: Sequence[str] = (),
            keep: np.ndarray | None = None, kept: Mapping[str, np.ndarray] | None = None
            ) -> Iterator[tuple[str, np.dtype, tuple, Iterator]]:
    """(stored name, dtype, shape, chunks of its bytes in C order) of each array an entry
    stores (:func:`layout`): packed rows a chunk at a time, other arrays as slices of
    themselves, not NumPy's 16 MB copies of them. Each chunk is valid until the next.
    ``keep``, ``kept``: as for :func:`layout`."""
    for name, value in layout(arrays, names, keep, kept).items():
        if isinstance(value, Rows):
            yield name, value.dtype, value.shape, value.chunks()
            continue
        a = np.asarray(value)  # (ascontiguousarray would make a 0-d array 1-d)
        a = a if a.flags.c_contiguous else np.ascontiguousarray(a)
        if a.dtype.hasobject:
            raise ValueError(f"sparse rows: {name} is an object array")
        flat = a.reshape(-1).view(np.uint8)
        yield name, a.dtype, a.shape, (flat[i:i + CHUNK_BYTES]
                                       for i in range(0, flat.size, CHUNK_BYTES))


def write_npy(fh: BinaryIO, dtype: np.dtype, shape: tuple, chunks: Iterator) -> None:
    """One ``.npy`` (format 1.0) of ``dtype`` and ``shape`` whose body is ``chunks``."""
    np.lib.format.write_array_header_1_0(fh, {
        "descr": np.lib.format.dtype_to_descr(dtype), "fortran_order": False, "shape": shape})
    for chunk in chunks:
        fh.write(chunk)


def save(fh: BinaryIO, arrays: Mapping[str, np.ndarray], names: Sequence[str] = (),
         compress: bool = False, keep: np.ndarray | None = None,
         kept: Mapping[str, np.ndarray] | None = None) -> None:
    """Write ``arrays`` (those in ``names`` packed, :func:`layout` with ``keep`` and ``kept``)
    to ``fh`` as an ``.npz`` archive that ``np.load`` reads (what ``np.savez`` /
    ``np.savez_compressed`` write), the packed rows a chunk at a time."""
    method = zipfile.ZIP_DEFLATED if compress else zipfile.ZIP_STORED
    with zipfile.ZipFile(fh, "w", compression=method, allowZip64=True) as zf:
        for name, dtype, shape, chunks in members(arrays, names, keep, kept):
            with zf.open(name + ".npy", "w", force_zip64=True) as member:
                write_npy(member, dtype, shape, chunks)


def is_rows(stored_name: str) -> bool:
    """Whether ``stored_name`` holds an array's kept rows (not the mask, shape or a dtype)."""
    return stored_name.startswith(PREFIX) and stored_name not in (MASK, SHAPE) and \
        not stored_name.startswith(DTYPE)


class Unpacker:
    """The arrays :func:`pack` was given, filled in from what it stored a chunk of rows at a
    time, so a reader can put each chunk it reads in its place without first assembling the
    packed array (:mod:`dbench.datasets.array_files`).

    ``small``: every stored array but the kept rows (:func:`is_rows`); the mask and shape
    among them, where anything was packed."""

    def __init__(self, small: Mapping[str, np.ndarray]):
        self.out = {k: v for k, v in small.items() if not k.startswith(PREFIX)}
        self._small = small
        self.index = None
        if MASK in small:
            self.rows_shape = tuple(int(s) for s in small[SHAPE])
            self.n_rows = int(np.prod(self.rows_shape))
            self.index = np.flatnonzero(np.unpackbits(small[MASK], count=self.n_rows))

    def target(self, stored_name: str, shape: tuple, dtype: np.dtype) -> np.ndarray:
        """The zeroed (all rows, channels) array that the kept rows ``stored_name`` (stored
        as ``shape``, ``dtype``) unpack into; ValueError when they do not fit the mask."""
        name = stored_name[len(PREFIX):]
        if self.index is None:
            raise ValueError(f"sparse rows: {name} is packed, but no mask was stored")
        if len(shape) != 2 or shape[0] != self.index.size:
            raise ValueError(f"sparse rows: {name} holds {shape[0] if shape else 0} rows, "
                             f"the mask {self.index.size}")
        given = self._small.get(DTYPE + name)
        full = np.zeros((self.n_rows, shape[1]),
                        np.dtype(np.asarray(given).item()) if given is not None else dtype)
        self.out[name] = full.reshape(self.rows_shape + (shape[1],))
        return full

    def fill(self, full: np.ndarray, start: int, rows: np.ndarray) -> None:
        """Put the kept rows ``start``.. (``rows``, (k, channels)) into ``full``
        (:meth:`target`)."""
        where = self.index[start:start + rows.shape[0]]
        if full.shape[1] == 0:
            return
        # each row as one opaque item: 20 % faster than NumPy's (k, channels) fancy assignment
        # (a narrowed integer chunk is cast first, a copy of one chunk)
        rows = np.ascontiguousarray(rows, dtype=full.dtype)
        item = np.dtype((np.void, full.dtype.itemsize * full.shape[1]))
        np.put(full.view(item).reshape(-1), where, rows.view(item))


def unpack(stored: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The arrays :func:`pack` was given, from what it returned (unpacked arrays pass as they
    are, so entries written without packing read the same way)."""
    if MASK not in stored:
        return dict(stored)
    un = Unpacker({k: v for k, v in stored.items() if not is_rows(k)})
    for k, v in stored.items():
        if is_rows(k):
            un.fill(un.target(k, v.shape, v.dtype), 0, v)
    return un.out


__all__ = ["pack", "unpack", "save", "layout", "members", "write_npy", "is_rows", "Unpacker",
           "PREFIX"]
