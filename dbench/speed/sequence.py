"""Per-frame speed of the temporal methods at 1280×720 on a synthetic moving sequence
(:func:`benchmark`; ``python -m dbench.studies.sequence_report --bench``), timed as
:func:`dbench.run.sequence_run.run_sequence` times a frame."""
from __future__ import annotations

import statistics
import time
from typing import Any, Iterable

from ..run import fpenv
from ..synthetic import synthetic_sequence


def benchmark(height: int = 720, width: int = 1280, repeats: int = 6,
              method_names: Iterable[str] = ("accumulate", "svgf", "asvgf", "bmfr", "oidn"),
              params: dict[str, dict] | None = None, threads: int | None = None
              ) -> dict[str, Any]:
    """Per-frame time of each method at ``height``×``width`` on :func:`synthetic_sequence`.

    Two warm-up frames (compilation, history filling), then ``repeats`` timed frames; reports
    the median wall time per frame and the process CPU time per frame (both cores together),
    which is less sensitive to other processes on a shared machine. OIDN runs in the same run
    (frame by frame) and every method's ``vs_oidn`` is its median over OIDN's. ``threads`` sets
    Numba's thread count for the run (default: all cores); the 1-minute load average before and after
    the run is recorded, since other processes on a small machine change the wall times a lot.
    """
    import os
    import resource

    from .. import registry
    from ..run.machine import machine_info

    params = params or {}
    seq = synthetic_sequence(height, width, frames=repeats + 2)
    info = machine_info()
    out: dict[str, Any] = {"benchmark": "sequence-speed", "height": height, "width": width,
                           "repeats": repeats, "machine": info["cpu"], "cores": info["cores"],
                           "when": time.strftime("%Y-%m-%d %H:%M:%S"),
                           "load_before": os.getloadavg()[0], "methods": {}}
    old_threads = None
    try:
        import numba
        old_threads = numba.get_num_threads()
        if threads:
            numba.set_num_threads(int(threads))
        out["threads"] = numba.get_num_threads()
    except ImportError:  # pragma: no cover
        pass
    try:
        _bench_methods(out, seq, method_names, params, registry, resource)
    finally:
        if old_threads is not None:
            import numba
            numba.set_num_threads(old_threads)
    out["load_after"] = os.getloadavg()[0]
    return out


def _bench_methods(out, seq, method_names, params, registry, resource) -> None:
    for name in method_names:
        m = registry.get(name, **params.get(name, {}))
        m.reset()
        walls, cpus = [], []
        for i, frame in enumerate(seq):
            r0 = resource.getrusage(resource.RUSAGE_SELF)
            t0 = time.perf_counter()
            fpenv.denoise(m, frame)
            wall = time.perf_counter() - t0
            r1 = resource.getrusage(resource.RUSAGE_SELF)
            if i >= 2:
                walls.append(wall)
                cpus.append((r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime))
        out["methods"][name] = {"median_ms": 1e3 * statistics.median(walls),
                                "min_ms": 1e3 * min(walls),
                                "cpu_ms": 1e3 * statistics.median(cpus),
                                "params": m.params}
    oidn = out["methods"].get("oidn")
    if oidn:
        for v in out["methods"].values():
            v["vs_oidn"] = v["median_ms"] / oidn["median_ms"]
