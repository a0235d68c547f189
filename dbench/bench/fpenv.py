"""Methods run inside the floating-point environment they found (C99 ``fegetenv``/``fesetenv``).

ONNX Runtime sessions made with ``session.set_denormal_as_zero`` (the shipped ``nca`` and
``autoencoder`` models) switch the calling thread to flush-to-zero and denormals-are-zero (the
x86 MXCSR bits) and leave it so, as does ``torch.set_flush_denormal``. Every later computation
on that thread then rounds subnormal values to 0, so a method's numbers depended on which
methods had run before it in the same process (measured: after ``nca`` a float32 product of
1e-40 gave 0, and a hand-back whose 1 / subnormal overflowed to NaN on its own came out finite
after it). The harness calls every method through :func:`denoise`, which restores the
environment (rounding mode, exception masks, FTZ/DAZ) when the call returns.
"""
from __future__ import annotations

import ctypes
import ctypes.util
from contextlib import contextmanager
from typing import Any, Iterator

#: Bytes reserved for a ``fenv_t``: larger than any platform's (32 on x86-64 glibc).
_ENV_BYTES = 512


def _load_libm():
    name = ctypes.util.find_library("m")
    try:
        lib = ctypes.CDLL(name) if name else ctypes.CDLL(None)
        lib.fegetenv.argtypes = lib.fesetenv.argtypes = [ctypes.c_void_p]
    except (OSError, AttributeError):  # no C maths library: nothing to save or restore
        return None
    return lib


_LIBM = _load_libm()


def snapshot() -> Any:
    """The calling thread's floating-point environment, or None where it cannot be read."""
    if _LIBM is None:
        return None
    env = ctypes.create_string_buffer(_ENV_BYTES)
    return env if _LIBM.fegetenv(env) == 0 else None


def restore(env: Any) -> None:
    """Set the calling thread's floating-point environment to a :func:`snapshot` (None: no-op)."""
    if env is not None:
        _LIBM.fesetenv(env)


@contextmanager
def kept_fp_environment() -> Iterator[None]:
    """Save the thread's floating-point environment and restore it on exit (a no-op where
    the C library offers no ``fegetenv``)."""
    env = snapshot()
    try:
        yield
    finally:
        restore(env)


def denoise(method: Any, data: Any) -> Any:
    """``method.denoise(data)`` inside :func:`kept_fp_environment`."""
    with kept_fp_environment():
        return method.denoise(data)


__all__ = ["denoise", "kept_fp_environment", "restore", "snapshot"]
