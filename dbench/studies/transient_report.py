"""Transient benchmarks and reports: collector timings, per-bin error curves, streak images.

* :func:`bench_collectors`: collector (a) (1-spp passes + host power sums) and collector (b)
  (in-integrator running sums: ``transient_path_stats``, or ``transient_prbvolpath_stats`` for
  participating media) as ratios to one plain render of the scene's integrator at the same spp,
  all measured in the same run, interleaved (median of ``repeats`` after a warm-up).
* :func:`state_bytes_vs_spp`: the statistics state of collector (b) for several spp (constant).
* :func:`video_metrics` / :func:`per_bin_table`: whole-video RMSE and relMSE (linear, every
  voxel), SSIM and PSNR of the time-integrated image (sum over T), and per-bin RMSE curves.
* :func:`plot_error_per_bin`, :func:`plot_bins`, :func:`plot_streak`: the figures (matplotlib,
  PNG): error per bin, a few bins side by side, and an x–t streak image (one image row over time)
  for noisy, denoised and reference.
* :func:`write_figures`: those three figures for one run (usable by ``dbench run`` on transient
  scenes, whose steady comparison grid cannot show a video).
* :func:`run_report`: all of it for the transient scenes, written to ``results/transient.md``
  (``python -m dbench.studies.transient_report``).

The machine these run on may be shared; every ratio is measured within one run, interleaved.
"""
from __future__ import annotations

import os
import statistics
import time
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import pandas as pd

from .. import io, metrics
from ..data import TransientFrame
from ..options import Parser
from ..report.transient_figures import write_figures
from ..run import fpenv
from ..speed.transient_collectors import bench_collectors, state_bytes_vs_spp

DEFAULT_METHODS = ("noisy", "statistical", "jbf-bins", "oidn-bins", "gauss3d")

NOTES = [
    "- Exactness: with the same seeds (1-spp passes, one camera per call) collector (b) gives "
    "bit-identical float64 power sums, `non_zero` counts, colour and moments to collector (a), "
    "for the identity and Box-Cox transforms, also on a corridor scene where next-event "
    "estimation makes paths leave a bin and come back (tests/datasets/test_transient.py). The seed's "
    "Alg. 4 as printed (flush on every bin change, `slots=1`) double-counts those paths there "
    "(`non_zero` can exceed spp).",
    "- Collector (b) keeps 2·max_depth slots per path (an emitter hit and a next-event estimate "
    "per vertex), so it can never run out; `slots < 2·max_depth` frees slots of bins the path "
    "has passed and counts forced early flushes in `n_overflow` (exact iff 0).",
    "- Media (`transient_prbvolpath_stats`, dbench/datasets/transient/collector_media.py): the "
    "primal path of mitransient's `transient_prbvolpath` with the film histogram replaced by the "
    "same slots; volume scatter vertices do next-event estimation too, and a path still adds at "
    "most 2·max_depth contributions (emitter hits at depth 0…max_depth, next-event estimates at "
    "vertices 1…max_depth−1). Emitters on null-BSDF shapes could exceed that: such a "
    "contribution is flushed on its own and counted in `n_overflow` (a guard that costs about "
    "5 % of a plain render). Bit-identical to collector (a) for the same seeds "
    "(tests/datasets/test_transient_media_collector.py).",
    "- Rendering all spp in one call (the default of `load(..., collector='b')`) gives the same "
    "statistics up to the order of the float64 atomic additions; its paths differ from (a)'s "
    "(different sample streams), which is why the cache key holds the collector.",
    "- The transient film works as the film of a Mitsuba `batch` sensor (several cameras per "
    "call), provided each camera keeps its own res×res film (it sets the camera's aspect "
    "ratio; without it a camera silently gets a 768×576 film and another view).",
    "- Measured: Mitsuba's perspective sensor starts camera rays on the near-clip plane, so a "
    "warped OPL misses near_clip/cos θ of the camera segment (0.01 m with the default near "
    "clip). The direct-arrival test scene uses near_clip = 1e-4.",
    "- fog-transient uses `transient_prbvolpath` (collector (b) through "
    "`transient_prbvolpath_stats`). Its G-buffers come from the same camera with the fog "
    "removed (surfaces behind the medium).",
    "- Whole-video RMSE weights every voxel equally: on cornell-transient it is dominated by "
    "the directly visible light in the first bins, which every spatial filter spreads into "
    "its neighbours, and filtering a bin spatially also blurs the wavefront across pixels "
    "(G-buffers say nothing about arrival time); the seed reports the JBF worse than its "
    "input on transient data too (docs/methods/jbf.md §1.5). The per-bin curves and streak images "
    "show where each baseline gains or loses.",
]


#: collector (b)'s sums layouts (dbench/datasets/transient/voxel_sums.py), as the report says them
LAYOUTS = {"packets": "S1, S2, S3 and the `non_zero` count as 4 float64 per voxel and channel "
                      "(the packet layout)",
           "compact": "3 float64 sums per voxel and channel and one uint64 per voxel packing "
                      "the three `non_zero` counts (the compact layout)"}


# ---------------------------------------------------------------------------------------------
# collector timings


def collector_section(scenes: Sequence[str], res: int = 64, spp: int = 64, bins: int = 200,
                      repeats: int = 5, media_res: int = 48, media_bins: int = 100
                      ) -> list[str]:
    """The Markdown lines of the collector benchmark: one row per scene that has collector (b)
    (:func:`bench_collectors`; media scenes at ``media_res``/``media_bins``), and the state size
    against spp for a surface and a media scene."""
    from ..datasets.scenes import catalogue
    from ..datasets.transient import load as tr
    from ..report.formats import markdown_table

    lines = ["## Per-bin statistics: collectors", "",
             "Both collectors compute, per pixel, bin and channel, float64 power sums of the "
             "transformed per-path bin sums (docs/methods/statistical.md §11). (a): 1-spp passes "
             "(several camera copies per call through a `batch` sensor) with host-side sums; "
             "(b): the `transient_path_stats` integrator (`transient_prbvolpath_stats` for the "
             "media scene), per-path slots of running sums flushed with atomics, state "
             "independent of spp. Ratios are to one plain render of the scene's integrator at "
             "the same spp (film histogram only, read back to NumPy). "
             "`a render` is the rendering part of (a) (1-spp calls, each developing a whole "
             "film); `b render` is (b)'s render call alone; `b` adds reading the sums back and "
             "computing the moments, colour and counts on the device (bit-identical to the "
             "host formulas). `load`: the 1-minute load average when the row finished.", ""]
    brow, media = [], []
    for name in scenes:
        sc = catalogue.get(name)
        if sc.integrator not in tr.IN_INTEGRATOR:
            continue
        if sc.medium:
            media.append(name)
        r_res, r_bins = (media_res, media_bins) if sc.medium else (res, bins)
        r = bench_collectors(name, r_res, spp, r_bins, repeats=repeats)
        brow.append({k: r[k] for k in ("scene", "integrator", "res", "spp", "bins", "copies_a",
                                       "plain_s", "a_s", "a_render_s", "b_s", "b_render_s",
                                       "ratio_a", "ratio_b", "ratio_b_render", "b_state_mb",
                                       "b_reentries", "b_overflow", "load")})
    lines += [markdown_table(pd.DataFrame(brow)), ""]
    for name in ["cornell-transient"] + media[:1]:
        mem = state_bytes_vs_spp(name)
        lines += [f"Collector (b) state vs spp ({name}, 32×32 px, 100 bins): " +
                  ", ".join(f"{r['spp']} spp → {r['state_bytes']:,} B" for r in mem) +
                  " (constant by construction; it holds " + LAYOUTS[mem[0]["layout"]] +
                  " and, per pixel and channel, Σ total and Σ total² of the paths' window "
                  "totals; overflows: " +
                  ", ".join(str(r["n_overflow"]) for r in mem) + ").", ""]
    return lines


# ---------------------------------------------------------------------------------------------
# metrics


def video_metrics(output: np.ndarray, reference: np.ndarray, ev: float = 0.0) -> dict[str, float]:
    """Whole-video RMSE and relMSE (every voxel), SSIM and PSNR of the time-integrated image."""
    return {"rmse": metrics.rmse(output, reference), "relmse": metrics.relmse(output, reference),
            "ssim_integrated": metrics.ssim(output, reference, ev=ev),
            "psnr_integrated": metrics.psnr(output, reference, ev=ev)}


# ---------------------------------------------------------------------------------------------
# figures


# ---------------------------------------------------------------------------------------------
# the report


def run_methods(frame: TransientFrame, names: Sequence[str] = DEFAULT_METHODS,
                repeats: int = 1) -> tuple[list[dict[str, Any]], dict[str, np.ndarray]]:
    """Run each method on ``frame``: rows of metrics + time, and the outputs."""
    from .. import registry
    from ..run.harness import time_call

    rows, outputs = [], {}
    for name in names:
        m = registry.get(name)
        ok, why = registry.applies(m, frame.kind, {b for b in ("color", "albedo", "normal",
                                                              "depth", "stats") if frame.has(b)})
        if not ok:
            rows.append({"method": name, "skipped": why})
            continue
        out, times = time_call(lambda: fpenv.denoise(m, frame), repeats=repeats, warmup=0)
        out = np.asarray(out, np.float32)
        outputs[name] = out
        rows.append({"method": name, **video_metrics(out, frame.reference, frame.meta.get("ev", 0)),
                     "time_s": statistics.median(times), "skipped": ""})
    return rows, outputs


def run_report(out_dir: str | Path = "results", scenes: Sequence[str] = (
        "cornell-transient", "caustic-transient", "fog-transient"), res: int = 64,
               spp: int = 32, bins: int = 200, ref_spp: int = 2048,
               methods_: Sequence[str] = DEFAULT_METHODS, bench_res: int = 64,
               bench_spp: int = 64, bench_repeats: int = 5, progress: bool = True,
               media_res: int = 48, media_bins: int = 100) -> str:
    """Benchmark collectors and baselines on the transient scenes; write
    ``<out_dir>/transient.md`` and figures under ``<out_dir>/transient/``. Returns the text.

    ``media_res``, ``media_bins``: the collector benchmark's size for participating-media scenes
    (a media path costs about 10× a surface path, so they are timed smaller)."""
    from .. import datasets
    from ..datasets.scenes import catalogue
    from ..datasets.transient import load as tr
    from ..report.formats import markdown_table
    from ..run.machine import machine_info

    out_dir = Path(out_dir)
    fig_dir = out_dir / "transient"
    fig_dir.mkdir(parents=True, exist_ok=True)
    info = machine_info()
    load_before = os.getloadavg()[0]
    lines = ["# Transient datasets, per-bin statistics and baselines", "",
             f"Generated by `python -m dbench.studies.transient_report` on {time.strftime('%Y-%m-%d')}. "
             f"Machine: {info['cpu']}, {info['cores']} cores, GPU: {info.get('gpu') or 'none'}; "
             f"load average {load_before:.2f} at the start (LOAD_AFTER at the end). Absolute "
             "times depend on other jobs on the machine; every ratio below is measured in one "
             "run with the compared renders interleaved (median of the repeats).", ""]

    # -- windows and energy ---------------------------------------------------------------------
    lines += ["## Scenes and time windows", "",
              "Time axis: optical path length (OPL, metres, warped: the camera segment counts; "
              "time = OPL / c). Each window starts at the scene's earliest direct arrival "
              "(geometry, rounded down) and ends where 99 % of the steady energy has arrived "
              "in a pilot render (`size_window`); *energy inside* is Σ video / Σ steady of the "
              "same paths, measured here on the reference renders.", ""]
    frames: dict[str, TransientFrame] = {}
    rows = []
    for name in scenes:
        sc = catalogue.get(name)
        t0 = time.perf_counter()
        frame = datasets.load(name, spp=spp, res=res, bins=bins, ref_spp=ref_spp,
                              progress=progress)
        frames[name] = frame
        m = frame.meta
        rows.append({"scene": name, "integrator": sc.integrator, "max_depth": sc.max_depth,
                     "start_opl": m["start_opl"], "end_opl": m["end_opl"], "bins": m["bins"],
                     "bin_width_opl": m["bin_width_opl"],
                     "bin_width_ps": m["bin_width_opl"] / tr.SPEED_OF_LIGHT * 1e12,
                     "energy_inside_noisy": m["energy_fraction"],
                     "energy_inside_reference": m.get("reference_energy_fraction"),
                     "collector": m["collector"], "load_s": time.perf_counter() - t0})
    lines += [markdown_table(pd.DataFrame(rows)), ""]
    sized = [tr.size_window(catalogue.get(name)) for name in scenes]
    lines += ["Window sizing (`size_window(scene, coverage=0.99, res=24, spp=256)`, pilot window "
              "[0, start + 40 m) with 4000 bins): first direct arrival from the geometry, the "
              "chosen [start, end), the share of the pilot's steady energy inside it and "
              "before it.", "",
              markdown_table(pd.DataFrame(sized)), ""]

    # -- collectors -----------------------------------------------------------------------------
    lines += collector_section(scenes, bench_res, bench_spp, bins, bench_repeats, media_res,
                               media_bins)

    # -- baselines ------------------------------------------------------------------------------
    lines += ["## Baselines", "",
              f"{res}×{res} px, {bins} bins, {spp} spp noisy input, {ref_spp} spp reference. "
              "RMSE and relMSE (ε = 1e-2) over every voxel of the video; SSIM and PSNR of the "
              "time-integrated image (sum over bins). Methods skip bins without energy. "
              "`jbf-bins` uses the JBF defaults (radius 20, seed Σ) on each bin; `gauss3d` "
              "σ_s² = 10 px², σ_t = 1 bin, r_s = 5, r_t = 1.", ""]
    for name, frame in frames.items():
        rows, outputs = run_methods(frame, methods_)
        lines += [f"### {name}", "", markdown_table(pd.DataFrame(rows)), ""]
        pick = write_figures(fig_dir, frame, outputs, prefix=f"{name}_", title=name)
        lines += [f"![RMSE per bin](transient/{name}_rmse_per_bin.png)",
                  f"![bins {pick}](transient/{name}_bins.png)",
                  f"![streak](transient/{name}_streak.png)", ""]
    lines += ["## Notes", "", *NOTES, ""]
    text = ("\n".join(lines) + "\n").replace("LOAD_AFTER", f"{os.getloadavg()[0]:.2f}", 1)
    io.write_text(out_dir / "transient.md", text)
    return text


def build_parser() -> Parser:
    """The options of :func:`main` (each single-valued one given at most once)."""
    ap = Parser(prog="python -m dbench.studies.transient_report",
                description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="results", help="folder of transient.md (figures in its "
                    "transient/)")
    ap.add_argument("--res", type=int, default=64, help="baselines: side of the square renders")
    ap.add_argument("--spp", type=int, default=32, help="baselines: spp of the noisy input")
    ap.add_argument("--bins", type=int, default=200, help="time bins (baselines and the "
                    "collector benchmark's surface scenes)")
    ap.add_argument("--ref-spp", type=int, default=2048, help="baselines: reference spp")
    ap.add_argument("--bench-res", type=int, default=64, help="collector benchmark: side of "
                    "the square renders")
    ap.add_argument("--bench-spp", type=int, default=64, help="collector benchmark: spp")
    ap.add_argument("--repeats", type=int, default=5, help="collector benchmark: timed "
                    "repeats after a warm-up (median)")
    ap.add_argument("--scenes", default="cornell-transient,caustic-transient,fog-transient",
                    help="comma list of transient scenes")
    ap.add_argument("--methods", default=",".join(DEFAULT_METHODS), help="baselines: comma "
                    "list of methods")
    ap.add_argument("--media-res", type=int, default=48, help="collector benchmark: side on "
                    "participating-media scenes (a media path costs about 10x a surface path)")
    ap.add_argument("--media-bins", type=int, default=100, help="collector benchmark: time "
                    "bins on participating-media scenes")
    ap.add_argument("--collectors-only", action="store_true",
                    help="print the collector benchmark only (results/transient.md untouched)")
    return ap


def main(argv: Sequence[str] | None = None) -> int:
    a = build_parser().parse_args(argv)
    scenes = [s for s in a.scenes.split(",") if s]
    if a.collectors_only:
        print(f"load average {os.getloadavg()[0]:.2f} at the start")
        print("\n".join(collector_section(scenes, a.bench_res, a.bench_spp, a.bins, a.repeats,
                                          a.media_res, a.media_bins)))
        print(f"load average {os.getloadavg()[0]:.2f} at the end")
        return 0
    print(run_report(a.out, scenes, a.res, a.spp, a.bins,
                     a.ref_spp, [m for m in a.methods.split(",") if m], a.bench_res,
                     a.bench_spp, a.repeats, media_res=a.media_res, media_bins=a.media_bins))
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
