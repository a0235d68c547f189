"""One benchmark cell: a method run on a dataset, timed, and scored against the reference.

Timing (anchors.md §1): rendering and I/O are excluded; one warm-up call, then the median of
``repeats`` calls measured with ``time.perf_counter``.
"""
from __future__ import annotations

import os
import platform
import statistics
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .. import metrics
from ..errors import DbenchInputError
from ..registry import Denoiser

DEFAULT_METRICS = ("rmse", "relmse", "smape", "psnr", "ssim", "flip")


@dataclass
class CellResult:
    """Outcome of one (method, dataset) cell."""

    method: str
    params: dict[str, Any]
    output: np.ndarray | None
    metrics: dict[str, float] = field(default_factory=dict)
    times_s: list[float] = field(default_factory=list)
    skipped: str = ""
    n_nonfinite: int = 0
    sequence: Any = None  # the SequenceResult of a sequence cell (per-frame rows, outputs)

    @property
    def time_s(self) -> float:
        return statistics.median(self.times_s) if self.times_s else float("nan")


def time_call(fn, repeats: int = 5, warmup: int = 1) -> tuple[Any, list[float]]:
    """Call ``fn()`` ``warmup`` times, then ``repeats`` times; return the last result and times."""
    result = None
    for _ in range(warmup):
        result = fn()
    times = []
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return result, times


def run_cell(method: Denoiser, frame, metric_names=DEFAULT_METRICS, repeats: int = 5,
             warmup: int = 1) -> CellResult:
    """Run ``method`` on ``frame``; skip with a reason when it does not apply."""
    available = {b for b in ("color", "albedo", "normal", "depth", "position", "stats",
                             "reference") if getattr(frame, b, None) is not None}
    ok, reason = method.applies_to(getattr(frame, "kind", "steady"), available)
    if not ok:
        return CellResult(method.name, dict(method.params), None, skipped=reason)

    def call():
        method.reset()
        return method.denoise(frame)

    output, times = time_call(call, repeats=repeats, warmup=warmup)
    output = np.asarray(output)
    if output.shape != frame.color.shape:
        raise DbenchInputError(f"{method.name} output: expected shape {frame.color.shape}, "
                               f"got {output.shape}")
    result = CellResult(method.name, dict(method.params), output.astype(np.float32),
                        times_s=times, n_nonfinite=int((~np.isfinite(output)).sum()))
    if frame.reference is not None:
        result.metrics = metrics.compute_all(output, frame.reference, names=list(metric_names),
                                             ev=frame.meta.get("ev", 0.0))
    return result


def run_sequence_cell(method: Denoiser, seq, metric_names=DEFAULT_METRICS,
                      warmup: int | None = None) -> CellResult:
    """Run a temporal ``method`` over a :class:`~dbench.data.Sequence` (``reset()`` once, then
    every frame in order) and summarise it as one cell.

    A recurrent method cannot be re-run on a frame, so each frame is timed once:
    ``times_s`` are the per-frame times after the warm-up (``time_s`` is their median) and the
    metrics are means over those frames (dbench.bench.sequence, spec/temporal.md §8), plus the
    temporal stability ``t_rmse`` and ``tpsnr``. ``output`` is the last frame's output.
    """
    from ..data import FRAME_BUFFERS
    from .sequence import WARMUP, run_sequence

    warmup = WARMUP if warmup is None else int(warmup)
    available = {b for b in FRAME_BUFFERS if seq.has(b)}
    ok, reason = method.applies_to("sequence", available)
    if not ok:
        return CellResult(method.name, dict(method.params), None, skipped=reason)
    names = list(metric_names)
    run = run_sequence(method, seq, metric_names=names, warmup=warmup, keep_outputs=True)
    after = run.per_frame[warmup:] if len(run.per_frame) > warmup else run.per_frame
    scores = {n: run.summary[f"mean_{n}"] for n in names}
    scores.update({k: run.summary[k] for k in ("t_rmse", "tpsnr") if k in run.summary})
    return CellResult(method.name, dict(method.params), run.outputs[-1], metrics=scores,
                      times_s=[r["time_s"] for r in after],
                      n_nonfinite=int(sum((~np.isfinite(o)).sum() for o in run.outputs)),
                      sequence=run)


def machine_info() -> dict[str, Any]:
    """CPU, core count and package versions, printed in every report."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    from importlib.metadata import PackageNotFoundError, version

    packages = {}
    for pkg in ("dbench", "mitsuba", "drjit", "mitransient", "numpy", "numba", "torch",
                "pyoidn", "flip-evaluator", "scikit-image", "onnxruntime"):
        try:
            packages[pkg] = version(pkg)
        except PackageNotFoundError:
            packages[pkg] = "missing"
    try:
        import torch
        gpu = torch.cuda.get_device_name(0) if torch.cuda.is_available() else "none"
    except Exception:  # noqa: BLE001
        gpu = "unknown"
    return {"cpu": cpu, "cores": os.cpu_count(), "python": platform.python_version(),
            "platform": platform.platform(), "gpu": gpu, "packages": packages}
