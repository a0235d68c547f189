"""Speed of the statistical denoiser's fast path against its reference (prints; not a test).

    python -m dbench.speed.statistical           # 1280×720, radius 20
    python -m dbench.speed.statistical --torch   # also the PyTorch path (CPU or CUDA)
    python -m dbench.speed.statistical --transient   # 256×256×100 video, r_s 5, r_t 1,
                                                             # and time vs non-empty bins

Times are medians of ``repeats`` runs after one warm-up call (which also compiles Numba). The
reference is timed on a crop and scaled per pixel (its cost is linear in the pixel count).
Transient timings also report the process CPU time (all threads): on a shared machine the wall
time grows with the load, the CPU time much less; CPU time / threads is the wall time the run
would take with the cores to itself.
"""
from __future__ import annotations

import argparse
import statistics
import time
from typing import Any, Callable

import numpy as np

from ..data import SampleStats
from ..methods.kernels.bilateral.guide import make_guide
from ..methods.statistical.fast import statistical_fast
from ..methods.statistical.params import resolve_threshold
from ..methods.statistical.reference import stat_planes, statistical_reference
from ..run import fpenv
from .timing import median_time, reference_crop
from ..synthetic import synthetic_frame


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


def _median_wall_cpu(fn: Callable[[], Any], repeats: int, warmup: bool = True):
    """Median wall seconds and median process CPU seconds (all threads) of ``repeats`` calls."""
    if warmup:
        fn()
    walls, cpus = [], []
    for _ in range(repeats):
        c, t = time.process_time(), time.perf_counter()
        fn()
        walls.append(time.perf_counter() - t)
        cpus.append(time.process_time() - c)
    return statistics.median(walls), statistics.median(cpus)


def synthetic_video(height: int, width: int, bins: int, nonempty: int, spp: int = 64,
                    seed: int = 2, zero_frac: float = 0.3, first: int | None = None):
    """Colour and identity statistics of a video whose bins ``first``..``first+nonempty−1`` hold
    energy (the others are exactly 0, as bins before the first arrival): a wavefront-like
    pattern, θ̂ ~ truth + N(0, σ²/n) with σ = truth, and ``zero_frac`` voxels no path reached
    (0, variance 0). Built bin by bin without storing samples."""
    rng = np.random.default_rng(seed)
    first = max(0, min(bins - nonempty, bins // 10)) if first is None else first
    yy, xx = np.mgrid[0:height, 0:width]
    mean = np.zeros((height, width, bins, 3))
    var = np.zeros((height, width, bins, 3))
    tint = np.array([1.0, 0.9, 0.7])
    for t in range(first, first + nonempty):
        r = np.hypot(yy - height / 2, xx - width / 3)
        front = np.exp(-0.5 * ((r - 3.0 * (t - first)) / 6.0) ** 2) + 0.05
        truth = front[..., None] * tint
        v = truth ** 2 / spp
        reached = rng.random((height, width, 1)) >= zero_frac
        mean[:, :, t] = np.where(reached, truth + rng.normal(size=truth.shape) * np.sqrt(v), 0.0)
        var[:, :, t] = np.where(reached, v, 0.0)
    stats = SampleStats(n=float(spp), mean=mean, var_mean=var, m3=np.zeros_like(mean),
                        transform="identity")
    return mean.astype(np.float32), stats


def benchmark_transient(height: int = 256, width: int = 256, bins: int = 100, radius: int = 5,
                        radius_t: int = 1, nonempty_fraction: float = 1.0, repeats: int = 3,
                        reference_max_voxels: int = 24 * 24 * 100, base: str = "jbf",
                        threads: int | None = None, method_too: bool = False) -> dict[str, Any]:
    """Median seconds per video of the spatio-temporal statistical denoiser (docs/methods/statistical.md §11.3).

    The whole public call is timed (:func:`~dbench.methods.statistical.transient.statistical_filter_video`:
    empty-bin detection, the one-pass preparation of the statistics, the 3D kernel, the
    normalisation), with ``round(nonempty_fraction·bins)`` non-empty bins. The reference is
    timed on a crop of at most ``reference_max_voxels`` voxels (same bins) and scaled per voxel.

    Returns:
        dict with ``fast_s`` (wall), ``fast_cpu_s`` (process CPU, all threads), ``threads``,
        ``nonempty_bins``, ``bins_in_play``, ``voxels``, ``reference_s`` (scaled),
        ``reference_crop``, ``speedup``; with ``method_too`` also ``method_s`` (the registered
        method, pixel-total rule included) and ``seed_rule_s`` (the seed's rule) of the same
        run.
    """
    import numba

    from ..synthetic import synthetic_frame
    from ..methods.statistical.transient import statistical_filter_video

    if threads is not None:
        numba.set_num_threads(int(threads))
    nonempty = int(round(nonempty_fraction * bins))
    f = synthetic_frame(height, width)
    color, stats = synthetic_video(height, width, bins, nonempty)
    kw = dict(radius=radius, radius_t=radius_t, base=base)

    def fast():
        return statistical_filter_video(color, stats, f["albedo"], f["normal"], f["depth"], **kw)

    _, info = statistical_filter_video(color, stats, f["albedo"], f["normal"], f["depth"],
                                       return_info=True, **kw)
    wall, cpu = _median_wall_cpu(fast, repeats)
    result: dict[str, Any] = dict(height=height, width=width, bins=bins, radius=radius,
                                  radius_t=radius_t, base=base, nonempty_bins=nonempty,
                                  bins_in_play=info["bins_in_play"], voxels=height * width * bins,
                                  window_voxels=info["window_voxels"], fast_s=wall,
                                  fast_cpu_s=cpu, threads=numba.get_num_threads())
    if method_too:
        # the registered method as a sweep calls it: the filter plus the pixel-total rule
        # (a total variance per pixel), and the seed's rule (no shrinkage, no pixel-total rule,
        # γ 0.05) in the same run, so the ratio between them is machine-independent
        from ..data import TransientFrame
        from ..registry import get

        frame = TransientFrame(color=color, stats=stats, albedo=f["albedo"], normal=f["normal"],
                               depth=f["depth"],
                               total_var=np.asarray(stats.var_mean).sum(axis=2))
        method_params = dict(radius=radius, radius_t=radius_t, base=base)
        for key, extra in (("method_s", {}),
                           ("seed_rule_s", dict(shrink=False, mass=False, gamma=0.05))):
            method = get("statistical", **method_params, **extra)
            result[key] = _median_wall_cpu(lambda: fpenv.denoise(method, frame), repeats)[0]
    if reference_max_voxels and nonempty:
        ch, cw = height, width
        while ch * cw * bins > reference_max_voxels and ch * cw > 1:
            ch, cw = max(1, ch // 2), max(1, cw // 2)
        csub = SampleStats(n=stats.n[:ch, :cw], mean=stats.mean[:ch, :cw],
                           var_mean=stats.var_mean[:ch, :cw], m3=stats.m3[:ch, :cw],
                           transform=stats.transform)
        ref_crop_s = median_time(lambda: statistical_filter_video(
            color[:ch, :cw], csub, f["albedo"][:ch, :cw], f["normal"][:ch, :cw],
            f["depth"][:ch, :cw], backend="reference", **kw), 1)
        ref_s = ref_crop_s * (height * width) / (ch * cw)
        result.update(reference_s=ref_s, reference_crop=(ch, cw, bins), speedup=ref_s / wall)
    return result


def time_vs_nonempty_bins(height: int = 256, width: int = 256, bins: int = 100,
                          counts: tuple[int, ...] = (0, 10, 25, 50, 75, 100), radius: int = 5,
                          radius_t: int = 1, repeats: int = 3) -> list[dict[str, Any]]:
    """:func:`benchmark_transient` for several numbers of non-empty bins (no reference), plus a
    least-squares line CPU s = a + b·(bins in play) in the first row's ``fit``."""
    rows = [benchmark_transient(height, width, bins, radius, radius_t, c / bins, repeats,
                                reference_max_voxels=0) for c in counts]
    x = np.array([r["bins_in_play"] for r in rows], float)
    y = np.array([r["fast_cpu_s"] for r in rows], float)
    if len(rows) >= 2 and np.ptp(x) > 0:
        b, a = np.polyfit(x, y, 1)
        resid = y - (a + b * x)
        r2 = 1.0 - float(np.sum(resid ** 2) / max(np.sum((y - y.mean()) ** 2), 1e-300))
        rows[0]["fit"] = dict(intercept_cpu_s=float(a), cpu_s_per_bin=float(b), r2=r2)
    return rows


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
    fast_s = median_time(lambda: statistical_fast(color, sp, guide, thr), repeats)
    result: dict[str, Any] = dict(height=height, width=width, radius=radius, fast_s=fast_s)
    if torch:
        result["torch_s"] = median_time(
            lambda: statistical_fast(color, sp, guide, thr, backend="torch"), repeats)

    ch, cw = reference_crop(height, width, reference_max_pixels)
    cguide = make_guide(f["albedo"][:ch, :cw], f["normal"][:ch, :cw], f["depth"][:ch, :cw],
                        radius=radius)
    csp = stat_planes(SampleStats(n=stats.n[:ch, :cw], mean=stats.mean[:ch, :cw],
                                  var_mean=stats.var_mean[:ch, :cw], m3=stats.m3[:ch, :cw],
                                  transform=stats.transform), (ch, cw))
    ref_crop_s = median_time(lambda: statistical_reference(color[:ch, :cw], csp, cguide, thr),
                              max(1, repeats // 3))
    ref_s = ref_crop_s * (height * width) / (ch * cw)
    result.update(reference_s=ref_s, reference_crop=(ch, cw), speedup=ref_s / fast_s)
    return result


# ---------------------------------------------------------------------------------------------
# Rendered transient scenes: end-to-end comparison and the temporal-radius study
# ---------------------------------------------------------------------------------------------

#: (label, registered method or None for the noisy input, parameters) of :func:`end_to_end`.
E2E_METHODS: tuple[tuple[str, str | None, dict], ...] = (
    ("noisy", None, {}),
    ("statistical", "statistical", {}),
    ("statistical (membership off = JBF 3D)", "statistical", dict(membership=False)),
    ("jbf-bins (per-bin JBF, r 20)", "jbf-bins", {}),
    ("jbf-bins 3D (r_s 5, r_t 1)", "jbf-bins", dict(radius=5, temporal_radius=1)),
    ("oidn-bins", "oidn-bins", {}),
    ("gauss3d", "gauss3d", {}),
    ("statistical gauss3d base", "statistical", dict(base="gauss3d")),
    ("statistical jbf base", "statistical", dict(base="jbf")),
    ("statistical gamma 0.1", "statistical", dict(gamma=0.1)),
    ("statistical r_t 0", "statistical", dict(radius_t=0)),
)


def light_mask(reference: np.ndarray, threshold: float = 1.0, dilate: int = 2) -> np.ndarray:
    """(H, W) bool: pixels that see the light source, i.e. whose time-integrated reference
    exceeds ``threshold`` in some channel, dilated by ``dilate`` pixels (their partly covered
    neighbours). Used for the "without light" RMSE of the reports."""
    from scipy.ndimage import binary_dilation

    m = np.asarray(reference, np.float64).sum(axis=2).max(-1) > threshold
    return binary_dilation(m, iterations=dilate) if dilate and m.any() else m


def _rmse(out: np.ndarray, ref: np.ndarray, exclude: np.ndarray | None = None) -> float:
    err = (np.asarray(out, np.float64) - ref) ** 2
    if exclude is not None:
        err = err[~exclude]
    return float(np.sqrt(np.mean(err)))


def end_to_end(scene: str = "cornell-transient", res: int = 64,
               spp_list: tuple[int, ...] = (128, 256, 512), bins: int | None = None,
               methods=E2E_METHODS) -> list[dict[str, Any]]:
    """Whole-video RMSE (linear, every voxel, against the dataset's reference video) of the
    noisy input and of each method, per spp; also without the light pixels (:func:`light_mask`).

    Renders through :func:`dbench.datasets.load` (cached; set DBENCH_CACHE). Methods that are not
    registered are skipped.
    """
    from .. import datasets  # noqa: F401  (the catalogue; dbench.registry registers the methods)
    from ..registry import available, get

    rows = []
    for spp in spp_list:
        t0 = time.perf_counter()
        v = datasets.load(scene, spp=int(spp), res=int(res), bins=bins, progress=False)
        load_s = time.perf_counter() - t0
        ref = v.reference.astype(np.float64)
        light = light_mask(ref)
        for label, name, params in methods:
            if name is not None and name not in available():
                continue
            t = time.perf_counter()
            if name is None:
                out, settings = v.color, None
            else:
                m = get(name, **params)
                out = fpenv.denoise(m, v)
                settings = getattr(m, "last_settings", None)
            row = dict(scene=scene, res=int(res), spp=int(spp), bins=v.bins,
                       bin_width_opl=v.bin_width_opl, method=label, rmse=_rmse(out, ref),
                       rmse_nolight=_rmse(out, ref, light), light_px=int(light.sum()),
                       seconds=time.perf_counter() - t, load_s=load_s,
                       ref_spp=v.meta.get("ref_spp"), transform=v.stats.transform)
            if name == "statistical" and settings:
                row["settings"] = {k: settings[k] for k in (
                    "base", "radius", "radius_t", "gamma_t", "temporal_profile",
                    "nonempty_bins", "bins_in_play")}
            rows.append(row)
    return rows


def radius_t_study(scene: str = "cornell-transient", res: int = 64, spp: int = 256,
                   bins_list: tuple[int, ...] = (31, 100, 200, 308, 400, 3080),
                   radii: tuple[int, ...] = (0, 1, 2, 3),
                   profiles: tuple[str, ...] = ("box", "gaussian")) -> list[dict[str, Any]]:
    """Whole-video RMSE of ``statistical`` (r_s = 5, γ = 0.05, jbf base) relative to the noisy
    input for each temporal radius, temporal profile and number of bins over the scene's fixed
    window (so the bin width changes): the seed's study of r_t against bin width (docs/methods/statistical.md §11.3,
    [S000 Fig. 5.4-5.5]; its 8 / 83 / 833 ps ≈ 3080 / 308 / 31 bins of cornell-transient)."""
    from .. import datasets
    from ..methods.statistical.transient import statistical_filter_video

    rows = []
    for bins in bins_list:
        v = datasets.load(scene, spp=int(spp), res=int(res), bins=int(bins), progress=False)
        ref = v.reference.astype(np.float64)
        light = light_mask(ref)
        noisy, noisy_nl = _rmse(v.color, ref), _rmse(v.color, ref, light)
        base = dict(scene=scene, res=int(res), spp=int(spp), bins=int(bins),
                    bin_width_opl=v.bin_width_opl,
                    bin_width_ps=v.bin_width_opl / 299792458.0 * 1e12, noisy=noisy,
                    noisy_nolight=noisy_nl, light_px=int(light.sum()),
                    nonempty=int(np.any(v.color != 0, axis=(0, 1, 3)).sum()))
        for rt in radii:
            for prof in profiles:
                if rt == 0 and prof != profiles[0]:
                    continue
                t = time.perf_counter()
                out = statistical_filter_video(v.color, v.stats, v.albedo, v.normal, v.depth,
                                               radius=5, radius_t=rt, temporal_profile=prof)
                r, rnl = _rmse(out, ref), _rmse(out, ref, light)
                rows.append(dict(base, radius_t=rt, profile=prof, rmse=r, ratio=r / noisy,
                                 rmse_nolight=rnl, ratio_nolight=rnl / noisy_nl,
                                 seconds=time.perf_counter() - t))
    return rows


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--height", type=int, default=720)
    ap.add_argument("--width", type=int, default=1280)
    ap.add_argument("--radius", type=int, default=20)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--torch", action="store_true")
    ap.add_argument("--e2e", metavar="JSON", help="run end_to_end on cornell-transient and "
                    "write the rows to JSON (renders; set DBENCH_CACHE)")
    ap.add_argument("--rt-study", metavar="JSON", help="run radius_t_study on cornell-transient "
                    "and write the rows to JSON (renders; set DBENCH_CACHE)")
    ap.add_argument("--transient", action="store_true",
                    help="time the video denoiser (256×256×100, r_s 5, r_t 1) and its cost vs "
                         "the number of non-empty bins instead")
    a = ap.parse_args(argv)
    if a.e2e or a.rt_study:
        import json

        for path, fn in ((a.e2e, end_to_end), (a.rt_study, radius_t_study)):
            if path:
                rows = fn()
                with open(path, "w", encoding="utf-8") as fh:
                    json.dump(rows, fh, indent=1)
                print(f"{len(rows)} rows -> {path}")
        return
    if a.transient:
        r = benchmark_transient(repeats=a.repeats, method_too=True)
        print(f"statistical video {r['width']}x{r['height']}x{r['bins']} r_s={r['radius']} "
              f"r_t={r['radius_t']} ({r['window_voxels']} voxels): {r['fast_s']:.2f} s wall, "
              f"{r['fast_cpu_s']:.2f} s CPU on {r['threads']} threads; reference "
              f"{r['reference_s']:.0f} s (scaled), speedup {r['speedup']:.0f}x; the method "
              f"with its pixel-total rule {r['method_s']:.2f} s, the seed's rule "
              f"{r['seed_rule_s']:.2f} s (target ≤ 2.5 s on 2 cores)")
        for row in time_vs_nonempty_bins(repeats=a.repeats):
            print(f"  non-empty {row['nonempty_bins']:4d} (in play {row['bins_in_play']:4d}): "
                  f"{row['fast_s']:.2f} s wall, {row['fast_cpu_s']:.2f} s CPU")
            if "fit" in row:
                fit = row["fit"]
        print(f"  fit: CPU s = {fit['intercept_cpu_s']:.3f} + {fit['cpu_s_per_bin']:.4f}·bins, "
              f"R² = {fit['r2']:.4f}")
        return
    r = benchmark(a.height, a.width, a.radius, a.repeats, torch=a.torch)
    extra = f", torch {r['torch_s']:.3f} s" if "torch_s" in r else ""
    print(f"statistical {r['width']}x{r['height']} r={r['radius']}: fast {r['fast_s']:.3f} s"
          f"{extra}, reference {r['reference_s']:.1f} s (crop {r['reference_crop'][1]}x"
          f"{r['reference_crop'][0]}, scaled), speedup {r['speedup']:.0f}x "
          f"(target ≤ 3 s per frame on 2 cores)")


if __name__ == "__main__":
    main()
