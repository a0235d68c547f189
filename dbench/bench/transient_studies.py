"""The seed's transient studies (seed 000 Fig. 5.4-5.6), one command each.

* ``fig5.4``: sample transform × λ × γ of the statistical denoiser on the transient scenes
  (spec/statistical.md §3, §5.1, §11.3), at one spp;
* ``fig5.5``: temporal radius r_t × bin width, the spatial radius r_s as a second axis, on one
  scene (the window stays the scene's, so the bin count sets the width);
* ``fig5.6``: error against spp (16 … 2048) for the noisy input, ``statistical``, ``jbf-bins``
  and ``oidn-bins``: a ``dbench sweep`` over the transient scenes (3 seeds, 95 % intervals),
  then its figure.

Each writes ``<out>/<study>.json`` (every number), ``<out>/<study>.md`` (the table) and
``<out>/<study>.png`` (the figure). Figures and tables give the error as a ratio to the noisy
input's of the same render: whole-video RMSE, its unbiased version (the reference's own variance
removed, spec/verdicts.md §2) and the RMSE of the time-integrated image (Σ over bins).

Reproduce::

    python -m dbench.bench.transient_studies fig5.4 --out results/transient_studies
    python -m dbench.bench.transient_studies fig5.5 --out results/transient_studies
    python -m dbench.bench.transient_studies fig5.6 --out results/transient_studies
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .. import io
from .plots import save

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
    out = method.denoise(frame)
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
    from ..datasets import load, scenes as catalogue

    sc = catalogue.get(scene)
    rows = []
    for bins in bins_list:
        frame = load(scene, spp, res, seed=seed, ref_spp=ref_spp, bins=bins, progress=False)
        width = sc.window(bins).bin_width_opl
        noisy = score(frame.color, frame)
        for r_s in radii_s:
            for r_t in radii_t:
                out, seconds = _denoise(frame, radius=r_s, radius_t=r_t)
                den = score(out, frame)
                rows.append({"scene": scene, "bins": bins, "bin_width_mm": 1000.0 * width,
                             "bin_width_ps": 1e12 * width / 299792458.0, "radius": r_s,
                             "radius_t": r_t, "spp": spp, "res": res, "ref_spp": ref_spp,
                             "ref_rmse": frame.meta.get("ref_rmse"), "time_s": seconds,
                             **{f"noisy_{k}": v for k, v in noisy.items()}, **den,
                             **_ratios(den, noisy)})
    return rows


def fig56(out: Path, scenes: Sequence[str] = SCENES, res: int = 64,
          spp: Sequence[int] = FIG56_SPP, ref_spp: int = 16384, seeds: int = 3,
          sweep_out: Path | None = None) -> list[dict[str, Any]]:
    """RMSE against spp (seed Fig. 5.6): runs (or resumes) the sweep, then reads its cells."""
    from .sweep import SweepConfig, load_cells, run_sweep

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


def plot54(rows: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scenes = sorted({r["scene"] for r in rows})
    fig, axes = plt.subplots(1, len(scenes), figsize=(4.2 * len(scenes), 3.4), squeeze=False)
    for ax, scene in zip(axes[0], scenes):
        for transform, lam in TRANSFORMS:
            sel = [r for r in rows if r["scene"] == scene and r["transform"] == transform
                   and (transform == "identity" or r["lam"] == lam)]
            label = transform if transform == "identity" else f"{transform} λ={lam}"
            ax.plot([r["gamma"] for r in sel], [r["rmse_ratio"] for r in sel], "o-",
                    label=label)
        ax.axhline(1.0, color="k", lw=0.8)
        ax.set_xscale("log")
        ax.set_title(scene)
        ax.set_xlabel("γ")
        ax.set_ylabel("RMSE / noisy RMSE")
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    save(fig, path)
    plt.close(fig)


def plot55(rows: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    radii_s = sorted({r["radius"] for r in rows})
    fig, axes = plt.subplots(1, len(radii_s), figsize=(4.4 * len(radii_s), 3.4), squeeze=False)
    for ax, r_s in zip(axes[0], radii_s):
        for r_t in sorted({r["radius_t"] for r in rows}):
            sel = sorted((r for r in rows if r["radius"] == r_s and r["radius_t"] == r_t),
                         key=lambda r: r["bin_width_ps"])
            ax.plot([r["bin_width_ps"] for r in sel], [r["rmse_ratio"] for r in sel], "o-",
                    label=f"r_t = {r_t}")
        ax.axhline(1.0, color="k", lw=0.8)
        ax.set_xscale("log")
        ax.set_title(f"r_s = {r_s}")
        ax.set_xlabel("bin width (ps)")
        ax.set_ylabel("RMSE / noisy RMSE")
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    save(fig, path)
    plt.close(fig)


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


COLUMNS = {
    "fig5.4": ("scene", "transform", "lam", "gamma", "rmse_ratio", "rmse_unbiased_ratio",
               "rmse_integrated_ratio", "noisy_rmse", "ref_rmse"),
    "fig5.5": ("bins", "bin_width_mm", "bin_width_ps", "radius", "radius_t", "rmse_ratio",
               "rmse_unbiased_ratio", "rmse_integrated_ratio", "noisy_rmse"),
    "fig5.6": ("scene", "spp", "method", "rmse", "rmse_ci", "rmse_unbiased", "psnr", "psnr_ci",
               "ssim", "ref_spp", "ref_rmse"),
}
TITLES = {
    "fig5.4": "Statistical denoiser: sample transform × λ × γ (seed Fig. 5.4)",
    "fig5.5": "Statistical denoiser: temporal radius × bin width × spatial radius (seed Fig. 5.5)",
    "fig5.6": "Transient error against spp: noisy, statistical, jbf-bins, oidn-bins (seed Fig. 5.6)",
}


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("study", choices=sorted(COLUMNS))
    parser.add_argument("--out", default="results/transient_studies")
    parser.add_argument("--res", type=int, default=64)
    parser.add_argument("--spp", type=int, default=256, help="fig5.4 / fig5.5")
    parser.add_argument("--ref-spp", type=int, default=None,
                        help="default 16384 (fig5.4, fig5.6) or 4096 (fig5.5)")
    parser.add_argument("--scenes", default=",".join(SCENES))
    args = parser.parse_args(argv)
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
    else:
        rows = fig56(out, scenes, args.res, ref_spp=args.ref_spp or 16384)
        plot56(rows, out / "fig5.6.png")
    seconds = time.perf_counter() - t0
    io.write_json(out / f"{args.study}.json", {"rows": rows, "wall_s": seconds})
    cmd = f"python -m dbench.bench.transient_studies {args.study} --out {args.out}"
    text = (f"# {TITLES[args.study]}\n\nGenerated by `{cmd}` in {seconds:.0f} s. Ratios are to "
            f"the noisy input of the same render; `rmse_unbiased` removes the reference's own "
            f"variance (spec/verdicts.md §2); `rmse_integrated` is the RMSE of the "
            f"time-integrated image.\n\n![{args.study}]({args.study}.png)\n\n"
            + table(rows, COLUMNS[args.study]))
    io.write_text(out / f"{args.study}.md", text)
    print(f"wrote {out / (args.study + '.md')}")


if __name__ == "__main__":
    main()
