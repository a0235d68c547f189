"""Speed of the statistical denoiser's fast path against its reference (prints; not a test).

    python -m dbench.methods.statistical.bench           # 1280×720, radius 20
    python -m dbench.methods.statistical.bench --torch   # also the PyTorch path (CPU or CUDA)

Times are medians of ``repeats`` runs after one warm-up call (which also compiles Numba). The
reference is timed on a crop and scaled per pixel (its cost is linear in the pixel count).
"""
from __future__ import annotations

import argparse
import statistics
import time
from typing import Any, Callable

import numpy as np

from ...data import SampleStats
from ..jbf.bench import synthetic_frame
from ..jbf.core import make_guide
from .core import resolve_threshold, stat_planes, statistical_fast, statistical_reference


def synthetic_stats(height: int, width: int, spp: int = 64, seed: int = 1,
                    zero_frac: float = 0.05) -> tuple[np.ndarray, SampleStats]:
    """Noisy colour and matching statistics (identity transform) without storing samples:
    θ̂ ~ truth + N(0, σ²/n) with σ = truth, plus a fraction of zero-variance pixels."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:height, 0:width]
    truth = (0.5 + 0.5 * ((xx // 64 + yy // 48) % 3))[..., None] * np.array([1.0, 0.9, 0.7])
    var = truth ** 2 / spp
    zero = rng.random((height, width)) < zero_frac
    var[zero] = 0.0
    mean = truth + rng.normal(size=truth.shape) * np.sqrt(var)
    stats = SampleStats(n=np.full(truth.shape, float(spp)), mean=mean, var_mean=var,
                        m3=np.zeros(truth.shape), transform="identity")
    return mean.astype(np.float32), stats


def _median_time(fn: Callable[[], Any], repeats: int) -> float:
    fn()
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def benchmark(height: int = 720, width: int = 1280, radius: int = 20, repeats: int = 3,
              reference_max_pixels: int = 160 * 90, torch: bool = False) -> dict[str, Any]:
    """Median seconds per frame: Numba fast path, reference (scaled from a crop), speedup.

    Returns:
        dict with ``fast_s``, ``reference_s``, ``reference_crop``, ``speedup`` and, with
        ``torch``, ``torch_s`` (PyTorch path on CUDA if available, else CPU float32).
    """
    f = synthetic_frame(height, width)
    color, stats = synthetic_stats(height, width)
    guide = make_guide(f["albedo"], f["normal"], f["depth"], radius=radius)
    sp = stat_planes(stats, (height, width))
    thr = resolve_threshold(sp.nint)
    fast_s = _median_time(lambda: statistical_fast(color, sp, guide, thr), repeats)
    result: dict[str, Any] = dict(height=height, width=width, radius=radius, fast_s=fast_s)
    if torch:
        result["torch_s"] = _median_time(
            lambda: statistical_fast(color, sp, guide, thr, backend="torch"), repeats)

    ch, cw = height, width
    while ch * cw > reference_max_pixels:
        ch, cw = max(1, ch // 2), max(1, cw // 2)
    cguide = make_guide(f["albedo"][:ch, :cw], f["normal"][:ch, :cw], f["depth"][:ch, :cw],
                        radius=radius)
    csp = stat_planes(SampleStats(n=stats.n[:ch, :cw], mean=stats.mean[:ch, :cw],
                                  var_mean=stats.var_mean[:ch, :cw], m3=stats.m3[:ch, :cw],
                                  transform=stats.transform), (ch, cw))
    ref_crop_s = _median_time(lambda: statistical_reference(color[:ch, :cw], csp, cguide, thr),
                              max(1, repeats // 3))
    ref_s = ref_crop_s * (height * width) / (ch * cw)
    result.update(reference_s=ref_s, reference_crop=(ch, cw), speedup=ref_s / fast_s)
    return result


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--height", type=int, default=720)
    ap.add_argument("--width", type=int, default=1280)
    ap.add_argument("--radius", type=int, default=20)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--torch", action="store_true")
    a = ap.parse_args(argv)
    r = benchmark(a.height, a.width, a.radius, a.repeats, torch=a.torch)
    extra = f", torch {r['torch_s']:.3f} s" if "torch_s" in r else ""
    print(f"statistical {r['width']}x{r['height']} r={r['radius']}: fast {r['fast_s']:.3f} s"
          f"{extra}, reference {r['reference_s']:.1f} s (crop {r['reference_crop'][1]}x"
          f"{r['reference_crop'][0]}, scaled), speedup {r['speedup']:.0f}x "
          f"(target ≤ 3 s per frame on 2 cores)")


if __name__ == "__main__":
    main()
