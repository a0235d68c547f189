"""The seed's transient studies (seed 000 Fig. 5.4-5.6), one command each.

* ``fig5.4``: sample transform × λ × γ of the statistical denoiser on the transient scenes
  (docs/methods/statistical.md §3, §5.1, §11.3), at one spp;
* ``fig5.5``: temporal radius r_t × bin width, the spatial radius r_s as a second axis, on one
  scene (the window stays the scene's, so the bin count sets the width);
* ``fig5.6``: error against spp (16 … 2048) for the noisy input, ``statistical``, ``jbf-bins``
  and ``oidn-bins``: a ``dbench sweep`` over the transient scenes (3 seeds, 95 % intervals),
  then its figure;
* ``ablation``: the statistical denoiser's rules one at a time (the seed's rule, + shrinkage,
  + the pixel-total rule, + γ = 0.1; both base filters on the media scene) at every spp
  (results/transient_statistical.md §6).

Each writes ``<out>/<study>.json`` (every number), ``<out>/<study>.md`` (the table) and
``<out>/<study>.png`` (the figure). Figures and tables give the error as a ratio to the noisy
input's of the same render: whole-video RMSE, its unbiased version (the reference's own variance
removed, docs/judging.md §2) and the RMSE of the time-integrated image (Σ over bins).

Reproduce::

    python -m dbench.studies.transient_studies fig5.4 --out results/transient_studies
    python -m dbench.studies.transient_studies fig5.5 --out results/transient_studies
    python -m dbench.studies.transient_studies fig5.6 --out results/transient_studies
    python -m dbench.studies.transient_studies ablation --out results/transient_studies
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .. import io
from ..options import Parser
from ..run import fpenv
from ..report.plots import save

SCENES = ("cornell-transient", "caustic-transient", "fog-transient")
#: (transform, λ) of Fig. 5.4: identity, Yeo-Johnson over the seed's λ range, Box-Cox 0.5
TRANSFORMS = (("identity", 0.5), ("yeo-johnson", 0.25), ("yeo-johnson", 0.5),
              ("yeo-johnson", 1.0), ("yeo-johnson", 1.5), ("box-cox", 0.5))
GAMMAS = (0.01, 0.05, 0.1, 0.2)
#: Fig. 5.5: bins over the scene's window (cornell-transient: 248 / 77 / 25 / 7.7 mm, i.e. about
#: 829 / 257 / 83 / 26 ps), temporal and spatial radii
BINS = (31, 100, 308, 1000)
RADII_T = (0, 1, 2, 3)
RADII_S = (2, 5)
FIG56_METHODS = ("noisy", "statistical", "jbf-bins", "oidn-bins")
#: the ablation's rows: one rule added at a time (results/transient_statistical.md §6)
ABLATION = (("A seed rule (γ 0.05, r_t 1)", dict(shrink=False, mass=False, gamma=0.05,
                                                  radius_t=1)),
            ("B + shrinkage", dict(shrink=True, mass=False, gamma=0.05, radius_t=1)),
            ("C + pixel-total rule", dict(shrink=True, mass=True, gamma=0.05, radius_t=1)),
            ("D + γ 0.1", dict(shrink=True, mass=True, gamma=0.1, radius_t=1)),
            ("E + r_t from the bin width (defaults)", dict(shrink=True, mass=True, gamma=0.1)))
#: references of the ablation: 1/16 of the largest input where affordable, 1/8 for the media
ABLATION_REF = {"cornell-transient": 32768, "caustic-transient": 32768, "fog-transient": 16384}
FIG56_SPP = (16, 64, 256, 1024, 2048)


def score(video: np.ndarray, frame) -> dict[str, float]:
    """Whole-video RMSE, its unbiased version sqrt(max(0, MSE − mean(reference_var))) and the
    RMSE of the time-integrated image (H, W, 3) against the frame's reference."""
    ref = frame.reference.astype(np.float64)
    err = np.asarray(video, np.float64) - ref
    mse = float(np.mean(err ** 2))
    ref_var = float(np.mean(frame.reference_var)) if frame.reference_var is not None else 0.0
    integrated = float(np.sqrt(np.mean(err.sum(axis=2) ** 2)))
    return {"rmse": mse ** 0.5, "rmse_unbiased": max(mse - ref_var, 0.0) ** 0.5,
            "rmse_integrated": integrated}


def _ratios(den: dict[str, float], noisy: dict[str, float]) -> dict[str, float]:
    return {f"{k}_ratio": (den[k] / noisy[k] if noisy[k] > 0 else float("nan")) for k in den}


def _denoise(frame, **params) -> tuple[np.ndarray, float]:
    from ..registry import get

    method = get("statistical", **params)
    t0 = time.perf_counter()
    out = fpenv.denoise(method, frame)
    return out, time.perf_counter() - t0


def fig54(scenes: Sequence[str] = SCENES, res: int = 64, spp: int = 256, ref_spp: int = 16384,
          bins: int | None = None, seed: int = 0) -> list[dict[str, Any]]:
    """Transform × λ × γ (seed Fig. 5.4): one row per (scene, transform, λ, γ)."""
    from ..datasets import load

    rows = []
    for scene in scenes:
        for transform, lam in TRANSFORMS:
            frame = load(scene, spp, res, transform=transform, lam=lam, seed=seed,
                         ref_spp=ref_spp, bins=bins, progress=False)
            noisy = score(frame.color, frame)
            for gamma in GAMMAS:
                out, seconds = _denoise(frame, gamma=gamma)
                den = score(out, frame)
                rows.append({"scene": scene, "transform": transform,
                             "lam": lam if transform != "identity" else None, "gamma": gamma,
                             "spp": spp, "res": res, "ref_spp": ref_spp,
                             "ref_rmse": frame.meta.get("ref_rmse"), "time_s": seconds,
                             **{f"noisy_{k}": v for k, v in noisy.items()}, **den,
                             **_ratios(den, noisy)})
    return rows


def fig55(scene: str = "cornell-transient", res: int = 64, spp: int = 256, ref_spp: int = 4096,
          bins_list: Sequence[int] = BINS, radii_t: Sequence[int] = RADII_T,
          radii_s: Sequence[int] = RADII_S, seed: int = 0) -> list[dict[str, Any]]:
    """Temporal radius × bin width × spatial radius (seed Fig. 5.5)."""
    from ..datasets import load
    from ..datasets.scenes import catalogue
    from ..methods.statistical.transient import auto_radius_t

    sc = catalogue.get(scene)
    rows = []
    for bins in bins_list:
        frame = load(scene, spp, res, seed=seed, ref_spp=ref_spp, bins=bins, progress=False)
        width = sc.window(bins).bin_width_opl
        auto = auto_radius_t(width)
        noisy = score(frame.color, frame)
        for r_s in radii_s:
            for r_t in radii_t:
                out, seconds = _denoise(frame, radius=r_s, radius_t=r_t)
                den = score(out, frame)
                rows.append({"scene": scene, "bins": bins, "bin_width_mm": 1000.0 * width,
                             "bin_width_ps": 1e12 * width / 299792458.0, "radius": r_s,
                             "radius_t": r_t, "auto_radius_t": auto,
                             "spp": spp, "res": res, "ref_spp": ref_spp,
                             "ref_rmse": frame.meta.get("ref_rmse"), "time_s": seconds,
                             **{f"noisy_{k}": v for k, v in noisy.items()}, **den,
                             **_ratios(den, noisy)})
    return rows


def fig56(out: Path, scenes: Sequence[str] = SCENES, res: int = 64,
          spp: Sequence[int] = FIG56_SPP, ref_spp: int = 16384, seeds: int = 3,
          sweep_out: Path | None = None) -> list[dict[str, Any]]:
    """RMSE against spp (seed Fig. 5.6): runs (or resumes) the sweep, then reads its cells."""
    from ..run.sweep import SweepConfig, load_cells, run_sweep

    sweep_out = Path(sweep_out or out / "sweep")
    config = SweepConfig(methods=list(FIG56_METHODS), scenes=list(scenes), spp=list(spp),
                         res=res, ref_spp=ref_spp, seeds=seeds, repeats=1,
                         metrics=["rmse", "relmse", "psnr", "ssim"])
    run_sweep(config, sweep_out, progress=False)
    rows = []
    for cell in load_cells(sweep_out):
        if cell.get("status") != "ok":
            continue
        rows.append({k: cell.get(k) for k in ("scene", "spp", "method", "rmse", "rmse_ci",
                                              "rmse_unbiased", "rmse_unbiased_ci", "psnr",
                                              "psnr_ci", "ssim", "ssim_ci", "ref_spp",
                                              "ref_rmse", "n_seeds", "time_s")})
    return sorted(rows, key=lambda r: (r["scene"], r["method"], r["spp"]))


def ablation(scenes: Sequence[str] = SCENES, res: int = 64, spp: Sequence[int] = FIG56_SPP,
             seed: int = 0) -> list[dict[str, Any]]:
    """One row per (scene, spp, rule set, base filter); media scenes run both bases."""
    from ..datasets import load
    from ..datasets.scenes import catalogue

    rows = []
    for scene in scenes:
        ref_spp = ABLATION_REF.get(scene, 16384)
        media = catalogue.get(scene).medium is not None
        for n in spp:
            frame = load(scene, n, res, seed=seed, ref_spp=ref_spp, progress=False)
            noisy = score(frame.color, frame)
            for name, params in ABLATION:
                for base in (("gauss3d", "jbf") if media else ("jbf",)):
                    out, seconds = _denoise(frame, base=base, **params)
                    den = score(out, frame)
                    rows.append({"scene": scene, "spp": n, "variant": name, "base": base,
                                 "ref_spp": ref_spp, "ref_rmse": frame.meta.get("ref_rmse"),
                                 "time_s": seconds,
                                 **{f"noisy_{k}": v for k, v in noisy.items()}, **den,
                                 **_ratios(den, noisy)})
    return rows


# ---------------------------------------------------------------------------------------------
# tables and figures


def _fmt(value: Any) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return f"{value:.3g}" if abs(value) < 1e4 else f"{value:.0f}"
    return str(value)


def table(rows: list[dict[str, Any]], columns: Sequence[str]) -> str:
    head = "| " + " | ".join(columns) + " |\n|" + "---|" * len(columns) + "\n"
    return head + "".join("| " + " | ".join(_fmt(r.get(c)) for c in columns) + " |\n"
                          for r in rows)


def ratio_panels(panels: dict[str, dict[str, list[dict[str, Any]]]], x_key: str, xlabel: str,
                 path: Path) -> None:
    """One panel per title, one line per label: ``rmse_ratio`` against ``x_key`` (log x), the
    noisy input's level drawn at 1."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(panels), figsize=(4.3 * len(panels), 3.4), squeeze=False)
    for ax, (title, lines) in zip(axes[0], panels.items()):
        for label, sel in lines.items():
            sel = sorted(sel, key=lambda r: r[x_key])
            ax.plot([r[x_key] for r in sel], [r["rmse_ratio"] for r in sel], "o-", label=label)
        ax.axhline(1.0, color="k", lw=0.8)
        ax.set(xscale="log", title=title, xlabel=xlabel, ylabel="RMSE / noisy RMSE")
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    save(fig, path)
    plt.close(fig)


def plot54(rows: list[dict[str, Any]], path: Path) -> None:
    panels = {}
    for scene in sorted({r["scene"] for r in rows}):
        panels[scene] = {
            (t if t == "identity" else f"{t} λ={lam}"):
                [r for r in rows if r["scene"] == scene and r["transform"] == t
                 and (t == "identity" or r["lam"] == lam)]
            for t, lam in TRANSFORMS}
    ratio_panels(panels, "gamma", "γ", path)


def plot55(rows: list[dict[str, Any]], path: Path) -> None:
    panels = {f"r_s = {r_s}": {f"r_t = {r_t}": [r for r in rows if r["radius"] == r_s
                                                and r["radius_t"] == r_t]
                               for r_t in sorted({r["radius_t"] for r in rows})}
              for r_s in sorted({r["radius"] for r in rows})}
    ratio_panels(panels, "bin_width_ps", "bin width (ps)", path)


def plot56(rows: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = sorted({r["scene"] for r in rows})
    fig, axes = plt.subplots(2, len(scenes), figsize=(4.2 * len(scenes), 6.4), squeeze=False)
    for col, scene in enumerate(scenes):
        for method in FIG56_METHODS:
            sel = [r for r in rows if r["scene"] == scene and r["method"] == method]
            if not sel:
                continue
            x = [r["spp"] for r in sel]
            axes[0][col].errorbar(x, [r["rmse"] for r in sel],
                                  yerr=[r.get("rmse_ci") or 0.0 for r in sel], marker="o",
                                  capsize=2, label=method)
            axes[1][col].errorbar(x, [r["psnr"] for r in sel],
                                  yerr=[r.get("psnr_ci") or 0.0 for r in sel], marker="o",
                                  capsize=2, label=method)
        axes[0][col].set(xscale="log", yscale="log", title=scene, ylabel="RMSE (all voxels)")
        axes[1][col].set(xscale="log", xlabel="spp", ylabel="PSNR of the integrated image, dB")
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    save(fig, path)
    plt.close(fig)


def fig56_summary(rows: list[dict[str, Any]]) -> str:
    """Markdown: each method's mean RMSE ÷ the noisy input's (all voxels) and its PSNR gain on
    the time-integrated image (dB, ± the 95 % interval over the seeds), per scene and spp."""
    by = {(r["scene"], r["spp"], r["method"]): r for r in rows}
    methods = [m for m in FIG56_METHODS if m != "noisy"]
    text = ("| scene | spp | noisy RMSE | " + " | ".join(f"{m} RMSE ÷ noisy" for m in methods)
            + " | " + " | ".join(f"{m} Δ PSNR integrated, dB" for m in methods) + " |\n|"
            + "---|" * (3 + 2 * len(methods)) + "\n")
    for scene, spp in sorted({(r["scene"], r["spp"]) for r in rows}):
        noisy = by.get((scene, spp, "noisy"))
        if noisy is None:
            continue
        cells = []
        for m in methods:
            r = by.get((scene, spp, m))
            ratio = r["rmse"] / noisy["rmse"] if r else float("nan")
            cells.append(f"**{ratio:.3f}**" if ratio >= 1 else f"{ratio:.3f}")
        for m in methods:
            r = by.get((scene, spp, m))
            gain = r["psnr"] - noisy["psnr"] if r else float("nan")
            text_gain = f"{gain:+.2f} ± {r.get('psnr_ci') or 0:.2f}" if r else ""
            cells.append(f"**{text_gain}**" if gain <= 0 else text_gain)
        text += (f"| {scene} | {spp} | {noisy['rmse']:.3g} ± {noisy.get('rmse_ci') or 0:.2g} | "
                 + " | ".join(cells) + " |\n")
    return text + "\n**Bold**: not better than the noisy input. The full cells follow.\n\n"


def ablation_table(rows: list[dict[str, Any]]) -> str:
    """Markdown: per scene, whole-video ÷ noisy / integrated ÷ noisy, bold where ≥ 1."""
    def cell(r):
        return " / ".join(f"**{x:.3f}**" if x >= 1 else f"{x:.3f}"
                          for x in (r["rmse_ratio"], r["rmse_integrated_ratio"]))

    text = ""
    for scene in dict.fromkeys(r["scene"] for r in rows):
        sel = [r for r in rows if r["scene"] == scene]
        spps = sorted({r["spp"] for r in sel})
        text += (f"**{scene}** (whole-video RMSE ÷ noisy / time-integrated-image RMSE ÷ noisy; "
                 f"reference {sel[0]['ref_spp']} spp, its own RMSE {sel[0]['ref_rmse']:.2g})\n\n"
                 "| variant | base | " + " | ".join(f"{n} spp" for n in spps) + " |\n|---|---|"
                 + "---:|" * len(spps) + "\n")
        for name, _ in ABLATION:
            for base in dict.fromkeys(r["base"] for r in sel):
                by_spp = {r["spp"]: r for r in sel if r["variant"] == name and r["base"] == base}
                text += (f"| {name} | {base} | "
                         + " | ".join(cell(by_spp[n]) for n in spps) + " |\n")
        noisy = ", ".join(f"{next(r for r in sel if r['spp'] == n)['noisy_rmse']:.3g}"
                          for n in spps)
        text += f"\nNoisy RMSE: {noisy}.\n\n"
    return text


COLUMNS = {
    "fig5.4": ("scene", "transform", "lam", "gamma", "rmse_ratio", "rmse_unbiased_ratio",
               "rmse_integrated_ratio", "noisy_rmse", "ref_rmse"),
    "fig5.5": ("bins", "bin_width_mm", "bin_width_ps", "radius", "radius_t", "auto_radius_t",
               "rmse_ratio",
               "rmse_unbiased_ratio", "rmse_integrated_ratio", "noisy_rmse"),
    "fig5.6": ("scene", "spp", "method", "rmse", "rmse_ci", "rmse_unbiased", "psnr", "psnr_ci",
               "ssim", "ref_spp", "ref_rmse"),
    "ablation": (),
}
TITLES = {
    "fig5.4": "Statistical denoiser: sample transform × λ × γ (seed Fig. 5.4)",
    "fig5.5": "Statistical denoiser: temporal radius × bin width × spatial radius (seed Fig. 5.5)",
    "fig5.6": "Transient error against spp: noisy, statistical, jbf-bins, oidn-bins (seed Fig. 5.6)",
    "ablation": "Statistical denoiser on transient scenes: its rules one at a time",
}


def build_parser() -> Parser:
    """The options of :func:`main` (each single-valued one given at most once)."""
    parser = Parser(prog="python -m dbench.studies.transient_studies",
                    description=__doc__.split("\n")[0])
    parser.add_argument("study", choices=sorted(COLUMNS), help="fig5.4 (sample transform × "
                        "λ × γ), fig5.5 (temporal radius × bin width), fig5.6 (error against "
                        "spp, a sweep) or ablation (the statistical denoiser's rules one at a "
                        "time)")
    parser.add_argument("--out", default="results/transient_studies", help="folder of "
                        "<study>.json, <study>.md and <study>.png")
    parser.add_argument("--res", type=int, default=64, help="side of the square renders")
    parser.add_argument("--spp", type=int, default=256, help="spp of the noisy input of fig5.4 "
                        "and fig5.5 (fig5.6 and ablation run 16 ... 2048)")
    parser.add_argument("--ref-spp", type=int, default=None,
                        help="default 16384 (fig5.4, fig5.6) or 4096 (fig5.5); "
                        "ablation sets its own")
    parser.add_argument("--scenes", default=",".join(SCENES), help="comma list of transient "
                        "scenes (fig5.5: the first)")
    return parser


def main(argv: list[str] | None = None) -> None:
    args = build_parser().parse_args(argv)
    out = Path(args.out)
    io.ensure_writable_dir(out, "--out")
    scenes = [s for s in args.scenes.split(",") if s]
    t0 = time.perf_counter()
    if args.study == "fig5.4":
        rows = fig54(scenes, args.res, args.spp, args.ref_spp or 16384)
        plot54(rows, out / "fig5.4.png")
    elif args.study == "fig5.5":
        rows = fig55(scenes[0], args.res, args.spp, args.ref_spp or 4096)
        plot55(rows, out / "fig5.5.png")
    elif args.study == "fig5.6":
        rows = fig56(out, scenes, args.res, ref_spp=args.ref_spp or 16384)
        plot56(rows, out / "fig5.6.png")
        runs = io.read_json(out / "sweep" / "sweep.json").get("runs", [])
        sweep_s = sum(float(r.get("wall_s") or 0.0) for r in runs)
    else:
        rows = ablation(scenes, args.res)
    seconds = time.perf_counter() - t0
    if args.study == "fig5.6":
        seconds = max(seconds, sweep_s)     # the sweep's own compute time, over its runs
    io.write_json(out / f"{args.study}.json", {"rows": rows, "wall_s": seconds})
    cmd = f"python -m dbench.studies.transient_studies {args.study} --out {args.out}"
    figure = "" if args.study == "ablation" else f"![{args.study}]({args.study}.png)\n\n"
    body = ablation_table(rows) if args.study == "ablation" else table(rows, COLUMNS[args.study])
    if args.study == "fig5.6":
        body = fig56_summary(rows) + body
    text = (f"# {TITLES[args.study]}\n\nGenerated by `{cmd}` in {seconds:.0f} s (2-core CPU). "
            f"64 × 64 px, each scene's 200-bin window unless a table says otherwise. Ratios are "
            f"to the noisy input of the same render; `rmse_unbiased` removes the reference's own "
            f"variance (docs/judging.md §2); `rmse_integrated` and `psnr` are those of the "
            f"time-integrated image (Σ over bins)" + (", the sweep's means over 3 seeds with "
            "95 % t-intervals" if args.study == "fig5.6" else "") + ".\n\n" + figure + body)
    io.write_text(out / f"{args.study}.md", text)
    print(f"wrote {out / (args.study + '.md')}")


if __name__ == "__main__":
    main()
