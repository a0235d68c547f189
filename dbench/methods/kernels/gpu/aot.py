"""Compiling dbench's Triton kernels for a CUDA GPU on a machine without one (docs/gpu.md §6).

A launch recorded by :func:`dbench.methods.kernels.gpu.runtime.recording` (made on CPU tensors
inside ``runtime.gpu_layout``, so with the GPU's block sizes and warps) is turned into the very
compilation Triton's JIT performs when the same launch meets CUDA tensors: the arguments are
specialised by the JIT's own binder (an integer equal to 1 becomes a constant, a multiple of 16
and a 16-byte-aligned pointer get the divisibility hint, unless the kernel lists the argument
in ``do_not_specialize``), the options are parsed by the CUDA backend, and ``triton.compile``
runs Triton's passes, LLVM and ``ptxas`` for the target. Nothing needs a GPU or its driver.

Two uses:

* a test compiles every kernel variant the device paths launch for ``sm_90``, so a kernel that
  the interpreter runs but the GPU compiler refuses fails on the CPU machines;
* ``dbench bench gpu`` compiles the variants in parallel processes before it times anything
  (:func:`compile_all`): the results land in Triton's on-disk cache under the key the JIT
  computes for the same launch, so the timed calls' warm-up finds them instead of compiling one
  kernel after another on one core.
"""
from __future__ import annotations

import importlib
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from typing import Any

from .runtime import Kernel, Launch

#: The default target: compute capability 9.0 (H100, H200), 32 threads a warp.
DEFAULT_ARCH = 90


@dataclass(frozen=True)
class Variant:
    """One compilation: the kernel (by module and name, so a worker process can import it), its
    signature (argument name → Triton type or "constexpr"), the constant values, the
    divisibility attributes and the options, as the JIT would pass them."""
    module: str
    name: str
    signature: tuple
    constexprs: tuple
    attrs: tuple
    options: tuple
    #: ``name(CONST=value, …)`` for tables (not part of the variant's identity).
    label: str = field(default="", compare=False)


def _target(arch: int):
    from triton.backends.compiler import GPUTarget
    return GPUTarget("cuda", int(arch), 32)


def _backend(arch: int):
    from triton.compiler import make_backend
    return make_backend(_target(arch))


def variant_of(launch: Launch, arch: int = DEFAULT_ARCH) -> Variant:
    """The compilation the JIT would perform for ``launch`` on a ``sm_<arch>`` GPU (its binder
    and argument packing, :mod:`triton.runtime.jit`, applied to the recorded arguments)."""
    from triton import knobs
    from triton.runtime.jit import create_function_from_signature

    jf = launch.kernel.jit()
    backend = _backend(arch)
    kwargs = dict(launch.meta)
    # as JITFunction.run sets them before binding
    kwargs["debug"] = kwargs.get("debug", jf.debug) or knobs.runtime.debug
    kwargs["instrumentation_mode"] = knobs.compilation.instrumentation_mode
    binder = create_function_from_signature(jf.signature, jf.params, backend)
    bound, specialization, options = binder(*launch.args, **kwargs)
    options, signature, constexprs, attrs = jf._pack_args(backend, kwargs, bound,
                                                          specialization, options)
    names = [p.name for p in jf.params]
    # the constants the kernel declares (an argument equal to 1 is one too, unnamed here)
    consts = ", ".join(f"{names[k[0]]}={v}" for k, v in constexprs.items()
                       if jf.params[k[0]].is_constexpr)
    return Variant(launch.kernel.__module__, launch.kernel.__name__,
                   tuple(signature.items()), tuple(sorted(constexprs.items(), key=str)),
                   # in the JIT's order: the source's hash reads them as written
                   tuple((k, tuple(map(tuple, v))) for k, v in attrs.items()),
                   tuple(sorted(options.__dict__.items())),
                   label=f"{launch.kernel.__name__}({consts})")


def variants(launches: list[Launch], arch: int = DEFAULT_ARCH) -> list[Variant]:
    """The distinct compilations of ``launches``, in order of first launch."""
    seen: dict[Variant, None] = {}
    for launch in launches:
        seen.setdefault(variant_of(launch, arch), None)
    return list(seen)


def source_of(variant: Variant):
    """The ``triton.compiler.ASTSource`` of ``variant``, equal (and of equal hash, so of equal
    cache key) to the one the JIT builds for the same launch."""
    from triton.compiler import ASTSource

    k = getattr(importlib.import_module(variant.module), variant.name)
    if not isinstance(k, Kernel):
        raise TypeError(f"{variant.module}.{variant.name} is not a dbench kernel")
    attrs = {key: [list(a) for a in val] for key, val in variant.attrs}
    return ASTSource(k.jit(), dict(variant.signature), dict(variant.constexprs), attrs)


def compile_variant(variant: Variant, arch: int = DEFAULT_ARCH) -> dict[str, Any]:
    """Compile one variant for ``sm_<arch>`` (through Triton's cache: a variant compiled before
    with the same Triton, ptxas and options is read back). Returns its label, the seconds it
    took, the sizes of its PTX and cubin and the shared memory it asks for."""
    import triton

    src = source_of(variant)
    t0 = time.perf_counter()
    compiled = triton.compile(src, target=_target(arch), options=dict(variant.options))
    seconds = time.perf_counter() - t0
    return {"kernel": variant.name, "variant": variant.label, "seconds": seconds,
            "ptx_bytes": len(compiled.asm.get("ptx", "")),
            "cubin_bytes": len(compiled.asm.get("cubin", b"")),
            "shared_bytes": int(getattr(compiled.metadata, "shared", 0) or 0)}


def compile_all(found: list[Variant], arch: int = DEFAULT_ARCH, jobs: int = 1
                ) -> list[dict[str, Any]]:
    """Compile every variant, ``jobs`` at a time in worker processes (``spawn``: no state
    inherited; each writes Triton's on-disk cache), in the order given. A variant that fails to
    compile is a row with its ``error``."""
    if jobs <= 1 or len(found) <= 1:
        return [_compile_row(v, arch) for v in found]
    import multiprocessing

    ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=min(jobs, len(found)), mp_context=ctx) as pool:
        return list(pool.map(_compile_row, found, [arch] * len(found)))


def _compile_row(variant: Variant, arch: int) -> dict[str, Any]:
    try:
        return compile_variant(variant, arch)
    except Exception as exc:  # noqa: BLE001 - a kernel the compiler refuses is a row, named
        return {"kernel": variant.name, "variant": variant.label, "seconds": float("nan"),
                "error": f"{type(exc).__name__}: {exc}"[:2000]}


__all__ = ["DEFAULT_ARCH", "Variant", "compile_all", "compile_variant", "source_of",
           "variant_of", "variants"]
