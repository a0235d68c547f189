"""Methods run inside the floating-point environment they found (C99 ``fegetenv``/``fesetenv``,
:mod:`dbench.methods.fpenv`).

A method that switches the calling thread to flush-to-zero and leaves it so (a plug-in calling
``torch.set_flush_denormal(True)``; the shipped ONNX sessions restore it themselves) would make
every later method in the process round subnormal values to 0, so that its numbers depended on
which methods ran before it. The harness calls every method through :func:`denoise`, which
restores the environment (rounding mode, exception masks, FTZ/DAZ) when the call returns.
"""
from __future__ import annotations

from typing import Any

from ..methods.fpenv import kept_fp_environment, restore, snapshot


def denoise(method: Any, data: Any) -> Any:
    """``method.denoise(data)`` inside :func:`kept_fp_environment`."""
    with kept_fp_environment():
        return method.denoise(data)


def denoise_device(method: Any, data: Any) -> Any:
    """``method.denoise_device(data)`` inside :func:`kept_fp_environment`."""
    with kept_fp_environment():
        return method.denoise_device(data)


__all__ = ["denoise", "denoise_device", "kept_fp_environment", "restore", "snapshot"]
