"""The launcher of dbench's Triton kernels: one source, compiled for CUDA tensors, interpreted
for CPU tensors (docs/gpu.md §1).

``@kernel`` wraps a Triton kernel function. ``K[grid](*args, **meta)`` runs ``triton.jit(fn)``
when any tensor argument is on a CUDA device and Triton's interpreter
(``triton.runtime.interpreter.InterpretedFunction``) otherwise, so the tests on the CPU machines
execute the very kernel source the GPU runs. The interpreter evaluates each program's block
operations with NumPy in the kernel's own dtypes (float32 stays float32), so the results it gives
match the compiled kernel's up to the order of floating-point operations and the ``exp``
implementation; the tests' tolerances cover both.

Kernels call no other ``@triton.jit`` functions, so both modes see one self-contained body.
"""
from __future__ import annotations

from contextlib import contextmanager
from functools import lru_cache
from typing import Any, Callable


@lru_cache(maxsize=1)
def triton_available() -> bool:
    """Whether the ``triton`` package imports here (it is needed on CUDA and by the tests)."""
    try:
        import triton  # noqa: F401
        return True
    except Exception:  # noqa: BLE001 - missing or broken: no kernels
        return False


class Kernel:
    """A Triton kernel runnable on CUDA tensors (compiled) and CPU tensors (interpreted)."""

    def __init__(self, fn: Callable) -> None:
        self.fn = fn
        self.__doc__ = fn.__doc__
        self.__name__ = fn.__name__
        self._compiled = None
        self._interpreted = None

    def _variant(self, on_cuda: bool):
        if on_cuda:
            if self._compiled is None:
                import triton
                self._compiled = triton.jit(self.fn)
            return self._compiled
        if self._interpreted is None:
            from triton.runtime.interpreter import InterpretedFunction
            self._interpreted = InterpretedFunction(self.fn)
        return self._interpreted

    def __getitem__(self, grid: Any):
        def launch(*args: Any, **meta: Any) -> None:
            on_cuda = any(getattr(getattr(a, "device", None), "type", None) == "cuda"
                          for a in args)
            if on_cuda:
                self._variant(True)[grid](*args, **meta)
            else:
                with _library_functions_as_python():
                    self._variant(False)[grid](*args, **meta)
        return launch


@contextmanager
def _library_functions_as_python():
    """Let the interpreter call Triton's own library functions that are themselves
    ``@triton.jit`` functions (``tl.zeros``, ``tl.sum`` …): outside ``TRITON_INTERPRET=1`` they
    refuse to be called from Python, so for the duration of an interpreted launch a call runs
    their Python body, which the interpreter's patched ``triton.language`` then evaluates. The
    compiled path never takes this route (it is set and restored around the CPU launch only)."""
    from triton.runtime.jit import JITFunction

    saved = JITFunction.__call__
    JITFunction.__call__ = lambda self, *a, **k: self.fn(*a, **k)
    try:
        yield
    finally:
        JITFunction.__call__ = saved


def kernel(fn: Callable) -> Kernel:
    """Decorator: ``fn`` (a Triton kernel body) as a :class:`Kernel`."""
    return Kernel(fn)


def cdiv(a: int, b: int) -> int:
    return -(-int(a) // int(b))


__all__ = ["Kernel", "cdiv", "kernel", "triton_available"]
