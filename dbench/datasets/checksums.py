"""Checksums of a cache entry's files: what ``meta.json`` records of each, taken in the same
pass that writes or reads the file.

A file's record is ``{"size": bytes, "xxh3_128": hex digest}`` in entries of format 5 and
later (:mod:`dbench.datasets.cache`), and ``{"size", "sha256"}`` in earlier ones, which are
still checked with sha256 (:func:`algorithm`).

Why xxh3-128 and not sha256: the checksum guards against damage (a truncated, half-written,
swapped or edited file), not against an adversary; whoever can write an entry's files can
write its ``meta.json`` too, so a cryptographic hash buys nothing here. A 128-bit xxh3 finds
such damage as surely and runs at about 20 GB/s against sha256's 1.8 GB/s on this project's
machines: 2.8 ms against 31 ms for the 56 MB statistics entry of a 128² × 100-bin transient
video (docs/transient.md §6). So it is taken inline, in the thread that writes or reads each
chunk, where sha256 needed a second thread, a copy of every chunk it was handed and still
added about 10 ms to storing that entry.
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import Any

#: The checksum of every file an entry written now records.
ALGORITHM = "xxh3_128"
#: The checksum entries before format 5 record.
LEGACY = "sha256"
#: The first entry format whose files carry :data:`ALGORITHM`.
FIRST_FORMAT = 5


def algorithm(meta: dict) -> str:
    """The checksum the entry with ``meta.json`` ``meta`` records of its files."""
    fmt = meta.get("cache_format")
    return ALGORITHM if isinstance(fmt, int) and fmt >= FIRST_FORMAT else LEGACY


class Digest:
    """The checksum of chunks handed over in order (any object with the buffer protocol; a
    NumPy array counts by its bytes, not its length)."""

    def __init__(self, name: str = ALGORITHM):
        if name not in (ALGORITHM, LEGACY):
            raise ValueError(f"checksum: expected {ALGORITHM} or {LEGACY}, got {name!r}")
        self.name = name
        self.size = 0
        if name == ALGORITHM:
            import xxhash  # (here: code that never touches a cache runs without it)

            self._hash = xxhash.xxh3_128()
        else:
            self._hash = hashlib.sha256()

    def update(self, chunk) -> None:
        view = memoryview(chunk)
        self._hash.update(view if view.c_contiguous else view.tobytes())
        self.size += view.nbytes

    def record(self) -> dict[str, Any]:
        """{"size", name: hex digest} of everything handed over."""
        return {"size": self.size, self.name: self._hash.hexdigest()}


class NoDigest:
    """A digest that takes none, for reading files this process has just written."""

    def update(self, chunk) -> None:
        pass

    def record(self) -> None:
        return None


def file_record(path: Path, name: str = ALGORITHM, chunk: int = 8 << 20) -> dict[str, Any]:
    """{"size", name: hex digest} of the file at ``path``, read ``chunk`` bytes at a time
    into one buffer (no larger than the file: a fresh 8 MB buffer cost more than hashing a
    1.5 MB file)."""
    digest = Digest(name)
    with open(path, "rb") as fh:
        buf = bytearray(max(1, min(chunk, os.fstat(fh.fileno()).st_size)))
        view = memoryview(buf)
        while n := fh.readinto(buf):
            digest.update(view[:n])
    return digest.record()


class DigestingWriter:
    """A write-only stream over ``fh`` that takes the checksum of what passes through, so a new
    entry's record needs no second read of its file. It has no ``tell``: zipfile then writes a
    streamed archive (sizes after each member), which ``np.load`` reads as any other; ``read``
    only raises (NumPy tells a stream from a path by it)."""

    def __init__(self, fh, name: str = ALGORITHM):
        self._fh = fh
        self._digest = Digest(name)

    def write(self, data) -> int:
        written = self._fh.write(data)
        self._digest.update(data)
        return written

    def read(self, *args):
        raise OSError("write-only stream")

    def flush(self) -> None:
        self._fh.flush()

    def record(self) -> dict[str, Any]:
        """{"size", checksum} of everything written (as :func:`file_record` of the file)."""
        return self._digest.record()


__all__ = ["ALGORITHM", "LEGACY", "FIRST_FORMAT", "algorithm", "Digest", "NoDigest",
           "DigestingWriter", "file_record"]
