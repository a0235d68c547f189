"""Parameter study of the temporal denoisers (results/temporal.md, "Parameter study").

Every variant runs on the sequence scenes at 1 spp over several noisy seeds (one reference per
scene), scored after the 8-frame warm-up like :mod:`dbench.run.sequence_run`: mean RMSE, relMSE and
``t_rmse`` per seed, then the mean and the 95 % t-interval over the seeds. The variants change one
thing at a time from the method's default, so the table shows how sensitive each method is to
each parameter (α, à-trous iterations, the variance the luminance weights use, the feedback tap,
the normal buffer of the edge-stopping weights, BMFR's residual hand-back, block size, feature
set — with the reflected and geometric normals —, samples per block and the temporal gradient).

Reproduce (about 10 minutes on 2 cores once the sequences are cached)::

    python -m dbench.studies.temporal_study --out results/temporal_study

writes ``study.json`` (every seed's numbers) and ``study.md`` (the tables).
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from ..options import Parser

#: scene: (frames, reference spp) — orbit as issue 16 measured it, the others as the sweep
SCENES = {"orbit": (48, 4096), "flicker": (24, 256), "mirror-pan": (24, 256)}
BASELINES = (("noisy", "noisy", {}), ("accumulate", "accumulate", {}),
             ("accumulate taa=True", "accumulate", {"taa": True}))
VARIANTS: tuple[tuple[str, str, dict[str, Any]], ...] = (
    ("svgf", "svgf", {}),
    ("svgf preset=paper", "svgf", {"preset": "paper"}),
    ("svgf preset=falcor", "svgf", {"preset": "falcor"}),
    ("svgf variance_of=sample", "svgf", {"variance_of": "sample"}),
    ("svgf feedback_tap=0", "svgf", {"feedback_tap": 0}),
    ("svgf iterations=2", "svgf", {"iterations": 2}),
    ("svgf iterations=5", "svgf", {"iterations": 5}),
    ("svgf alpha_min=0.1", "svgf", {"alpha_min": 0.1}),
    ("svgf alpha_min=0.05", "svgf", {"alpha_min": 0.05}),
    ("svgf sigma_l=2", "svgf", {"sigma_l": 2.0}),
    ("svgf sigma_l=10", "svgf", {"sigma_l": 10.0}),
    ("svgf luminance_kernel=laplacian (the paper's)", "svgf", {"luminance_kernel": "laplacian"}),
    ("svgf variance_boost=False (the paper's)", "svgf", {"variance_boost": False}),
    ("svgf normal_buffer=reflected_normal", "svgf", {"normal_buffer": "reflected_normal"}),
    ("svgf normal_buffer=geo_normal", "svgf", {"normal_buffer": "geo_normal"}),
    ("svgf taa=True", "svgf", {"taa": True}),
    ("asvgf", "asvgf", {}),
    ("asvgf alpha_floor=False", "asvgf", {"alpha_floor": False}),
    ("asvgf preset=paper", "asvgf", {"preset": "paper"}),
    ("asvgf variance_boost=False", "asvgf", {"variance_boost": False}),
    ("asvgf variance_boost=svgf (Falcor's)", "asvgf", {"variance_boost": "svgf"}),
    ("asvgf variance_boost=asvgf (Schied's everywhere; the previous default)", "asvgf",
     {"variance_boost": "asvgf"}),
    ("asvgf luminance_kernel=laplacian (the paper's)", "asvgf", {"luminance_kernel": "laplacian"}),
    ("asvgf variance_boost=svgf luminance_kernel=laplacian (the default before §15)", "asvgf",
     {"variance_boost": "svgf", "luminance_kernel": "laplacian"}),
    ("asvgf gradient_mode=filtered", "asvgf", {"gradient_mode": "filtered"}),
    ("asvgf gradient_mode=paper", "asvgf", {"gradient_mode": "paper"}),
    ("asvgf gradient_mode=filtered_abs", "asvgf", {"gradient_mode": "filtered_abs"}),
    ("asvgf normal_buffer=reflected_normal", "asvgf", {"normal_buffer": "reflected_normal"}),
    ("asvgf taa=True", "asvgf", {"taa": True}),
    ("bmfr", "bmfr", {}),
    ("bmfr handback=wiener (the previous default)", "bmfr", {"handback": "wiener"}),
    ("bmfr preset=paper (no hand-back, demodulated)", "bmfr", {"preset": "paper"}),
    ("bmfr handback=none block_size=16", "bmfr", {"handback": "none", "block_size": 16}),
    ("bmfr temporal_gradient=False", "bmfr", {"temporal_gradient": False}),
    ("bmfr block_size=8", "bmfr", {"block_size": 8}),
    ("bmfr block_size=16", "bmfr", {"block_size": 16}),
    ("bmfr block_size=64", "bmfr", {"block_size": 64}),
    ("bmfr features=seed", "bmfr", {"features": "seed"}),
    ("bmfr features=normals", "bmfr", {"features": "normals"}),
    ("bmfr features=reflected", "bmfr", {"features": "reflected"}),
    ("bmfr features=paper+geo", "bmfr", {"features": "paper+geo"}),
    ("bmfr features=reflected+geo", "bmfr", {"features": "reflected+geo"}),
    ("bmfr samples=36", "bmfr", {"samples": 36}),
    ("bmfr preset=seed", "bmfr", {"preset": "seed"}),
    ("bmfr alpha1=0.05", "bmfr", {"alpha1": 0.05}),
    ("bmfr taa=True", "bmfr", {"taa": True}),
)
METRICS = ("rmse", "rmse_surface", "relmse", "t_rmse")


def _interval(values: list[float]) -> tuple[float, float]:
    """Mean and half-width of the 95 % t-interval (:func:`dbench.metrics.judge.t_interval`),
    the half-width 0 for a single seed."""
    from ..metrics.judge import t_interval

    mean, half = t_interval(values)
    return mean, (half if math.isfinite(half) else 0.0)


def run(res: Any = 64, seeds: tuple[int, ...] = (0, 1, 2), scenes=tuple(SCENES),
        variants=BASELINES + VARIANTS, progress: bool = True,
        settings: dict[str, tuple[int, int]] | None = None) -> list[dict[str, Any]]:
    """Rows ``{scene, label, method, params, seed, rmse, rmse_surface, relmse, t_rmse}`` (and
    ``rmse_after_change``, the 5 frames from a light change, where the scene has one) for every
    variant, scene and seed. ``res``: a side or (width, height), as ``datasets.load`` takes it;
    ``settings``: {scene: (frames, reference spp)}, :data:`SCENES` by default."""
    from .. import datasets, registry
    from ..run.sequence_run import run_sequence, window_mean

    rows = []
    for scene in scenes:
        frames, ref_spp = (settings or SCENES)[scene]
        for seed in seeds:
            seq = datasets.load(scene, spp=1, res=res, frames=frames, ref_spp=ref_spp, seed=seed,
                                progress=False)
            for label, name, params in variants:
                r = run_sequence(registry.get(name, **params), seq,
                                 metric_names=("rmse", "rmse_surface", "relmse"))
                row = {"scene": scene, "label": label, "method": name, "params": params,
                       "seed": seed, "rmse": r.summary["mean_rmse"],
                       "rmse_surface": r.summary["mean_rmse_surface"],
                       "relmse": r.summary["mean_relmse"], "t_rmse": r.summary["t_rmse"]}
                change = seq.meta.get("events", {}).get("light_change")
                if change is not None:
                    row["rmse_after_change"] = window_mean(r, "rmse", int(change), 5)
                rows.append(row)
                if progress:
                    print(f"{scene} seed {seed} {label}: rmse {row['rmse']:.5f}", flush=True)
    return rows


def paired_difference(mine: list[dict[str, Any]], base: list[dict[str, Any]], metric: str
                      ) -> str:
    """``mine − base`` of ``metric`` seed by seed (the same noisy input for both), as
    ``mean ± 95 % half-width`` and a word: "below" or "above" when the interval excludes 0,
    else "tied" (docs/judging.md §3: a paired difference has a much smaller interval than
    either method's own; :func:`~dbench.report.verdicts.paired_interval`); "—" with fewer than
    two common seeds."""
    from ..report.verdicts import paired_interval

    paired = paired_interval({"per_seed": mine}, {"per_seed": base}, metric)
    if paired is None:
        return "—"
    return paired_text(*paired)


def paired_word(mean: float, half: float) -> str:
    """"below" or "above" when the interval mean ± half excludes 0, else "tied"."""
    return "below" if mean + half < 0 else "above" if mean - half > 0 else "tied"


def paired_text(mean: float, half: float, digits: int = 4) -> str:
    """``mean ± half (word)`` with ``digits`` decimals and :func:`paired_word`."""
    return f"{mean:+.{digits}f} ± {half:.{digits}f} ({paired_word(mean, half)})"


def tables(rows: list[dict[str, Any]], res: int) -> str:
    """Markdown: one table per scene, every variant's mean ± 95 % interval over the seeds, and
    its RMSE relative to ``accumulate``; flags where a variant is not below accumulate; and
    the paired differences to ``accumulate`` of the RMSE over surfaces and the relMSE."""
    out = []
    for scene in dict.fromkeys(r["scene"] for r in rows):
        frames, ref_spp = SCENES[scene]
        sub = [r for r in rows if r["scene"] == scene]
        n_seeds = len({r["seed"] for r in sub})
        base = [r for r in sub if r["label"] == "accumulate"]
        acc = np.mean([r["rmse"] for r in base])
        change = all("rmse_after_change" in r for r in sub)
        out += [f"### {scene} ({res}², {frames} frames, {ref_spp}-spp references, "
                f"{n_seeds} seeds, mean ± 95 % interval)", "",
                "| variant | RMSE | ÷ accumulate | RMSE (surfaces) | relMSE | t-RMSE | "
                "RMSE (surfaces) − accumulate, paired | relMSE − accumulate, paired |"
                + (" RMSE, 5 frames after the light change |" if change else ""),
                "|---|---|---|---|---|---|---|---|" + ("---|" if change else "")]
        for label in dict.fromkeys(r["label"] for r in sub):
            mine = [r for r in sub if r["label"] == label]
            cells = {m: _interval([r.get(m, r["rmse"]) for r in mine]) for m in METRICS}
            ratio = cells["rmse"][0] / acc
            flag = "" if ratio < 1 or label in ("noisy", "accumulate") else " (not below)"
            paired = (("—", "—") if label == "accumulate" else
                      tuple(paired_difference(mine, base, m) for m in ("rmse_surface", "relmse")))
            line = (f"| {label} | {cells['rmse'][0]:.4f} ± {cells['rmse'][1]:.4f} | "
                    f"{ratio:.3f}{flag} | {cells['rmse_surface'][0]:.4f} | "
                    f"{cells['relmse'][0]:.4f} ± {cells['relmse'][1]:.4f} | "
                    f"{cells['t_rmse'][0]:.4f} | {paired[0]} | {paired[1]} |")
            if change:
                line += f" {np.mean([r['rmse_after_change'] for r in mine]):.4f} |"
            out.append(line)
        out.append("")
    return "\n".join(out)


def build_parser() -> Parser:
    """The options of :func:`main` (each single-valued one given at most once)."""
    ap = Parser(prog="python -m dbench.studies.temporal_study",
                description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="results/temporal_study", help="folder of study.json and "
                    "study.md")
    ap.add_argument("--res", type=int, default=64, help="side of the square frames")
    ap.add_argument("--seeds", default="0,1,2", help="comma list of the noisy renders' seeds")
    ap.add_argument("--scenes", default=",".join(SCENES), help="comma list of sequence scenes, "
                    f"of {', '.join(SCENES)} (their frames and reference spp are the study's)")
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from ..io import write_json, write_text

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = run(args.res, tuple(int(s) for s in args.seeds.split(",")),
               tuple(args.scenes.split(",")))
    write_json(out / "study.json", {"res": args.res, "rows": rows})
    write_text(out / "study.md", tables(rows, args.res))
    print(f"wrote {out / 'study.md'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
