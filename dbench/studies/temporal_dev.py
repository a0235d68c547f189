"""Development study of the temporal denoisers on sequences outside the catalogue
(results/temporal_study/dev.md; docs/temporal.md §12).

The sequence catalogue (`orbit`, `flicker`, `mirror-pan`) is what dbench reports on, so its
scenes must not choose the methods' defaults. This study runs the variants on the camera-animated
training sequences of the recurrent autoencoder (:func:`dbench.learn.scenes.training_sequence`:
procedural rooms and open scenes with conductors, glass, glossy and textured surfaces and
visible lights, disjoint from the catalogue), skipping nearly black ones as the training set
does, at 1 spp over several noisy seeds, scored after the 8-frame warm-up like
:mod:`dbench.run.sequence_run`. For each variant it reports, against plain ``accumulate`` on the
same scene and seed, the geometric mean of the ratios of RMSE, RMSE over surfaces and relMSE,
and the share of (scene, seed) pairs where the variant's relMSE is below accumulate's.

Reproduce (about 2 minutes on 2 cores once the sequences are cached, 5 to render them)::

    python -m dbench.studies.temporal_dev --out results/temporal_study
    python -m dbench.studies.temporal_dev --out results/temporal_study --held-out

writes ``dev.json`` (every scene's and seed's numbers) and ``dev.md``; ``--held-out`` runs the
defaults alone on the next 8 usable sequences, which chose nothing (``heldout.json``,
``heldout.md``): the figures to quote for scenes a user brings.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from ..methods.bmfr.params import ALBEDO_FLOOR_BMFR
from ..methods.svgf.params import ALBEDO_FLOOR
from ..options import Parser

FRAMES, REF_SPP, RES = 24, 256, 64
FLOORS = (0.02, 0.05, 0.1, 0.2, 0.3, 0.5, 1.0)
DEFAULT_FLOOR = {"svgf": ALBEDO_FLOOR, "asvgf": ALBEDO_FLOOR, "bmfr": ALBEDO_FLOOR_BMFR}
ALPHAS = (0.2, 0.1, 0.05, 0.02)
SIGMAS = (2.0, 4.0, 6.0, 8.0)
#: (label, method, params): the demodulation floor of every filter (the default marked), then
#: the temporal α floor of SVGF and A-SVGF, BMFR's two accumulation factors, the luminance
#: weight's form and σ_l
VARIANTS: tuple[tuple[str, str, dict[str, Any]], ...] = (
    ("accumulate", "accumulate", {}),
    *((f"{m} albedo_floor={f}" + (" (default)" if f == DEFAULT_FLOOR[m] else ""), m,
       {"albedo_floor": f}) for m in ("svgf", "asvgf", "bmfr") for f in FLOORS),
    *((f"{m} alpha_min={a}" + (" (default)" if a == 0.2 else ""), m, {"alpha_min": a})
      for m in ("svgf", "asvgf") for a in ALPHAS),
    ("bmfr alpha1=0.1 alpha2=0.05", "bmfr", {"alpha1": 0.1, "alpha2": 0.05}),
    ("bmfr handback=wiener (the previous default)", "bmfr", {"handback": "wiener"}),
    ("svgf luminance_kernel=laplacian (the paper's)", "svgf", {"luminance_kernel": "laplacian"}),
    ("asvgf luminance_kernel=laplacian (the paper's)", "asvgf", {"luminance_kernel": "laplacian"}),
    ("svgf variance_boost=False (the paper's)", "svgf", {"variance_boost": False}),
    ("svgf variance_boost=asvgf", "svgf", {"variance_boost": "asvgf"}),
    ("asvgf variance_boost=False", "asvgf", {"variance_boost": False}),
    ("asvgf variance_boost=svgf (Falcor's)", "asvgf", {"variance_boost": "svgf"}),
    ("asvgf variance_boost=asvgf (the previous default)", "asvgf", {"variance_boost": "asvgf"}),
    ("asvgf variance_boost=svgf luminance_kernel=laplacian (the default before §15)", "asvgf",
     {"variance_boost": "svgf", "luminance_kernel": "laplacian"}),
    ("asvgf gradient_mode=filtered", "asvgf", {"gradient_mode": "filtered"}),
    ("asvgf gradient_mode=paper", "asvgf", {"gradient_mode": "paper"}),
    ("asvgf gradient_mode=filtered_abs", "asvgf", {"gradient_mode": "filtered_abs"}),
    *((f"svgf sigma_l={s}" + (" (default)" if s == 4.0 else ""), "svgf", {"sigma_l": s})
      for s in SIGMAS),
)


#: the defaults, measured on sequences that chose nothing (``--held-out``), the variance boosts
#: of docs/temporal.md §15 off or in their previous form, and A-SVGF with
#: the gradients of docs/temporal.md §14, which these sequences favour and the catalogue's
#: flicker (``"filtered"``) or mirror-pan (both) do not
HELD_OUT_VARIANTS = (("accumulate", "accumulate", {}), ("svgf", "svgf", {}),
                     ("asvgf", "asvgf", {}), ("bmfr", "bmfr", {}),
                     ("bmfr handback=wiener", "bmfr", {"handback": "wiener"}),
                     ("svgf variance_boost=False", "svgf", {"variance_boost": False}),
                     ("asvgf variance_boost=asvgf (the previous default)", "asvgf",
                      {"variance_boost": "asvgf"}),
                     ("asvgf variance_boost=False luminance_kernel=laplacian", "asvgf",
                      {"variance_boost": False, "luminance_kernel": "laplacian"}),
                     ("asvgf variance_boost=svgf luminance_kernel=laplacian", "asvgf",
                      {"variance_boost": "svgf", "luminance_kernel": "laplacian"}),
                     ("asvgf gradient_mode=filtered", "asvgf", {"gradient_mode": "filtered"}),
                     ("asvgf gradient_mode=filtered_abs", "asvgf",
                      {"gradient_mode": "filtered_abs"}))


def dev_sequences(n_scenes: int, skip: int = 0, min_mean: float = 0.03):
    """Training sequences (:func:`~dbench.learn.scenes.training_sequence`, ``FRAMES`` frames)
    whose scene is not nearly black: ``n_scenes`` of them after the first ``skip``."""
    from ..learn.dataset import probe_mean
    from ..learn.scenes import training_scene, training_sequence

    out, index, usable = [], 0, 0
    while len(out) < n_scenes:
        if probe_mean(training_scene(index)) >= min_mean:
            if usable >= skip:
                out.append(training_sequence(index, FRAMES))
            usable += 1
        index += 1
    return out


def run(n_scenes: int = 8, seeds: tuple[int, ...] = (0, 1), variants=VARIANTS,
        progress: bool = True, skip: int = 0) -> list[dict[str, Any]]:
    """Rows ``{scene, seed, label, method, params, rmse, rmse_surface, relmse}`` on the
    sequences of :func:`dev_sequences`."""
    from .. import registry
    from ..datasets.sequence.load import load_sequence
    from ..run.sequence_run import run_sequence

    rows = []
    for scene in dev_sequences(n_scenes, skip):
        for seed in seeds:
            seq = load_sequence(scene, spp=1, res=RES, seed=seed, ref_spp=REF_SPP,
                                progress=False)
            for label, name, params in variants:
                s = run_sequence(registry.get(name, **params), seq,
                                 metric_names=("rmse", "rmse_surface", "relmse")).summary
                rows.append({"scene": scene.name, "seed": seed, "label": label, "method": name,
                             "params": params, "rmse": s["mean_rmse"],
                             "rmse_surface": s["mean_rmse_surface"],
                             "relmse": s["mean_relmse"]})
        if progress:
            print(f"{scene.name}: done", flush=True)
    return rows


def table(rows: list[dict[str, Any]]) -> str:
    """Markdown: per variant the geometric means of its ratios to accumulate and the share of
    (scene, seed) pairs where its relMSE is below accumulate's."""
    base = {(r["scene"], r["seed"]): r for r in rows if r["label"] == "accumulate"}
    pairs = len(base)
    scenes = sorted({r["scene"] for r in rows})
    lines = [f"Training sequences {', '.join(scenes)} ({RES}², {FRAMES} frames, "
             f"{REF_SPP}-spp references, 1 spp, {pairs // max(len(scenes), 1)} seeds each). "
             "Ratios to plain accumulation on the same scene and seed, geometric mean over "
             f"the {pairs} pairs.", "",
             "| variant | RMSE ÷ acc. | RMSE (surfaces) ÷ acc. | relMSE ÷ acc. | "
             "relMSE below acc. |", "|---|---|---|---|---|"]
    for label in dict.fromkeys(r["label"] for r in rows):
        if label == "accumulate":
            continue
        mine = [r for r in rows if r["label"] == label]
        ratios = {m: [r[m] / base[(r["scene"], r["seed"])][m] for r in mine]
                  for m in ("rmse", "rmse_surface", "relmse")}
        g = {m: math.exp(float(np.mean(np.log(v)))) for m, v in ratios.items()}
        wins = float(np.mean([v < 1 for v in ratios["relmse"]]))
        lines.append(f"| {label} | {g['rmse']:.3f} | {g['rmse_surface']:.3f} | "
                     f"{g['relmse']:.3f} | {wins:.0%} |")
    return "\n".join(lines) + "\n"


def build_parser() -> Parser:
    """The options of :func:`main` (each single-valued one given at most once)."""
    ap = Parser(prog="python -m dbench.studies.temporal_dev",
                description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="results/temporal_study", help="folder of dev.json and "
                    "dev.md (heldout.json and heldout.md with --held-out)")
    ap.add_argument("--scenes", type=int, default=8, help="how many training sequences")
    ap.add_argument("--seeds", default="0,1", help="comma list of the noisy renders' seeds")
    ap.add_argument("--held-out", action="store_true",
                    help="the defaults only, on the next --scenes sequences after the ones "
                         "that chose them (written to heldout.json / heldout.md)")
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from ..io import write_json, write_text

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    seeds = tuple(int(s) for s in args.seeds.split(","))
    if args.held_out:
        rows = run(args.scenes, seeds, HELD_OUT_VARIANTS, skip=args.scenes)
        name, title = "heldout", "on held-out sequences (defaults only)"
    else:
        rows = run(args.scenes, seeds)
        name, title = "dev", "on sequences outside the catalogue"
    write_json(out / f"{name}.json", {"rows": rows})
    write_text(out / f"{name}.md", f"# Temporal denoisers {title}\n\n" + table(rows))
    print(f"wrote {out / (name + '.md')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
