"""Where a method runs: the ``--device`` choice, frames uploaded to a device once, outputs brought
back, and timing that waits for the device (docs/gpu.md).

A method with a device path implements ``Denoiser.denoise_device(frame)``: it receives a
:class:`DeviceFrame` whose buffers are tensors already on the device and returns an (H, W, 3)
float32 tensor on the same device. Nothing inside such a call converts to NumPy; the host↔device
copies happen here, at the harness boundary, and are timed apart from the method
(:func:`upload`, :func:`download`).

Shapes: pixel buffers (H, W, C) float32 as in :mod:`dbench.data`; statistics (H, W, 3) float64.

Example:
    >>> import numpy as np
    >>> from dbench.data import Frame
    >>> f = Frame(color=np.ones((2, 3, 3), np.float32))
    >>> d = upload(f, "cpu")
    >>> tuple(d.color.shape), d.kind, d.shape
    ((2, 3, 3), 'steady', (2, 3))
    >>> download(d.color).dtype
    dtype('float32')
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import numpy as np

from .data import FRAME_BUFFERS
from .errors import DbenchInputError

#: Choices of ``--device``: ``auto`` is CUDA where a usable GPU is present, else the CPU.
DEVICES = ("auto", "cpu", "cuda")


@lru_cache(maxsize=1)
def cuda_usable() -> bool:
    """Whether PyTorch sees a CUDA device and can allocate on it."""
    try:
        import torch
        if not torch.cuda.is_available():
            return False
        torch.zeros(1, device="cuda")
        return True
    except Exception:  # noqa: BLE001 - any failure means "not usable"
        return False


def resolve_device(name: Any) -> str:
    """``"cpu"`` or ``"cuda"`` for a ``--device`` value; ``auto`` picks CUDA when usable.

    Raises:
        DbenchInputError: an unknown name, or ``cuda`` without a usable CUDA GPU.
    """
    if name not in DEVICES:
        raise DbenchInputError(f"device: expected one of {list(DEVICES)}, got {name!r}")
    if name == "auto":
        return "cuda" if cuda_usable() else "cpu"
    if name == "cuda" and not cuda_usable():
        raise DbenchInputError("device: 'cuda' asked for, but PyTorch sees no usable CUDA GPU "
                               "here; valid: cpu (or auto)")
    return name


@lru_cache(maxsize=4)
def device_name(device: str) -> str:
    """The GPU's name for ``"cuda"`` (``torch.cuda.get_device_name``); ``"cpu"`` for the host,
    whose model the harness records with every result (:mod:`dbench.run.machine`)."""
    if device == "cuda":
        import torch
        return torch.cuda.get_device_name(0)
    return "cpu"


def synchronize(device: str) -> None:
    """Wait until every kernel queued on ``device`` has finished (no-op on the CPU)."""
    if device == "cuda":
        import torch
        torch.cuda.synchronize()


@dataclass
class DeviceStats:
    """:class:`dbench.data.SampleStats` as float64 tensors (H, W, 3) on a device."""

    n: Any
    mean: Any
    var_mean: Any
    m3: Any
    transform: str
    lam: float

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(self.mean.shape)

    @property
    def theta(self):
        """θ̂ = μ + M3 / (6 var_mean n²), the correction 0 where that denominator is 0, as
        :attr:`dbench.data.SampleStats.theta` computes it."""
        import torch
        denom = 6.0 * self.var_mean * self.n * self.n
        safe = torch.where(denom > 0, denom, torch.ones_like(denom))
        return self.mean + torch.where(denom > 0, self.m3 / safe, torch.zeros_like(denom))


@dataclass
class DeviceFrame:
    """A frame's buffers as tensors on one device (see :func:`upload`).

    Attributes:
        kind: ``"steady"`` or ``"sequence"`` (per-frame of a sequence), as the host frame's.
        device: ``"cpu"`` or ``"cuda"``.
        buffers: {name: (H, W, C) float32 tensor} for the buffers that were uploaded.
        stats: :class:`DeviceStats` or None.
        meta: the host frame's ``meta`` (plain Python data, never copied to the device).
        total_var: a transient frame's (H, W, 3) float64 variance of its time-integrated image
            (:class:`dbench.data.TransientFrame`), uploaded with its statistics; else None.
    """

    kind: str
    device: str
    buffers: dict[str, Any]
    stats: DeviceStats | None = None
    meta: dict[str, Any] = field(default_factory=dict)
    total_var: Any = None

    def __getattr__(self, name: str) -> Any:
        if name in FRAME_BUFFERS:
            return self.buffers.get(name)
        raise AttributeError(name)

    @property
    def shape(self) -> tuple[int, int]:
        return tuple(self.buffers["color"].shape[:2])

    def has(self, buffer: str) -> bool:
        return (self.stats is not None) if buffer == "stats" else buffer in self.buffers


def upload(frame: Any, device: str, names: Any = None) -> DeviceFrame:
    """The buffers ``names`` of a host :class:`~dbench.data.Frame` (default: every one it has
    except ``reference`` and ``reference_var``, which only the judge reads) as tensors on
    ``device``: pixel buffers float32, statistics float64, each contiguous. A transient
    frame's colour and statistics are (H, W, T, 3); its ``total_var`` travels with the
    statistics (it comes from the same samples)."""
    import torch

    wanted = set(FRAME_BUFFERS) - {"reference"} if names is None else set(names)
    bufs = {}
    for name in FRAME_BUFFERS:
        arr = getattr(frame, name, None)
        if name in wanted and arr is not None:
            # a copy, never a view: the harness hands read-only arrays, and a tensor sharing
            # their memory would let a method write to its input (run/inputs.py)
            bufs[name] = torch.tensor(np.asarray(arr, np.float32), device=device)
    stats = None
    st = getattr(frame, "stats", None)
    if st is not None and (names is None or "stats" in wanted):
        def f64(a):
            return torch.tensor(np.asarray(a, np.float64), device=device)
        stats = DeviceStats(f64(st.n), f64(st.mean), f64(st.var_mean), f64(st.m3),
                            str(st.transform), float(st.lam))
    total_var = getattr(frame, "total_var", None)
    return DeviceFrame(getattr(frame, "kind", "steady"), device, bufs, stats,
                       dict(getattr(frame, "meta", {}) or {}),
                       None if stats is None or total_var is None else f64(total_var))


def download(tensor: Any) -> np.ndarray:
    """A method's output tensor as a contiguous float32 NumPy array on the host."""
    return np.ascontiguousarray(tensor.detach().to("cpu").numpy(), dtype=np.float32)


def timed(fn, device: str) -> tuple[Any, float]:
    """(result, wall seconds) of ``fn()``, the device synchronised before and after."""
    synchronize(device)
    t0 = time.perf_counter()
    out = fn()
    synchronize(device)
    return out, time.perf_counter() - t0


__all__ = ["DEVICES", "DeviceFrame", "DeviceStats", "cuda_usable", "device_name", "download",
           "resolve_device", "synchronize", "timed", "upload"]
