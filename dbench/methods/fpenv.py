"""The calling thread's floating-point environment, saved and restored (C99 ``fegetenv`` /
``fesetenv`` through ctypes): rounding mode, exception masks and the x86 flush-to-zero /
denormals-are-zero bits.

Why: ONNX Runtime's ``session.set_denormal_as_zero`` (the shipped ``nca`` and ``autoencoder``
sessions, :mod:`dbench.methods.ort_session`) switches the calling thread to flush-to-zero when
the process's first session is built and leaves it so, as ``torch.set_flush_denormal`` does.
Every later computation on that thread then rounds subnormal values to 0, so a method's numbers
depended on which methods had run before it in the same process (measured: after ``nca`` a
float32 product of 1e-40 gave 0, and a hand-back whose 1 / subnormal overflowed to NaN on its
own came out finite after it). The ONNX sessions are built and run inside
:func:`kept_fp_environment`, and the harness (:mod:`dbench.run.fpenv`) calls every method,
plug-ins included, inside it too.
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


__all__ = ["kept_fp_environment", "restore", "snapshot"]
