"""``dbench bench gpu``: every method's device path timed on one GPU at 1280×720 against its
numba path on the host CPU cores and against OIDN on the same GPU, its output checked against
the numba output, its kernel launches and copies counted (docs/gpu.md §4). With
``statistical`` comes one more row: its transient (spatio-temporal) form on a 128² × 32-bin
video (:data:`TRANSIENT_SIZE`), timed and checked the same way.

Timing: the frame is uploaded once; each device call is timed with ``torch.cuda.synchronize()``
before and after it, after warm-up calls (compilation, caches; a temporal method's history
filled by the 8 warm-up frames of :mod:`dbench.run.sequence_run`), median of ``repeats``. Host
calls: median of ``host_repeats`` after one warm-up. One further device call is profiled
(``torch.profiler``) to count kernel launches and memory copies. Nothing here is a CPU figure
presented as a GPU one: each row names where each of its times was measured.

On a machine without a GPU, ``device="cpu"`` runs the same script on CPU tensors (the kernels
through Triton's interpreter) at a small size: a dry run that the tests use, whose times mean
nothing and which is never written to ``results/gpu``.
"""
from __future__ import annotations

import json
import re
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np

from ..device import download, synchronize, timed, upload
from ..run import fpenv
from ..run.harness import time_call
from ..run.machine import machine_info

#: The methods the GPU issue times, in its order, with its targets (ms per call or frame).
TARGETS_MS: dict[str, float] = {"statistical": 10.0, "jbf": 5.0, "accumulate": 0.3,
                                "svgf": 2.0, "asvgf": 3.0, "bmfr": 3.0, "nca": 2.0,
                                "autoencoder": 8.0, "oidn": 1.1 * 3.15}
#: OIDN's own benchmark on the H200 (oidnBenchmark -d cuda, 1280×720, high quality), ms.
OIDN_OWN_MS = 3.15
#: The synthetic frame's samples per pixel.
SPP = 16
#: The transient video's (height, width, bins) on a GPU, and its target per call (ms): the size
#: whose numba time on 16 host cores was measured at 1.26 s; a dry run on CPU tensors takes at
#: most 8 × 12 pixels of its frame size and 2 bins (Triton's interpreter walks the 11² × 3
#: window, about 7 s a call on such a video).
TRANSIENT_SIZE = (256, 256, 100)
#: The frame (height, width) of the finite-output check (a 3e38 block and a NaN pixel).
HOSTILE_SIZE = (64, 96)
TRANSIENT_TARGET_MS = 30.0


def _temporal(method) -> bool:
    return "sequence" in method.kinds and "steady" not in method.kinds


def synthetic_frame(height: int, width: int, hostile: bool = False, spp: int = SPP):
    """The benchmark frame (:func:`dbench.synthetic.base_frame` with a static camera's
    motion and gradient); ``hostile`` adds a 3e38 block and a NaN pixel."""
    from ..synthetic import base_frame

    frame = base_frame(height, width, spp=spp)
    frame = frame.with_buffers(meta={"spp": spp},
                               motion=np.zeros((height, width, 2), np.float32),
                               gradient=np.array(frame.color, copy=True))
    if hostile:  # the finite-output contract: a block of 3e38 colour and a NaN pixel
        color = np.array(frame.color, copy=True)
        color[: max(height // 4, 1), : max(width // 4, 1)] = 3e38
        color[-1, -1] = np.nan
        frame = frame.with_buffers(color=color, gradient=color.copy())
    return frame


def _available(frame) -> set[str]:
    from ..data import BUFFER_NAMES
    return {b for b in BUFFER_NAMES if getattr(frame, b, None) is not None}


def _host_run(name: str, frame, repeats: int) -> tuple[float, np.ndarray]:
    """(median seconds, output) of the host path (numba where the method has it)."""
    from .. import registry
    from ..run.sequence_run import WARMUP

    m = registry.get(name)
    if _temporal(m):
        m.reset()
        for _ in range(WARMUP):
            fpenv.denoise(m, frame)

    def call():
        if not _temporal(m):
            m.reset()
        return fpenv.denoise(m, frame)

    out = call()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = call()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), np.asarray(out, np.float32)


def count_device_work(fn, device: str) -> dict[str, int]:
    """Kernel launches and memory copies of one call of ``fn`` (PyTorch profiler, CUPTI: every
    kernel on the device is seen, Triton's and OIDN's included). {} off CUDA."""
    if device != "cuda":
        return {}
    from torch.profiler import ProfilerActivity, profile

    synchronize(device)
    with profile(activities=[ProfilerActivity.CPU, ProfilerActivity.CUDA]) as prof:
        fn()
        synchronize(device)
    kernels = copies = sets = 0
    for e in prof.events():
        if getattr(e, "device_type", None) is None or str(e.device_type) != "DeviceType.CUDA":
            continue
        if e.name.startswith("Memcpy"):
            copies += 1
        elif e.name.startswith("Memset"):
            sets += 1
        else:
            kernels += 1
    return {"kernel_launches": kernels, "memcpy": copies, "memset": sets}


def device_run(name: str, frame, device: str, repeats: int, params: dict | None = None
               ) -> dict[str, Any]:
    """A method's device path on ``frame``: median synchronised time after warm-up, the
    copies, launches and copies per call (CUDA), its output; ``{"device_path": False}`` when
    the method (with ``params``) has none."""
    from .. import registry
    from ..run.sequence_run import WARMUP

    m = registry.get(name, **(params or {}))
    if not m.runs_on_device():
        return {"device_path": False}
    data, upload_s = timed(lambda: upload(frame, device, m.wants(_available(frame))), device)
    temporal = _temporal(m)

    def call():
        if not temporal:
            m.reset()
        return fpenv.denoise_device(m, data)

    m.reset()
    _, times = time_call(call, repeats=repeats, warmup=WARMUP if temporal else 2, device=device)
    counts = count_device_work(call, device)
    out, download_s = timed(lambda: download(call()), device)
    # what the calls ran on, where the method says (OIDN: its CPU device on CPU tensors)
    ran = (getattr(m, "last_settings", None) or {}).get("backend") or m.device_backend
    return {"device_path": True, "backend": ran, "time_s": statistics.median(times),
            "time_s_min": min(times), "time_s_max": max(times), "upload_s": upload_s,
            "download_s": download_s, **counts, "output": out,
            "settings": {k: v for k, v in (getattr(m, "last_settings", None) or {}).items()
                         if isinstance(v, (str, int, float, bool, type(None)))}}


def _nonfinite_on_hostile(name: str, height: int, width: int, device: str,
                          frame=None) -> int | None:
    """Non-finite output values of the device path on ``frame`` (default: the hostile
    :func:`synthetic_frame` of that size)."""
    from .. import registry
    from ..run.sequence_run import WARMUP

    m = registry.get(name)
    if not m.runs_on_device():
        return None
    frame = synthetic_frame(height, width, hostile=True) if frame is None else frame
    data = upload(frame, device, m.wants(_available(frame)))
    m.reset()
    out = None
    for _ in range(WARMUP if _temporal(m) else 1):
        out = fpenv.denoise_device(m, data)
    return int((~np.isfinite(download(out))).sum())


def compare(device_out: np.ndarray, host_out: np.ndarray) -> dict[str, float]:
    """Largest absolute difference, and relative to max(|host|, 1e-3), over finite pixels."""
    ok = np.isfinite(device_out) & np.isfinite(host_out)
    diff = np.abs(device_out.astype(np.float64) - host_out)
    rel = diff / np.maximum(np.abs(host_out.astype(np.float64)), 1e-3)
    return {"max_abs_diff": float(diff[ok].max()) if ok.any() else float("nan"),
            "max_rel_diff": float(rel[ok].max()) if ok.any() else float("nan"),
            "mean_abs_diff": float(diff[ok].mean()) if ok.any() else float("nan"),
            "finite_mismatch": int((np.isfinite(device_out) != np.isfinite(host_out)).sum())}


#: the statistics cost a render may have against a plain one (README.md, "How renders work")
RENDER_TARGET = 1.10


def render_row(height: int, width: int, spp: int = 64, log=print) -> dict[str, Any]:
    """``dbench bench render`` of ``cornell`` at the frame's size on the render device this
    process renders with (``cuda_ad_rgb`` on a GPU machine): a plain render against the samples
    with and without statistics, in interleaved rounds (:func:`dbench.speed.timing.bench_render`),
    so one GPU loan also measures what statistics cost there; a failure is the entry's
    ``error``, never the run's."""
    from .timing import bench_render

    t0 = time.perf_counter()
    try:
        row = bench_render("cornell", res=f"{width}x{height}", spp=spp, repeats=3)
    except Exception as exc:  # noqa: BLE001 - recorded, as for the methods' rows
        row = {"benchmark": "render", "error": f"{type(exc).__name__}: {exc}"[:500]}
    row.update(target_ratio=RENDER_TARGET, wall_s=time.perf_counter() - t0)
    log(f"render cornell {width}x{height} {spp} spp: failed: {row['error']}" if "error" in row
        else f"render cornell {width}x{height} {spp} spp on {row['variant']}: plain "
             f"{row['plain_s']:.3f} s, statistics {row['ratio_stats_vs_plain']:.2f}x plain "
             f"(target {RENDER_TARGET:.2f}x)")
    return row


#: (scene, size, the per-bin statistics' target cost against a plain render) of the transient
#: render rows (issue targets; README.md, "How renders work")
TRANSIENT_RENDERS = (("cornell-transient", 128, 1.2), ("fog-transient", 48, 1.5))


def transient_render_rows(renders=TRANSIENT_RENDERS, log=print) -> list[dict[str, Any]]:
    """``dbench bench render`` of each transient scene of ``renders`` (100 bins, 64 spp) on the
    render device this process renders with: a plain mitransient render against colour and
    per-bin statistics through ``datasets.load``, with storing, with the cache off and read
    back (:func:`dbench.speed.transient_render.bench_render_transient`); a failure is the
    row's ``error``, never the run's."""
    from .transient_render import bench_render_transient

    rows = []
    for scene, res, target in renders:
        t0 = time.perf_counter()
        try:
            # one fresh process each for the first call (CUDA context, kernels from disk)
            row = bench_render_transient(scene, res=res, spp=64, bins=100, repeats=3,
                                         first_rounds=1)
        except Exception as exc:  # noqa: BLE001 - recorded, as for the methods' rows
            row = {"benchmark": "render-transient", "scene": scene, "res": res,
                   "error": f"{type(exc).__name__}: {exc}"[:500]}
        row.update(target_ratio=target, wall_s=time.perf_counter() - t0)
        log(f"render {scene} {res}²: failed: {row['error']}" if "error" in row else
            f"render {scene} {res}² on {row['variant']}: plain {row['plain_s']:.3f} s, "
            f"statistics {row['ratio_stats_vs_plain']:.2f}x with storing, "
            f"{row['ratio_stats_nocache_vs_plain']:.2f}x cache off (target {target:.2f}x)")
        rows.append(row)
    return rows


def bench_gpu(height: int = 720, width: int = 1280, repeats: int = 10, host_repeats: int = 3,
              device: str = "cuda", methods_: list[str] | None = None,
              hostile_size: tuple[int, int] = HOSTILE_SIZE, log=print,
              precompiled: dict[str, Any] | None = None, render: bool = True,
              transient_renders=TRANSIENT_RENDERS) -> dict[str, Any]:
    """Every method of :data:`TARGETS_MS` (or ``methods_``): device time, host time, the check
    against the host output, launches and copies; OIDN's qualities on the device; with
    ``render``, the statistics cost of a render at the same size (:func:`render_row`) and of
    the transient renders ``transient_renders`` (:func:`transient_render_rows`).
    ``precompiled``: the result of :func:`dbench.speed.kernels.precompile` run just before (the
    kernels compiled side by side into Triton's cache, so that the timed warm-up reads them),
    recorded as the entry ``precompile``."""
    names = list(methods_ or TARGETS_MS)
    pre = precompiled
    frame = synthetic_frame(height, width)
    rows = []
    for name in names:
        t0 = time.perf_counter()
        row: dict[str, Any] = {"method": name, "target_ms": TARGETS_MS.get(name)}
        try:
            host_s, host_out = _host_run(name, frame, host_repeats)
            row["host_time_s"] = host_s
            dev = device_run(name, frame, device, repeats)
            out = dev.pop("output", None)
            row.update(dev)
            if out is not None:
                row.update(compare(out, host_out))
                row["hostile_nonfinite"] = _nonfinite_on_hostile(name, *hostile_size, device)
                row["speedup_vs_host"] = host_s / row["time_s"]
        except Exception as exc:  # noqa: BLE001 - one method's failure is its row, not the run's
            row.update(device_path=bool(row.get("device_path")),
                       error=f"{type(exc).__name__}: {exc}"[:500])
        row["wall_s"] = time.perf_counter() - t0
        rows.append(row)
        log(_row_text(row, device))
    if "statistical" in names:
        rows.append(_transient_row(device, repeats, host_repeats, height, width))
        log(_row_text(rows[-1], device))
    oidn_rows = []
    if "oidn" in names:
        for quality in ("high", "balanced", "fast"):
            try:
                r = device_run("oidn", frame, device, repeats, params={"quality": quality})
                r.pop("output", None)
            except Exception as exc:  # noqa: BLE001 - recorded, as for the rows
                r = {"error": f"{type(exc).__name__}: {exc}"[:500]}
            oidn_rows.append({"quality": quality, **r})
    oidn_s = next((r["time_s"] for r in rows if r["method"] == "oidn" and r.get("device_path")),
                  None)
    for r in rows:
        if oidn_s and r.get("device_path"):
            r["ratio_vs_oidn_device"] = r["time_s"] / oidn_s
    info = machine_info()
    return {"benchmark": "gpu", "device": device, "device_name": _device_label(device),
            "height": height, "width": width, "spp": SPP, "repeats": repeats,
            "host_repeats": host_repeats, "host": f"{info['cpu']}, {info['cores']} cores",
            "packages": info["packages"], "rows": rows, "oidn_qualities": oidn_rows,
            "oidn_own_benchmark_ms": OIDN_OWN_MS,
            "render": render_row(height, width, log=log) if render else None,
            "transient_render": transient_render_rows(transient_renders, log=log)
            if render else None,
            "precompile": pre,
            "when": time.strftime("%Y-%m-%d %H:%M:%S")}


def transient_video(height: int, width: int, bins: int, hostile: bool = False):
    """The benchmark's TransientFrame: every bin non-empty
    (:func:`dbench.speed.statistical.synthetic_video`), the G-buffers of
    :func:`dbench.synthetic.synthetic_frame`, the total's variance the sum of the bins'
    (they are independent there); ``hostile`` adds a block of 3e38 in one bin and a NaN voxel."""
    from ..data import TransientFrame
    from ..synthetic import synthetic_frame as gbuffers
    from .statistical import synthetic_video

    color, stats = synthetic_video(height, width, bins, bins)
    g = gbuffers(height, width)
    if hostile:
        color = np.array(color, copy=True)
        color[: max(height // 4, 1), : max(width // 4, 1), bins // 2] = 3e38
        color[-1, -1, -1] = np.nan
    return TransientFrame(color=color, stats=stats, albedo=g["albedo"], normal=g["normal"],
                          depth=g["depth"], total_var=np.asarray(stats.var_mean).sum(axis=2))


def _transient_row(device: str, repeats: int, host_repeats: int, height: int, width: int
                   ) -> dict[str, Any]:
    """The transient statistical denoiser (its defaults: r_s = 5, r_t = 1) on a
    :data:`TRANSIENT_SIZE` video, timed and checked as the other rows, against
    :data:`TRANSIENT_TARGET_MS` on a GPU (none for a dry run's tiny video)."""
    from .. import registry

    h, w, t = TRANSIENT_SIZE if device == "cuda" else (min(height, 8), min(width, 12), 2)
    row: dict[str, Any] = {"method": f"statistical (transient {h}x{w}x{t})",
                           "target_ms": TRANSIENT_TARGET_MS if device == "cuda" else None}
    t0 = time.perf_counter()
    try:
        frame = transient_video(h, w, t)
        host_s, host_out = _host_run("statistical", frame, host_repeats)
        row["host_time_s"] = host_s
        dev = device_run("statistical", frame, device, repeats)
        out = dev.pop("output", None)
        row.update(dev)
        if out is not None:
            row.update(compare(out, host_out))
            hostile = transient_video(h, w, t, hostile=True)
            row["hostile_nonfinite"] = _nonfinite_on_hostile("statistical", h, w, device,
                                                             frame=hostile)
            # the host path's own count on the same video, so a device count is read against
            # what the host does (both rescale huge planes: only the NaN voxel should remain)
            host_hostile = fpenv.denoise(registry.get("statistical"), hostile)
            row["hostile_nonfinite_host"] = int((~np.isfinite(np.asarray(host_hostile))).sum())
            row["speedup_vs_host"] = host_s / row["time_s"]
    except Exception as exc:  # noqa: BLE001 - recorded as the row
        row.update(device_path=bool(row.get("device_path")),
                   error=f"{type(exc).__name__}: {exc}"[:500])
    row["wall_s"] = time.perf_counter() - t0
    return row


def bench_method_device(name: str, height: int, width: int, repeats: int, spp: int,
                         params: dict[str, Any], device: str) -> dict[str, Any]:
    """:func:`dbench.speed.timing.bench_method` on a device (``dbench bench METHOD --device
    cuda``): the device paths of the method and of OIDN, the frame uploaded once, synchronised
    calls; the result names the device and backend (printed by ``speed.format_result``)."""
    from ..device import device_name

    frame = synthetic_frame(height, width, spp=spp)
    mine = device_run(name, frame, device, max(repeats, 5), params=params)
    if not mine.get("device_path"):
        from ..errors import DbenchInputError
        raise DbenchInputError(f"--device {device}: {name} has no device path with these "
                               "parameters; run it with --device cpu")
    oidn = device_run("oidn", frame, device, max(repeats, 5))
    t, t_oidn = mine["time_s"], oidn["time_s"]
    return {"benchmark": "method", "method": name, "height": height, "width": width,
            "spp": spp, "params": params, "settings": mine.get("settings", {}),
            "time_s": t, "oidn_time_s": t_oidn, "ratio_vs_oidn": t / t_oidn,
            "mpix_per_s": height * width / t / 1e6, "device": device,
            "backend": mine["backend"], "machine": f"{device_name(device)} ({device})",
            "upload_s": mine["upload_s"], "download_s": mine["download_s"],
            "when": time.strftime("%Y-%m-%d %H:%M:%S")}


def _device_label(device: str) -> str:
    from ..device import device_name
    return device_name(device)


def _row_text(r: dict[str, Any], device: str) -> str:
    if "error" in r:
        return f"{r['method']:<12} failed: {r['error']}"
    host = f"host {r['host_time_s'] * 1e3:9.2f} ms"
    if not r.get("device_path"):
        return f"{r['method']:<12} {host}   no device path (runs on the host CPU)"
    return (f"{r['method']:<12} {host}   {device} {r['time_s'] * 1e3:8.3f} ms "
            f"(target {r['target_ms'] if r['target_ms'] is not None else '-'}) "
            f"launches {r.get('kernel_launches', '-')} copies {r.get('memcpy', '-')} "
            f"max rel diff {r['max_rel_diff']:.2e} non-finite on 3e38 block "
            f"{r['hostile_nonfinite']}"
            + (f" (host {r['hostile_nonfinite_host']})" if "hostile_nonfinite_host" in r else ""))


def markdown(result: dict[str, Any]) -> str:
    """The README's table of a :func:`bench_gpu` result."""
    dev = result["device_name"]
    lines = [f"| method | {dev}: device path | backend | target | numba on {result['host']} | "
             "speed-up | launches / copies per call | max rel. diff to numba |",
             "|---|---:|---|---:|---:|---:|---|---:|"]
    for r in result["rows"]:
        if "error" in r:
            lines.append(f"| {r['method']} | failed: {r['error'][:80]} | | | | | | |")
            continue
        host = f"{r['host_time_s'] * 1e3:.1f} ms"
        if not r.get("device_path"):
            lines.append(f"| {r['method']} | none (host only) | | {r['target_ms']} ms | {host} "
                         "| | | |")
            continue
        target = "-" if r["target_ms"] is None else f"{r['target_ms']:.2f} ms"
        lines.append(f"| {r['method']} | {r['time_s'] * 1e3:.3f} ms | {r['backend']} | "
                     f"{target} | {host} | {r['speedup_vs_host']:.0f}× | "
                     f"{r.get('kernel_launches', '-')} / {r.get('memcpy', '-')} | "
                     f"{r['max_rel_diff']:.1e} |")
    ren = result.get("render")
    if ren and "error" not in ren:  # the statistics cost of a render on the same machine
        lines += ["", f"Render statistics, cornell {ren['res']} at {ren['spp']} spp on "
                      f"{ren['variant']}: {ren['ratio_stats_vs_plain']:.2f}× a plain render's "
                      f"{ren['plain_s']:.3f} s (target {ren['target_ratio']:.2f}×)."]
    elif ren:
        lines += ["", f"Render statistics: failed: {ren['error'][:120]}"]
    for t in result.get("transient_render") or ():
        size = f"{t['res']}²" if isinstance(t["res"], int) else t["res"]
        lines += ["", f"Transient per-bin statistics, {t['scene']} {size}: failed: "
                      f"{t['error'][:120]}" if "error" in t else
                  f"Transient per-bin statistics, {t['scene']} {size} × {t['bins']} bins at "
                  f"{t['spp']} spp on {t['variant']}: {t['ratio_stats_vs_plain']:.2f}× a plain "
                  f"render's {t['plain_s']:.3f} s with storing, "
                  f"{t['ratio_stats_nocache_vs_plain']:.2f}× with the cache off, "
                  f"{t['ratio_stats_cached_vs_plain']:.2f}× read back (target "
                  f"{t['target_ratio']:.2f}×)"
                  + (f"; as the first call of a fresh process {t['ratio_first_stats_vs_plain']:.2f}×"
                     f" a plain render's {t['first_plain_s']:.3f} s" if "first_plain_s" in t
                     else "") + "."]
    return "\n".join(lines)


def result_path(result: dict[str, Any], root: str | Path = "results/gpu") -> Path:
    """``results/gpu/<device name>.json``, the name reduced to letters, digits and dashes."""
    slug = re.sub(r"[^A-Za-z0-9]+", "-", result["device_name"]).strip("-").lower()
    return Path(root) / f"{slug or 'gpu'}.json"


def write_result(result: dict[str, Any], path: str | Path) -> None:
    from ..io import write_text
    write_text(Path(path), json.dumps(result, indent=1, default=str) + "\n")


__all__ = ["OIDN_OWN_MS", "RENDER_TARGET", "TARGETS_MS", "TRANSIENT_RENDERS", "TRANSIENT_SIZE",
           "TRANSIENT_TARGET_MS", "bench_gpu", "bench_method_device", "compare",
           "count_device_work", "device_run", "synthetic_frame", "transient_render_rows",
           "transient_video", "markdown", "result_path", "write_result"]
