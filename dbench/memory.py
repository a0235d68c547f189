"""How dbench asks for memory where it reads much of it at once: 4 kB pages for cache entries.

Since 1.20 NumPy advises the kernel to back every large array with 2 MB pages
(``madvise(MADV_HUGEPAGE)``). On this project's virtual machines, once a process has touched a
few hundred MB, each new 2 MB page is backed at 0.11–0.28 GB/s against about 2 GB/s for 4 kB
pages (64 MB arrays of zeros, first touch). Reading a cache entry writes fresh arrays: the
first read of a 128² × 100-bin transient entry (colour and statistics, 157 MB unpacked) in a
process took 1.5–2.0 s with 2 MB pages against 0.21–0.28 s with 4 kB pages, where rendering it
again takes 0.4 s (README.md, "How renders work").

:func:`small_pages` turns NumPy's advice off for such a block: reading cache entries
(:mod:`dbench.datasets.cache`). Elsewhere NumPy's own advice stands: methods, the frames they
are given and their timing are measured as in a user's process, and scoring (the judge) was
faster with 2 MB pages once a process had some to reuse (0.18–0.23 s against 0.44 s a call at
128² × 100 bins, after a first call of 2.2–2.5 s against 0.73 s). Where
``NUMPY_MADVISE_HUGEPAGE`` is set, the user has decided and nothing is changed.
"""
from __future__ import annotations

import os
from contextlib import contextmanager
from typing import Iterator


def _setter():
    """NumPy's switch of its huge-page advice (it returns the previous state), or None."""
    try:
        from numpy._core import multiarray
    except ImportError:  # another NumPy: its own advice stands
        return None
    return getattr(multiarray, "_set_madvise_hugepage", None)


@contextmanager
def small_pages() -> Iterator[None]:
    """NumPy's huge-page advice off inside the block (module docstring), then as it was."""
    switch = None if "NUMPY_MADVISE_HUGEPAGE" in os.environ else _setter()
    if switch is None:
        yield
        return
    before = switch(False)
    try:
        yield
    finally:
        switch(before)


def advice_text() -> str:
    """The line a report prints of how this process asked for memory."""
    given = os.environ.get("NUMPY_MADVISE_HUGEPAGE")
    if given is not None:
        return f"NumPy huge-page advice as NUMPY_MADVISE_HUGEPAGE={given} sets it, throughout"
    if _setter() is None:
        return "NumPy huge-page advice as NumPy sets it, throughout"
    return ("NumPy's own huge-page advice, off while reading the cache "
            "(NUMPY_MADVISE_HUGEPAGE=0 or 1 sets it throughout)")


__all__ = ["advice_text", "small_pages"]
