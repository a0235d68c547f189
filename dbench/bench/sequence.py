"""Running a method over a :class:`~dbench.data.Sequence`: per-frame metrics, the mean after a
warm-up, temporal stability, plots, strip comparisons and the 720p speed benchmark.

* :func:`run_sequence` — ``reset()`` then ``denoise(frame)`` for every frame in order; per-frame
  time (``time.perf_counter`` around each call; rendering excluded) and metrics against the
  frame's reference.
* Summary (:class:`SequenceResult.summary`): mean of every metric over frames ≥ ``warmup``
  (default 8, the history-filling "slow start" of spec/svgf.md §8 is excluded), median time per
  frame after the warm-up, and temporal stability (:func:`temporal_stability`).
* Temporal stability (like noisebase's tPSNR): the error of the frame-to-frame differences
  against the reference's, ``d_i = out_i − out_{i−1}`` vs ``r_i = ref_i − ref_{i−1}``:
  ``t_rmse`` on linear values, and ``tpsnr`` = PSNR of the tone-mapped differences
  ``T(out_i) − T(out_{i−1})`` vs ``T(ref_i) − T(ref_{i−1})`` (peak 1, T = dbench tone map),
  both over frames i ≥ max(warmup, 1); ``cvvdp``, ColorVideoVDP's JOD of the frames after the
  warm-up (dbench/metrics/video_quality.py), on small sequences unless asked for.
* :func:`plot_errors`, :func:`strip` — matplotlib figures; :func:`benchmark` — per-frame time at
  1280×720 on a synthetic moving sequence; :func:`main` writes results/temporal figures.

Example:
    >>> from dbench.bench.sequence import synthetic_sequence, run_sequence
    >>> seq = synthetic_sequence(16, 24, frames=10)
    >>> res = run_sequence("accumulate", seq)
    >>> {"mean_rmse", "mean_ssim", "mean_rmse_surface"} <= set(res.summary), len(res.per_frame)
    (True, 10)
"""
from __future__ import annotations

import statistics
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable

import numpy as np

from .. import metrics
from ..data import Frame, Sequence
from ..device import download, timed, upload
from ..errors import DbenchInputError
from ..metrics import video_quality
from . import fpenv
from .inputs import check_unchanged, input_guard, private_copy

WARMUP = 8
SEQUENCE_METRICS = ("rmse", "ssim")
TEMPORAL_METHODS = ("noisy", "accumulate", "svgf", "asvgf", "bmfr")


@dataclass
class SequenceResult:
    """Outcome of one method on one sequence.

    Attributes:
        method, params: the method's name and parameters.
        per_frame: list of dicts ``{"frame", "time_s", <metric>: value}``, one per frame.
        summary: ``mean_<metric>`` after the warm-up, ``median_time_s``, ``t_rmse``, ``tpsnr``,
            ``warmup``, ``frames``.
        outputs: the denoised frames (H, W, 3) float32 when kept, else None.
    """

    method: str
    params: dict[str, Any]
    per_frame: list[dict[str, float]]
    summary: dict[str, float] = field(default_factory=dict)
    outputs: list[np.ndarray] | None = None
    #: the judgements of the frames after the warm-up (intervals resample their pixel blocks)
    judgements: list[Any] = field(default_factory=list)

    def series(self, metric: str) -> np.ndarray:
        return np.array([r.get(metric, np.nan) for r in self.per_frame], np.float64)


def _method(method) -> Any:
    if isinstance(method, str):
        from .. import methods
        return methods.get(method)
    return method


def temporal_stability(outputs: list[np.ndarray], references: list[np.ndarray],
                       warmup: int = WARMUP, ev: float = 0.0) -> dict[str, float]:
    """``t_rmse`` (linear) and ``tpsnr`` (tone-mapped, dB) of the frame-to-frame differences of
    ``outputs`` against those of ``references`` over frames i ≥ max(warmup, 1); NaN when there
    are fewer than two frames or any output is non-finite."""
    start = max(int(warmup), 1)
    if len(outputs) != len(references):
        raise DbenchInputError(f"outputs: expected {len(references)} frames, got {len(outputs)}")
    if len(outputs) <= start:
        return {"t_rmse": float("nan"), "tpsnr": float("nan")}
    if not all(np.isfinite(o).all() for o in outputs[start - 1:]):
        return {"t_rmse": float("nan"), "tpsnr": float("nan")}
    se_lin, se_ldr, count = 0.0, 0.0, 0
    tm_prev_o = metrics.tonemap(outputs[start - 1], ev)
    tm_prev_r = metrics.tonemap(references[start - 1], ev)
    for i in range(start, len(outputs)):
        do = np.asarray(outputs[i], np.float64) - np.asarray(outputs[i - 1], np.float64)
        dr = np.asarray(references[i], np.float64) - np.asarray(references[i - 1], np.float64)
        se_lin += float(((do - dr) ** 2).sum())
        tm_o, tm_r = metrics.tonemap(outputs[i], ev), metrics.tonemap(references[i], ev)
        se_ldr += float((((tm_o - tm_prev_o) - (tm_r - tm_prev_r)) ** 2).sum())
        tm_prev_o, tm_prev_r = tm_o, tm_r
        count += do.size
    mse_ldr = se_ldr / count
    return {"t_rmse": float(np.sqrt(se_lin / count)),
            "tpsnr": float(min(100.0, 10 * np.log10(1.0 / mse_ldr)) if mse_ldr > 0 else 100.0)}


def run_sequence(method, seq: Sequence, metric_names: Iterable[str] = SEQUENCE_METRICS,
                 warmup: int = WARMUP, keep_outputs: bool = False,
                 device: str = "cpu", cvvdp: bool | None = None) -> SequenceResult:
    """Run ``method`` (name or Denoiser) over ``seq`` in order and score every frame.

    ``cvvdp``: score the frames after the warm-up with ColorVideoVDP (summary ``cvvdp``, JOD;
    dbench/metrics/video_quality.py) at ``seq.meta["fps"]`` (default 30); None: only when
    scored frames × pixels is at most 24 × 128² (README.md, "Metrics").

    With ``device="cuda"`` and a method with a device path, every frame is uploaded before its
    call and the output downloaded after it, those copies timed apart (the summary's
    ``transfer_s``, the median per frame), the call itself timed with the device synchronised.

    A temporal method is reset once and keeps its history; a steady (single-frame) method is
    reset before every frame (:meth:`dbench.registry.Denoiser.per_frame`). Frames without a
    reference get times but no metrics. Returns a :class:`SequenceResult`.
    """
    m = _method(method)
    if not isinstance(seq, Sequence):
        raise DbenchInputError(f"seq: expected a dbench.data.Sequence, got {type(seq).__name__}")
    from ..data import BUFFER_NAMES
    available = {b for b in BUFFER_NAMES if seq.has(b)}
    ok, why = m.applies_to("sequence", available)
    if not ok:
        raise DbenchInputError(f"{m.name}: cannot run on this sequence: {why}")
    names = list(metric_names)
    ev = seq.meta.get("ev", seq[0].meta.get("ev", 0.0))
    from .scoring import judge_frame

    m.reset()
    rows, outs, judgements = [], [], []
    stateless = m.per_frame("sequence")  # a steady method: every frame alone
    on_device = device != "cpu" and m.runs_on_device()
    transfers = []
    mine = private_copy(seq)  # read-only; compared with seq after the run (bench/inputs.py)
    for i, frame in enumerate(seq):
        given = mine[i]
        if stateless:
            m.reset()
        with input_guard(m.name):
            if on_device:
                data, up_s = timed(lambda: upload(given, device, m.wants(available)), device)
                out, dt = timed(lambda: fpenv.denoise_device(m, data), device)
                out, down_s = timed(lambda: download(out), device)
                transfers.append(up_s + down_s)
            else:
                t0 = time.perf_counter()
                out = fpenv.denoise(m, given)
                dt = time.perf_counter() - t0
        out = np.asarray(out)
        if out.shape != frame.color.shape:
            raise DbenchInputError(f"{m.name} output: expected shape {frame.color.shape}, "
                                   f"got {out.shape}")
        row: dict[str, float] = {"frame": i, "time_s": dt}
        if frame.reference is not None:
            j = judge_frame(out, frame, names)
            row.update(j.values)
            judgements.append(j)
        rows.append(row)
        outs.append(out.astype(np.float32))
    check_unchanged(m.name, mine, seq)
    res = SequenceResult(m.name, dict(m.params), rows, outputs=outs if keep_outputs else None,
                         judgements=judgements[warmup:] if len(judgements) > warmup
                         else judgements)
    after = rows[warmup:] if len(rows) > warmup else rows
    summary: dict[str, float] = {"warmup": int(warmup), "frames": len(rows)}
    scored = [k for k in (rows[0] if rows else {}) if k not in ("frame", "time_s")]
    for name in dict.fromkeys(list(names) + scored):
        vals = [r[name] for r in after if name in r]
        summary[f"mean_{name}"] = float(np.mean(vals)) if vals else float("nan")
    summary["median_time_s"] = float(statistics.median(r["time_s"] for r in after))
    if transfers:
        summary["transfer_s"] = float(statistics.median(transfers))
    if seq.has("reference"):
        refs = [f.reference for f in seq]
        summary.update(temporal_stability(outs, refs, warmup, ev))
        summary.update(video_quality.sequence_cvvdp(
            outs, refs, warmup, ev, seq.meta.get("fps", video_quality.DEFAULT_FPS), cvvdp))
    res.summary = summary
    return res


def compare(seq: Sequence, method_names: Iterable[str] = TEMPORAL_METHODS,
            params: dict[str, dict] | None = None, warmup: int = WARMUP,
            keep_outputs: bool = True) -> dict[str, SequenceResult]:
    """Run several methods on one sequence; returns {name: SequenceResult}."""
    from .. import methods

    params = params or {}
    return {n: run_sequence(methods.get(n, **params.get(n, {})), seq, warmup=warmup,
                            keep_outputs=keep_outputs) for n in method_names}


def summary_rows(results: dict[str, SequenceResult], scene: str = "") -> list[dict[str, Any]]:
    return [{"scene": scene, "method": n, **r.summary} for n, r in results.items()]


def window_mean(result: SequenceResult, metric: str, start: int, length: int) -> float:
    """Mean of ``metric`` over frames [start, start + length)."""
    return float(np.nanmean(result.series(metric)[start:start + length]))


# ---------------------------------------------------------------------------------------------
# figures


def plot_errors(results: dict[str, SequenceResult], path: str | Path, metric: str = "rmse",
                warmup: int = WARMUP, title: str = "", events: dict | None = None) -> Path:
    """Error against frame index, one line per method; the warm-up is shaded."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 3.6), dpi=120)
    for name, r in results.items():
        ax.plot(r.series(metric), label=name, lw=1.4)
    ax.axvspan(-0.5, warmup - 0.5, color="0.9", label="warm-up")
    for label, frame in (events or {}).items():
        ax.axvline(frame, color="k", ls=":", lw=1)
        ax.text(frame + 0.3, ax.get_ylim()[1], label, va="top", fontsize=7)
    ax.set_xlabel("frame")
    ax.set_ylabel(metric)
    if metric in ("rmse",):
        ax.set_yscale("log")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7, ncol=3)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path


def strip(seq: Sequence, results: dict[str, SequenceResult], path: str | Path,
          frames: Iterable[int] | None = None, crop: tuple[slice, slice] | None = None,
          title: str = "") -> Path:
    """A labelled grid (PNG): rows = methods and the reference, columns = frames, tone-mapped
    with the metrics' tone map (EV of the scene)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ev = seq.meta.get("ev", 0.0)
    n = len(seq)
    frames = list(frames) if frames is not None else sorted({0, 2, WARMUP, n // 2, n - 1} &
                                                             set(range(n)))
    crop = crop or (slice(None), slice(None))
    rows = []
    for name, r in results.items():
        if r.outputs is None:
            raise DbenchInputError(f"{name}: run with keep_outputs=True to draw a strip")
        rows.append((name, [r.outputs[i][crop] for i in frames]))
    if seq.has("reference"):
        rows.append(("reference", [seq[i].reference[crop] for i in frames]))
    h, w = rows[0][1][0].shape[:2]
    scale = max(1.0, 96 / max(h, w))
    fig, axes = plt.subplots(len(rows), len(frames), squeeze=False, dpi=100,
                             figsize=(len(frames) * w * scale / 100 + 0.9,
                                      len(rows) * h * scale / 100 + 0.5))
    for a, (name, images) in enumerate(rows):
        for b, im in enumerate(images):
            ax = axes[a, b]
            ax.imshow(metrics.tonemap(np.nan_to_num(im), ev), interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            if b == 0:
                ax.set_ylabel(name, fontsize=8)
            if a == 0:
                ax.set_title(f"frame {frames[b]}", fontsize=8)
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout(pad=0.2, rect=(0, 0, 1, 1 - 0.35 / fig.get_figheight()) if title else None)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path


# ---------------------------------------------------------------------------------------------
# synthetic sequences and the speed benchmark


def synthetic_sequence(height: int, width: int, frames: int = 12, shift: int = 2, seed: int = 0
                       ) -> Sequence:
    """A moving synthetic sequence at any size (no renderer): a textured, shaded plane pair seen
    by a camera panning ``shift`` px per frame (integer motion vectors), 1-spp-like noise,
    an exact reference, and a gradient buffer equal to the previous frame's colour (what
    re-shading the previous samples under an unchanged light gives)."""
    rng = np.random.default_rng(seed)
    total_w = width + shift * frames
    y, x = np.mgrid[0:height, 0:total_w].astype(np.float32)
    clean = 0.5 + 0.4 * np.sin(x / 37.0)[..., None] * np.cos(y / 23.0)[..., None]
    clean = np.repeat(clean, 3, axis=2) * np.array([1.0, 0.8, 0.6], np.float32)
    clean[:, total_w // 2:] *= 0.3
    albedo = np.where(((x // 16 + y // 16) % 2)[..., None] > 0, 0.8, 0.3) * np.ones(3, np.float32)
    normal = np.zeros((height, total_w, 3), np.float32)
    normal[..., 2] = 1.0
    normal[height // 2:] = (0.0, 1.0, 0.0)
    depth = np.where(np.arange(height)[:, None] < height // 2, 2.0, 2.5) * np.ones((1, total_w))
    position = np.dstack([x / 100, y / 100, depth]).astype(np.float32)
    radiance = clean * albedo
    noise = rng.exponential(1.0, (frames, height, total_w)).astype(np.float32)
    out = []
    prev = None
    for i in range(frames):
        sl = (slice(None), slice(i * shift, i * shift + width))
        color = radiance[sl] * noise[i][sl][..., None]
        grad = color if prev is None else prev  # static light: re-shading = previous frame
        prev = color
        motion = np.zeros((height, width, 2), np.float32)
        motion[..., 0] = shift if i > 0 else 0.0
        out.append(Frame(color=color, albedo=albedo[sl], normal=normal[sl],
                         depth=depth[sl][..., None], position=position[sl],
                         reference=radiance[sl], motion=motion, gradient=grad,
                         meta={"frame": i}))
    return Sequence(out, meta={"scene": "synthetic", "ev": 0.0})


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

    from .. import methods
    from .machine import machine_info

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
        _bench_methods(out, seq, method_names, params, methods, resource)
    finally:
        if old_threads is not None:
            import numba
            numba.set_num_threads(old_threads)
    out["load_after"] = os.getloadavg()[0]
    return out


def _bench_methods(out, seq, method_names, params, methods, resource) -> None:
    for name in method_names:
        m = methods.get(name, **params.get(name, {}))
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


# ---------------------------------------------------------------------------------------------
# results/temporal figures


def quality_run(scene: str, res: int = 64, frames: int | None = None, spp: int = 1,
                ref_spp: int = 1024, seed: int = 0, method_names=TEMPORAL_METHODS,
                cache=None, progress: bool = True) -> tuple[Sequence, dict[str, SequenceResult]]:
    from .. import datasets

    seq = datasets.load(scene, spp=spp, res=res, frames=frames, ref_spp=ref_spp, seed=seed,
                        cache=cache, progress=progress)
    return seq, compare(seq, method_names)


def main(argv: list[str] | None = None) -> int:
    """``python -m dbench.bench.sequence [--res 64] [--frames 48] [--ref-spp 1024] [--out DIR]
    [--speed]``: quality figures (tables, error plots, strips) for orbit, flicker and mirror-pan,
    and optionally the 720p speed benchmark; writes JSON + PNG under ``--out``."""
    import argparse

    ap = argparse.ArgumentParser(prog="python -m dbench.bench.sequence")
    ap.add_argument("--scenes", default="orbit,flicker,mirror-pan")
    ap.add_argument("--res", type=int, default=64)
    ap.add_argument("--frames", type=int, default=None)
    ap.add_argument("--ref-spp", type=int, default=1024)
    ap.add_argument("--out", default="results/temporal")
    ap.add_argument("--speed", action="store_true")
    ap.add_argument("--no-quality", action="store_true")
    ap.add_argument("--repeats", type=int, default=6)
    ap.add_argument("--threads", default="2,1", help="Numba thread counts to time, e.g. 2,1")
    a = ap.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    if not a.no_quality:
        for scene in [s for s in a.scenes.split(",") if s]:
            seq, results = quality_run(scene, a.res, a.frames, ref_spp=a.ref_spp)
            events = seq.meta.get("events", {})
            rows += summary_rows(results, scene)
            if "light_change" in events:
                k = events["light_change"]
                for n, r in results.items():
                    rows[-len(results) + list(results).index(n)]["rmse_after_change_5"] = \
                        window_mean(r, "rmse", k, 5)
            plot_errors(results, out / f"{scene}_rmse.png", "rmse",
                        title=f"{scene}, {a.res}², 1 spp, reference {a.ref_spp} spp",
                        events=events)
            plot_errors(results, out / f"{scene}_ssim.png", "ssim", title=f"{scene} SSIM",
                        events=events)
            frames = sorted({1, WARMUP, len(seq) // 2, len(seq) - 1}
                            | ({events["light_change"], events["light_change"] + 2}
                               if "light_change" in events else set()))
            c = min(a.res, 96)  # a central crop keeps the PNG small at high resolution
            o = (a.res - c) // 2
            strip(seq, results, out / f"{scene}_strip.png", frames=frames,
                  crop=(slice(o, o + c), slice(o, o + c)),
                  title=f"{scene}, {a.res}² (central {c}² crop), 1 spp; rows: methods, reference")
            print(f"{scene}: " + ", ".join(f"{n} {r.summary['mean_rmse']:.4f}"
                                           for n, r in results.items()), flush=True)
        from ..io import write_json
        write_json(out / "quality.json", rows)
    if a.speed:
        from ..io import write_json
        runs = [benchmark(repeats=a.repeats, threads=int(t)) for t in a.threads.split(",") if t]
        for res in runs:
            print(f"threads={res.get('threads')} load {res['load_before']:.1f}->"
                  f"{res['load_after']:.1f}: " + ", ".join(
                      f"{n} {v['median_ms']:.0f} ms (min {v['min_ms']:.0f}, cpu {v['cpu_ms']:.0f})"
                      for n, v in res["methods"].items()), flush=True)
        write_json(out / "speed.json", runs)
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
