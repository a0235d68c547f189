"""What ColorVideoVDP costs against the other metrics of a sequence, on the same frames
(README.md, "Metrics").

:func:`bench_video_metrics` times, on one synthetic moving sequence of (T, H, W, 3) linear
frames and a noisy output of it, each metric over the whole sequence: ``rmse``, ``ssim`` and
``flip`` summed over the frames (``dbench.metrics.compute``, as a sequence cell scores them frame
by frame), the temporal stability (``t_rmse`` with ``tpsnr``, one pass:
:func:`dbench.run.sequence_run.temporal_stability`) and ``cvvdp``
(:func:`dbench.metrics.video_quality.cvvdp_jod`). The metrics run in interleaved rounds
(:func:`dbench.speed.timing.interleaved_times`) so a slow spell of the machine falls on all of
them alike; each figure is the median over the rounds, and the ratio is to ``rmse``.

    dbench bench video-metrics [--res 64] [--repeats 3] [--out results/bench_metrics.jsonl]
"""
from __future__ import annotations

import statistics
import time
from typing import Any

import numpy as np

from ..run.machine import machine_info
from .timing import interleaved_times


def _sequence(frames: int, height: int, width: int) -> tuple[np.ndarray, np.ndarray]:
    """A drifting textured reference and an output with Monte Carlo-like noise (seeded)."""
    rng = np.random.default_rng(0)
    texture = rng.gamma(2.0, 0.3, (height, width + frames, 3))
    ref = np.stack([texture[:, t:t + width] for t in range(frames)])
    out = np.maximum(ref + rng.normal(0.0, 0.05, ref.shape) * np.sqrt(ref), 0.0)
    return out, ref


def bench_video_metrics(frames: int = 24, height: int = 64, width: int = 64,
                        repeats: int = 3) -> dict[str, Any]:
    """Seconds per sequence of each metric (median of ``repeats`` interleaved rounds after one
    warm-up round) and each one's ratio to ``rmse``; CPU."""
    from .. import metrics
    from ..metrics.video_quality import DEFAULT_FPS, cvvdp_jod
    from ..run.sequence_run import temporal_stability

    out, ref = _sequence(frames, height, width)
    outs, refs = list(out), list(ref)

    def per_frame(name):
        return lambda: [metrics.compute(name, o, r) for o, r in zip(outs, refs)]

    fns = {"rmse": per_frame("rmse"), "ssim": per_frame("ssim"), "flip": per_frame("flip"),
           "t_rmse+tpsnr": lambda: temporal_stability(outs, refs, warmup=0),
           "cvvdp": lambda: cvvdp_jod(out, ref, fps=DEFAULT_FPS)}
    times = interleaved_times(list(fns.values()), repeats)
    seconds = {k: statistics.median(t) for k, t in zip(fns, times)}
    return {"benchmark": "video-metrics", "frames": frames, "height": height, "width": width,
            "rounds": repeats, "seconds": seconds,
            "ratio_vs_rmse": {k: v / seconds["rmse"] for k, v in seconds.items()},
            "device": "cpu", "machine": machine_info()["cpu"],
            "when": time.strftime("%Y-%m-%d %H:%M:%S")}


def format_result(result: dict[str, Any]) -> str:
    lines = [f"metric cost per sequence, {result['frames']} frames of {result['width']}x"
             f"{result['height']} px, CPU ({result['machine']}; median of {result['rounds']} "
             f"interleaved rounds):"]
    for name, s in result["seconds"].items():
        lines.append(f"  {name:<14} {s * 1e3:10.1f} ms  ({result['ratio_vs_rmse'][name]:8.1f}x "
                     f"rmse)")
    return "\n".join(lines)
