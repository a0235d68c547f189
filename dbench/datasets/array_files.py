"""A cache entry's arrays as a folder of ``.npy`` files, written and read a chunk at a time.

This is how :mod:`dbench.datasets.cache` stores uncompressed arrays (entry formats 4 and 5): the
float64 per-bin statistics and colour of transient videos, packed by their non-zero rows
(:mod:`.sparse_rows`). Each array is one ``arrays/<stored name>.npy`` (format 1.0) that
``np.load`` reads as any other.

Why not one ``arrays.npz``, as before: a zip member carries a CRC-32, which ``zipfile``
computes over every byte written and again over every byte read, 13 ms each way for the 56 MB
statistics entry of a 128² × 100-bin video on this project's machines. The entry's checksums
(``meta.json``, :mod:`.checksums`) already check those bytes, so the CRC was a second checksum
of the same bytes.

Reading is one pass over each file: every chunk read goes to the checksum and straight to its
place in the unpacked array (:class:`.sparse_rows.Unpacker`), where the zip form took a
checksum pass over the file, a read into packed arrays and an unpacking copy
(docs/transient.md §6).
"""
from __future__ import annotations

import io as _io
from functools import partial
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np

from . import sparse_rows

#: The folder of an entry that holds its arrays.
FOLDER = "arrays"
SUFFIX = ".npy"
_MAGIC = b"\x93NUMPY\x01\x00"


def write(folder: Path, arrays: Mapping[str, np.ndarray], names: Sequence[str],
          wrap: Callable[[Any], Any], keep: np.ndarray | None = None,
          kept: Mapping[str, np.ndarray] | None = None) -> dict[str, Any]:
    """Write ``arrays`` (those in ``names`` packed, :func:`.sparse_rows.layout` with ``keep``
    and ``kept``) into the new folder ``folder``, one file each, through ``wrap(file)`` (a
    writer with ``write`` and ``record``, e.g. the cache's checksum); return {file name: its
    writer's ``record()``}."""
    bad = [n for n in arrays if not n or n != Path(n).name or n.startswith(".")]
    if bad:  # each array is a file of the folder
        raise ValueError(f"{FOLDER}/: array names must be plain file names, got {bad}")
    folder.mkdir()
    records = {}
    for name, dtype, shape, chunks in sparse_rows.members(arrays, names, keep, kept):
        with open(folder / (name + SUFFIX), "wb") as fh:
            writer = wrap(fh)
            sparse_rows.write_npy(writer, dtype, shape, chunks)
        records[name + SUFFIX] = writer.record()
    return records


def _header(fh, digest) -> tuple[tuple, np.dtype]:
    """(shape, dtype) of the ``.npy`` open in ``fh``, its header read and handed to
    ``digest``; ValueError for anything this module does not write."""
    head = fh.read(len(_MAGIC) + 2)
    if len(head) < len(_MAGIC) + 2 or head[:len(_MAGIC)] != _MAGIC:
        raise ValueError("not a .npy of format 1.0")
    text = fh.read(int.from_bytes(head[-2:], "little"))
    digest.update(head)
    digest.update(text)
    shape, fortran, dtype = np.lib.format.read_array_header_1_0(_io.BytesIO(head[-2:] + text))
    if fortran or dtype.hasobject:
        raise ValueError("not an array this cache writes")
    return shape, dtype


def read(folder: Path, files: Iterable[str], digest: Callable[[], Any]
         ) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """The arrays :func:`write` was given, from the files ``files`` of ``folder``, and
    {file: ``record()`` of the ``digest()`` object (``update``, ``record``) that saw its
    bytes}. ValueError (naming the file) when a file is not one :func:`write` writes or its
    rows do not fit the stored mask; OSError when it cannot be read."""
    files = list(files)
    stored = {f[:-len(SUFFIX)]: f for f in files if f.endswith(SUFFIX)}
    if len(stored) != len(files):
        raise ValueError(f"{FOLDER}/: unexpected file in {sorted(files)}")
    records: dict[str, Any] = {}
    small = {name: _read(folder / f, digest, records, _plain)  # the packed rows need the mask
             for name, f in stored.items() if not sparse_rows.is_rows(name)}
    unpacker = sparse_rows.Unpacker(small)
    for name, f in stored.items():
        if sparse_rows.is_rows(name):
            _read(folder / f, digest, records, partial(_rows, unpacker=unpacker, name=name))
    return unpacker.out, records


def _read(path: Path, digest: Callable[[], Any], records: dict, body: Callable):
    """``body(file, shape, dtype, digest)`` of the ``.npy`` at ``path`` after its header, the
    file's bytes handed to a new ``digest()``, whose ``record()`` goes into ``records``;
    a ValueError names the file."""
    d = digest()
    try:
        with open(path, "rb") as fh:
            return body(fh, *_header(fh, d), d)
    except ValueError as exc:
        raise ValueError(f"{FOLDER}/{path.name}: {exc}") from None
    finally:
        records[path.name] = d.record()


def _plain(fh, shape: tuple, dtype: np.dtype, digest) -> np.ndarray:
    """The array of that shape and dtype read from ``fh`` a chunk at a time, each chunk handed
    to ``digest`` (the chunks are the array's own memory, which nothing writes again)."""
    out = np.empty(shape, dtype)
    view = memoryview(out.reshape(-1).view(np.uint8))
    for start in range(0, len(view), sparse_rows.CHUNK_BYTES):
        part = view[start:start + sparse_rows.CHUNK_BYTES]
        if fh.readinto(part) != len(part):
            raise ValueError("shorter than its header says")
        digest.update(part)
    return out


def _rows(fh, shape: tuple, dtype: np.dtype, digest, unpacker: sparse_rows.Unpacker,
          name: str) -> None:
    """The kept rows ``name`` read from ``fh`` into their unpacked array, a chunk of
    :data:`.sparse_rows.CHUNK_ROWS` rows at a time."""
    full = unpacker.target(name, shape, dtype)
    if not shape[0] or not dtype.itemsize * shape[1]:
        return
    # one buffer for every chunk: the digest is done with a chunk when update() returns
    buf = np.empty((min(sparse_rows.CHUNK_ROWS, shape[0]), shape[1]), dtype)
    for start in range(0, shape[0], sparse_rows.CHUNK_ROWS):
        part = buf[:min(sparse_rows.CHUNK_ROWS, shape[0] - start)]
        if fh.readinto(part.reshape(-1).view(np.uint8)) != part.nbytes:
            raise ValueError("shorter than its header says")
        digest.update(part)
        unpacker.fill(full, start, part)


__all__ = ["FOLDER", "read", "write"]
