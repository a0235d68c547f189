"""results/temporal: the temporal methods on the sequence catalogue (:func:`quality_run`,
per-frame errors, strips, the summary table) and their 720p speed
(``python -m dbench.studies.sequence_report``)."""
from __future__ import annotations

from pathlib import Path

from ..data import Sequence
from ..options import Parser
from ..report.sequence_figures import plot_errors, strip
from ..run.sequence_run import (
    TEMPORAL_METHODS,
    WARMUP,
    SequenceResult,
    compare,
    summary_rows,
    window_mean,
)
from ..speed.sequence import benchmark


def quality_run(scene: str, res: int = 64, frames: int | None = None, spp: int = 1,
                ref_spp: int = 1024, seed: int = 0, method_names=TEMPORAL_METHODS,
                cache=None, progress: bool = True) -> tuple[Sequence, dict[str, SequenceResult]]:
    from .. import datasets

    seq = datasets.load(scene, spp=spp, res=res, frames=frames, ref_spp=ref_spp, seed=seed,
                        cache=cache, progress=progress)
    return seq, compare(seq, method_names)


def build_parser() -> Parser:
    """The options of :func:`main` (each single-valued one given at most once)."""
    ap = Parser(prog="python -m dbench.studies.sequence_report",
                description="The temporal methods on the sequence catalogue (per-frame "
                "errors, strips, the summary table) and their 720p speed: results/temporal.")
    ap.add_argument("--scenes", default="orbit,flicker,mirror-pan",
                    help="comma list of sequence scenes (1 spp each)")
    ap.add_argument("--res", type=int, default=64, help="side of the square frames")
    ap.add_argument("--frames", type=int, default=None, help="frames from the start (default "
                    "all)")
    ap.add_argument("--ref-spp", type=int, default=1024, help="reference spp")
    ap.add_argument("--out", default="results/temporal", help="folder of quality.json, "
                    "speed.json and the figures")
    ap.add_argument("--speed", action="store_true", help="also time the methods per frame at "
                    "1280x720 (speed.json)")
    ap.add_argument("--no-quality", action="store_true", help="leave out the quality run and "
                    "its figures")
    ap.add_argument("--repeats", type=int, default=6, help="--speed: timed frames per method "
                    "after two warm-up frames")
    ap.add_argument("--threads", default="2,1", help="Numba thread counts to time, e.g. 2,1")
    return ap


def main(argv: list[str] | None = None) -> int:
    """``python -m dbench.studies.sequence_report [--res 64] [--frames 48] [--ref-spp 1024]
    [--out DIR] [--speed]``: quality figures (tables, error plots, strips) for orbit, flicker and
    mirror-pan, and optionally the 720p speed benchmark; writes JSON + PNG under ``--out``."""
    a = build_parser().parse_args(argv)
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
