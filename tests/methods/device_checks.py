"""Shared by the device-path tests: the ways out of a device call to NumPy or the host refused
for its duration (dbench/denoiser.py ``denoise_device``: no NumPy conversion inside a call)."""
from __future__ import annotations

from contextlib import contextmanager

import torch

#: Everything by which image data could leave the device: the strict set.
HOST_EXITS = ("numpy", "__array__", "tolist", "item")


@contextmanager
def host_conversions_refused(monkeypatch, names=HOST_EXITS, small_tolist: int | None = None,
                             what: str = "image data left the device inside denoise_device"):
    """Inside the block each of ``names`` on a tensor raises AssertionError(``what``); with
    ``small_tolist`` = k, ``tolist`` of at most k elements (a few scalars read back, a
    synchronisation) is allowed and of more refused. Every patch is undone afterwards."""
    def refuse(*_a, **_k):
        raise AssertionError(what)

    for name in names:
        monkeypatch.setattr(torch.Tensor, name, refuse)
    if small_tolist is not None:
        original = torch.Tensor.tolist

        def tolist(t):
            if t.numel() > small_tolist:
                refuse()
            return original(t)
        monkeypatch.setattr(torch.Tensor, "tolist", tolist)
    try:
        yield
    finally:
        monkeypatch.undo()
