"""The launcher of dbench's Triton kernels: one source, compiled for CUDA tensors, interpreted
for CPU tensors (docs/gpu.md §1).

``@kernel`` wraps a Triton kernel function. ``K[grid](*args, **meta)`` runs ``triton.jit(fn)``
when any tensor argument is on a CUDA device and Triton's interpreter
(``triton.runtime.interpreter.InterpretedFunction``) otherwise, so the tests on the CPU machines
execute the very kernel source the GPU runs. The interpreter evaluates each program's block
operations with NumPy in the kernel's own dtypes (float32 stays float32), so the results it gives
match the compiled kernel's up to the order of floating-point operations and the ``exp``
implementation; the tests' tolerances cover both.

Kernels may call the ``@triton.jit`` device functions of ``common.py``: compiled, Triton inlines
them; interpreted, their Python bodies run (see ``_library_functions_as_python``).

Two aids for compiling without a GPU (docs/gpu.md §6): :func:`recording` collects every launch
(kernel, arguments, meta-parameters) while the interpreter runs it, and :func:`gpu_layout` makes
the launch choices that differ between the interpreter and the GPU (pixels per program, warps)
take the GPU's values on CPU tensors, so that a recording made here has the launches a GPU
makes; :mod:`dbench.methods.kernels.gpu.aot` compiles them for a CUDA target.
"""
from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Callable

#: Set inside :func:`gpu_layout`; the list of :func:`recording`, when one is open.
_STATE: dict[str, Any] = {"gpu_layout": False, "recording": None, "execute": True}


@lru_cache(maxsize=1)
def triton_available() -> bool:
    """Whether the ``triton`` package imports here (it is needed on CUDA and by the tests)."""
    try:
        import triton  # noqa: F401
        return True
    except Exception:  # noqa: BLE001 - missing or broken: no kernels
        return False


@dataclass(frozen=True)
class Launch:
    """One launch seen by :func:`recording`: the kernel, its positional arguments (tensors as
    passed) and its keyword meta-parameters (constexprs and launch options such as
    ``num_warps``)."""
    kernel: "Kernel"
    args: tuple
    meta: dict


def on_gpu_layout(device: Any) -> bool:
    """Whether launches for ``device`` (a torch device or its type) take the GPU's choices of
    block size and warps: on CUDA, and on any device inside :func:`gpu_layout`."""
    return getattr(device, "type", device) == "cuda" or _STATE["gpu_layout"]


@contextmanager
def gpu_layout():
    """Inside the block, launch choices follow the GPU (:func:`on_gpu_layout`) on CPU tensors
    too; the interpreter runs them unchanged (it ignores ``num_warps``), more slowly."""
    saved = _STATE["gpu_layout"]
    _STATE["gpu_layout"] = True
    try:
        yield
    finally:
        _STATE["gpu_layout"] = saved


@contextmanager
def recording(execute: bool = True):
    """Yields a list to which every kernel launch inside the block is appended as a
    :class:`Launch`. With ``execute`` False the launches are recorded and not run, so the
    outputs hold whatever their buffers held: for learning which kernels a device path launches
    (no device path steers its launches by a kernel's output), not for its numbers."""
    saved = _STATE["recording"], _STATE["execute"]
    launches: list[Launch] = []
    _STATE["recording"], _STATE["execute"] = launches, bool(execute)
    try:
        yield launches
    finally:
        _STATE["recording"], _STATE["execute"] = saved


class Kernel:
    """A Triton kernel runnable on CUDA tensors (compiled) and CPU tensors (interpreted).

    ``do_not_specialize`` names scalar arguments whose values must not give the compiled kernel
    variants of its own (Triton compiles one for an integer equal to 1 and one for a multiple of
    16 by default): each variant costs a compilation of many seconds on a fresh machine."""

    def __init__(self, fn: Callable, do_not_specialize: tuple[str, ...] = ()) -> None:
        self.fn = fn
        self.__doc__ = fn.__doc__
        self.__name__ = fn.__name__
        self.__module__ = fn.__module__
        self.do_not_specialize = tuple(do_not_specialize)
        self._compiled = None
        self._interpreted = None

    def jit(self):
        """The ``triton.jit`` form of the kernel (made once), which CUDA launches compile."""
        if self._compiled is None:
            import triton
            self._compiled = triton.jit(self.fn, do_not_specialize=list(self.do_not_specialize))
        return self._compiled

    def _variant(self, on_cuda: bool):
        if on_cuda:
            return self.jit()
        if self._interpreted is None:
            from triton.runtime.interpreter import InterpretedFunction
            self._interpreted = InterpretedFunction(self.fn)
        return self._interpreted

    def __getitem__(self, grid: Any):
        def launch(*args: Any, **meta: Any) -> None:
            if _STATE["recording"] is not None:
                _STATE["recording"].append(Launch(self, args, dict(meta)))
                if not _STATE["execute"]:
                    return
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


def kernel(fn: Callable | None = None, *, do_not_specialize: tuple[str, ...] = ()):
    """Decorator: ``fn`` (a Triton kernel body) as a :class:`Kernel`; ``@kernel(
    do_not_specialize=("step",))`` passes the names on (:class:`Kernel`)."""
    if fn is None:
        return lambda f: Kernel(f, do_not_specialize)
    return Kernel(fn)


def cdiv(a: int, b: int) -> int:
    return -(-int(a) // int(b))


__all__ = ["Kernel", "Launch", "cdiv", "gpu_layout", "kernel", "on_gpu_layout", "recording",
           "triton_available"]
