"""``dbench bench kernels``: every Triton kernel variant the device paths launch, compiled for a
CUDA target on this machine, with the seconds each compilation takes (docs/gpu.md §6).

The launches are learnt by running each method's device path on CPU tensors inside
``runtime.gpu_layout`` (the GPU's block sizes and warps) with the launches recorded and not
executed (``runtime.recording(execute=False)``: the variants depend on the arguments' types,
sizes and constants, never on a kernel's output), on a frame whose height and width are
multiples of 16 like 1280 × 720, so that Triton specialises the sizes as it does there. The
methods are those ``dbench bench gpu`` times, each with its defaults, over as many frames as a
temporal method needs to launch its history-carrying variants, and the transient statistical
denoiser.

``dbench bench gpu`` calls :func:`precompile` first on the GPU machine, with the GPU's own
target and one worker per core, so that its timed warm-up reads compiled kernels from Triton's
cache instead of compiling them one by one (docs/gpu.md §4). Here, on a machine without a GPU,
the same command proves that every variant compiles and says what each costs. The seconds are
this machine's CPU seconds, never a GPU figure.
"""
from __future__ import annotations

import os
import time
from typing import Any

#: Frame size of the recording: multiples of 16 (Triton's divisibility hint) as 1280 × 720.
HEIGHT, WIDTH = 16, 32
#: Frames a method's device path is called on: enough for the history-carrying launches.
FRAMES = 3


def record_launches(methods: list[str] | None = None, transient: bool = True,
                    size: tuple[int, int] | None = None,
                    transient_size: tuple[int, int, int] | None = None) -> dict[str, list]:
    """Method name → its device path's launches (``runtime.Launch``) on a synthetic frame of
    ``size`` (height, width; default :data:`HEIGHT` × :data:`WIDTH`), every frame's, with the
    GPU's launch choices, not executed. Methods without a device path are left out.
    ``transient`` adds "statistical (transient)" on a video of ``transient_size`` (height,
    width, bins; default 16 × 32 × 4) when ``statistical`` is among the methods.

    Triton specialises integer arguments by value (1, multiples of 16), sizes derived from the
    frame's included (A-SVGF's strata are ⌈H/3⌉ × ⌈W/3⌉), so a recording has the variants of
    its own size: ``dbench bench gpu`` records at the sizes it times."""
    from .. import registry
    from ..device import upload
    from ..methods.kernels.gpu.runtime import gpu_layout, recording
    from ..run import fpenv
    from .gpu import TARGETS_MS, _available, _temporal, synthetic_frame, transient_video

    found: dict[str, list] = {}
    frame = synthetic_frame(*(size or (HEIGHT, WIDTH)))
    jobs = [(n, frame) for n in (methods or list(TARGETS_MS))]
    if transient and (methods is None or "statistical" in methods):
        jobs.append(("statistical (transient)",
                     transient_video(*(transient_size or (HEIGHT, WIDTH, 4)))))
    for label, fr in jobs:
        m = registry.get(label.split(" ")[0])
        if not m.runs_on_device():
            continue
        data = upload(fr, "cpu", m.wants(_available(fr)))
        m.reset()
        with gpu_layout(), recording(execute=False) as launches:
            for _ in range(FRAMES if _temporal(m) else 1):
                fpenv.denoise_device(m, data)
        if launches:
            found[label] = launches
    return found


def precompile(arch: int | None = None, jobs: int | None = None,
               methods: list[str] | None = None, log=None,
               sizes: list[tuple[int, int]] | None = None,
               transient_size: tuple[int, int, int] | None = None) -> dict[str, Any]:
    """Every variant of :func:`record_launches` at each of ``sizes`` (default: the recording
    frame alone) compiled for ``sm_<arch>`` (default: the GPU PyTorch sees, else
    :data:`aot.DEFAULT_ARCH`), ``jobs`` processes at a time (default: one per core). Returns
    the target, the wall time and a row per variant (the methods that launch it, its compile
    seconds and sizes, or its error)."""
    from ..methods.kernels.gpu import aot

    arch = int(arch or _local_arch() or aot.DEFAULT_ARCH)
    jobs = int(jobs or os.cpu_count() or 1)
    t0 = time.perf_counter()
    users: dict[Any, list[str]] = {}
    for i, size in enumerate(sizes or [None]):
        recorded = record_launches(methods, transient=(i == 0), size=size,
                                   transient_size=transient_size)
        for label, launches in recorded.items():
            for v in aot.variants(launches, arch):
                if label not in users.setdefault(v, []):
                    users[v].append(label)
    found = list(users)
    record_s = time.perf_counter() - t0
    if log:
        log(f"compiling {len(found)} kernel variants for sm_{arch}, {jobs} at a time")
    t1 = time.perf_counter()
    rows = aot.compile_all(found, arch, jobs)
    for v, row in zip(found, rows):
        row["methods"] = users[v]
    return {"benchmark": "kernels", "arch": f"sm_{arch}", "jobs": jobs, "variants": len(found),
            "record_s": record_s, "compile_wall_s": time.perf_counter() - t1,
            "compile_sum_s": sum(r["seconds"] for r in rows if "error" not in r),
            "errors": sum("error" in r for r in rows), "rows": rows}


def _local_arch() -> int | None:
    """The compute capability of the GPU PyTorch sees (e.g. 90), None without one."""
    try:
        import torch
        if torch.cuda.is_available():
            major, minor = torch.cuda.get_device_capability()
            return 10 * major + minor
    except Exception:  # noqa: BLE001 - no usable GPU: the default target
        pass
    return None


def format_result(result: dict[str, Any]) -> str:
    """A table of the variants, slowest first, and the totals."""
    lines = [f"kernels for {result['arch']}: {result['variants']} variants, "
             f"{result['compile_wall_s']:.1f} s wall with {result['jobs']} process(es) "
             f"({result['compile_sum_s']:.1f} s of compilation; launches recorded in "
             f"{result['record_s']:.1f} s); compile times are this machine's CPU seconds",
             "", "| kernel variant | methods | compile s | cubin KiB |", "|---|---|---:|---:|"]
    for r in sorted(result["rows"], key=lambda r: -(r["seconds"] if r["seconds"] == r["seconds"]
                                                      else 1e9)):
        if "error" in r:
            lines.append(f"| {r['variant']} | {', '.join(r['methods'])} | failed | "
                         f"{r['error'].splitlines()[0][:120]} |")
        else:
            lines.append(f"| {r['variant']} | {', '.join(r['methods'])} | {r['seconds']:.2f} | "
                         f"{r['cubin_bytes'] / 1024:.0f} |")
    return "\n".join(lines)


__all__ = ["FRAMES", "HEIGHT", "WIDTH", "format_result", "precompile", "record_launches"]
