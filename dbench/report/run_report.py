"""Run reports and pictures: the Markdown report of one ``dbench run``, matplotlib → PNG
comparison grids (CSV and Markdown tables themselves: :mod:`dbench.report.formats`).

The report reads results; it never renders or denoises. Every file is written atomically.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Sequence

import numpy as np
import pandas as pd

from .. import io, metrics
from ..resolution import size_text
from . import headline, verdicts
from .formats import cores_text, markdown_text
from .tables import cells_frame

#: Headline columns of a sequence run (steady and transient runs: verdicts.HEADLINE).
SEQUENCE_COLUMNS = verdicts.headline_columns("sequence")


def metric_definitions_md() -> str:
    """The metric definitions from the metric records, then the verdicts' own quantities
    (ref_rmse, interval kinds) and the tone map (:func:`dbench.report.verdicts.definitions`)."""
    lines = [f"- **{name}**: {text}" for name, text in verdicts.definitions().items()]
    lines.append(f"- Tone map: {metrics.TONEMAP_DEFINITION}")
    return "\n".join(lines)


def machine_md(info: dict[str, Any]) -> str:
    pk = ", ".join(f"{k} {v}" for k, v in info["packages"].items())
    memory = f"\n- Memory: {info['memory']}" if info.get("memory") else ""
    # usable: taskset, a container's cpuset or CPU quota (older records lack it)
    cores = cores_text(info.get("usable_cores"), info.get("cores"))
    return (f"- CPU: {info['cpu']} ({cores}); GPU: {info['gpu']}\n"
            f"- Python {info['python']} on {info['platform']}\n- Packages: {pk}{memory}")


def error_map(output: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Per-pixel relative error |x − r| / (|r| + 0.01), channel mean, (H, W), in float64: an
    output of 3e38 (allowed by the method contract, README.md "Add your own denoiser") would
    overflow float32 here and in the plot's colour mapping."""
    # inf stays inf (nan_to_num's default, the largest float, overflows the division)
    out = np.nan_to_num(np.asarray(output, dtype=np.float64), nan=1e6, posinf=np.inf,
                        neginf=-np.inf)
    ref = np.asarray(reference, dtype=np.float64)
    err = np.abs(out - ref) / (np.abs(ref) + 1e-2)
    return err.mean(axis=-1)


def zoom_window(reference: np.ndarray, outputs: Sequence[np.ndarray] = (), ev: float = 0.0,
                frac: float = 0.25) -> tuple[int, int, int]:
    """(y0, x0, size) of the square inset shown zoomed in comparison grids, of side ``frac`` ×
    the shorter image side: where the outputs' tone-mapped errors against the reference sum
    highest (where the methods go wrong), or, without outputs, where the reference varies most."""
    from scipy.ndimage import uniform_filter

    ref = metrics.tonemap(np.nan_to_num(reference), ev=ev).astype(np.float64)
    h, w = ref.shape[:2]
    size = min(h, w, max(2, int(round(min(h, w) * frac))))  # 1 on a 1-pixel image
    if len(outputs):
        score = sum(np.abs(metrics.tonemap(np.nan_to_num(o), ev=ev) - ref).mean(-1)
                    for o in outputs)
        score = uniform_filter(score, size, mode="nearest")
    else:
        lum = ref.mean(-1)
        mean = uniform_filter(lum, size, mode="nearest")
        score = uniform_filter(lum * lum, size, mode="nearest") - mean * mean
    lo, hi_y, hi_x = size // 2, h - (size - size // 2), w - (size - size // 2)
    inner = score[lo:hi_y + 1, lo:hi_x + 1]
    cy, cx = np.unravel_index(int(np.argmax(inner)), inner.shape)
    return int(cy), int(cx), size


def error_map_title(output: np.ndarray, reference: np.ndarray) -> str:
    """Title of an :func:`error_map` panel: what the map shows and the figure it illustrates,
    the output's relMSE (mean((x − r)² / (r² + ε))) and its mean relative error (rMAE, the
    map's mean)."""
    if not np.all(np.isfinite(output)):
        return "relative error map\n(non-finite output)"
    rel = metrics.compute("relmse", output, reference)
    rmae = float(error_map(output, reference).mean())
    # one figure a line: side by side they are wider than a panel of the grid
    return f"relative error map\nrelMSE {rel:.3g}\nmap mean {rmae:.3g}"


def comparison_grid(path: str | Path, images: Sequence[tuple[str, np.ndarray]],
                    reference: np.ndarray | None, ev: float = 0.0,
                    title: str = "") -> None:
    """PNG grid: the tone-mapped images (the zoomed window outlined), the zoomed inset of each
    (:func:`zoom_window`), and their relative error maps (:func:`comparison_figure`)."""
    import matplotlib.pyplot as plt

    fig = comparison_figure(images, reference, ev, title)
    with io.atomic_path(path, suffix=".tmp.png") as tmp:
        fig.savefig(tmp, dpi=GRID_DPI, format="png", metadata={"Software": None})
    plt.close(fig)


#: Resolution the comparison grid is saved at (its text is laid out for it).
GRID_DPI = 110


def comparison_figure(images: Sequence[tuple[str, np.ndarray]], reference: np.ndarray | None,
                      ev: float = 0.0, title: str = ""):
    """The matplotlib figure of :func:`comparison_grid`, not yet saved."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    cols = list(images) + ([("reference", reference)] if reference is not None else [])
    rows = 3 if reference is not None else 1
    size = 2.6
    # image rows as tall as the images' aspect ratio needs (the zoom row is square)
    h, w = cols[0][1].shape[:2]
    heights = [h / w, 1.0, h / w][:rows]
    fig, axes = plt.subplots(rows, len(cols), squeeze=False,
                             figsize=(size * len(cols), size * sum(heights) + 0.4 * rows),
                             gridspec_kw={"height_ratios": heights},
                             # titles, captions and the colour bar get their own room
                             layout="constrained")
    vmax = 1.0
    denoised = [img for label, img in images if label != "noisy"] or [img for _, img in images]
    zoom = zoom_window(reference, denoised, ev) if reference is not None else None
    for j, (label, img) in enumerate(cols):
        shown = metrics.tonemap(np.nan_to_num(img), ev=ev)
        ax = axes[0, j]
        ax.imshow(shown, interpolation="nearest")
        ax.set_title(label, fontsize=9)
        ax.set_axis_off()
        if zoom is None:
            continue
        y0, x0, side = zoom
        ax.add_patch(Rectangle((x0 - 0.5, y0 - 0.5), side, side, fill=False, ec="cyan", lw=1))
        ax = axes[1, j]
        ax.imshow(shown[y0:y0 + side, x0:x0 + side], interpolation="nearest")
        ax.set_title("zoom", fontsize=8)
        ax.set_axis_off()
        ax = axes[2, j]
        if label == "reference":
            ax.set_axis_off()
            continue
        emap = error_map(img, reference)
        im = ax.imshow(emap, cmap="magma", vmin=0.0, vmax=vmax, interpolation="nearest")
        ax.set_title(error_map_title(img, reference), fontsize=8)
        ax.set_axis_off()
    if rows == 3:
        fig.colorbar(im, ax=axes[2, :].tolist(), shrink=0.8,
                     label="relative error |x−r|/(|r|+0.01)")
    if title:
        fig.suptitle(title, fontsize=10)
    return fig


#: The settings whose values hold the scene's or the methods' names (dbench/run/scene_run.py).
NAMED_SETTINGS = frozenset({"scene", "folder", "scene parameters", "method parameters",
                            "method devices", "resolved settings"})


def run_report_md(table: pd.DataFrame, settings: dict[str, Any], info: dict[str, Any],
                  skipped: dict[str, str], notes: Sequence[str] = (),
                  rank_by: str = "relmse", failed: dict[str, str] | None = None,
                  library_warnings: int | None = None) -> str:
    """The Markdown report of one ``dbench run``.

    ``table``: one row per method label with the columns of
    :func:`dbench.report.tables.cells_frame` (``<metric>_ci``, ``ci_kind``, ``n_seeds``,
    ``ref_spp``, ``ref_rmse``); missing columns are shown as missing, not guessed.
    ``library_warnings``: how many warnings the libraries raised (kept in ``run.log``).
    """
    asked = rank_by
    d, rank_by, cols, shown = _headline(table, settings, rank_by)
    sequence = settings.get("kind") == "sequence"
    parts = [f"# dbench run: {markdown_text(settings['scene'])} at {settings['spp']} spp, "
             f"{size_text(settings['res'])} px", ""]
    if len(d):
        parts += headline.scene_block_md(d, rank_by, shown, asked=asked)
    else:
        parts += ["(no method finished)", ""]
    absent = [c for c in cols if c not in shown]
    parts += ["**Bold**: the best entry of a column and every entry tied with it (the paired "
              "difference over common seeds includes 0; without them, the intervals overlap or one "
              "is missing, shown `± n/a`; the noisy input is not a candidate for the fastest "
              "`time_s`); entries are mean ± 95 % half-width. " + headline.VERDICT_NOTE + " Lower is "
              "better except PSNR, tPSNR, SSIM and cvvdp. " + (
                  "Sequence: every frame is denoised once, in order; metrics are means and "
                  "`time_s` the median per-frame time over the frames after the warm-up "
                  f"({settings['repeats']}); `t_rmse`/`tpsnr` score the frame-to-frame "
                  "differences against the reference's (rendering excluded); `cvvdp` is ColorVideoVDP's "
                  "quality in JOD (10: no visible difference; README.md, Metrics), empty where "
                  "the video is too large for its default."
                  if sequence else
                  "`time_s` is the median denoise time over "
                  f"{headline.timing_words(settings['repeats'], _seed_count(d))} (rendering "
                  "excluded), ± half its interquartile range.")
              + (f" Not recorded: {', '.join(absent)}." if absent else ""), ""]
    warn = verdicts.ref_warnings_md(d) if len(d) else []
    if warn:
        parts += ["## Reference noise", ""] + warn + [""]
    if failed:
        parts += ["## Failed", "", "These methods raised an error or broke the method contract; "
                  "they have no row above, and the run exits with code 4.", ""]
        # the error's text is a library's (``<lambda>``, ``__init__``): escaped as names are
        parts += [f"- **{markdown_text(m)}**: {markdown_text(why)}"
                  for m, why in failed.items()] + [""]
    if skipped:
        parts += ["## Skipped", ""] + [f"- {markdown_text(m)}: {markdown_text(why)}"
                                       for m, why in skipped.items()] + [""]
    if library_warnings is not None:
        n = library_warnings
        parts += ["## Library warnings", "",
                  f"{n} library warning{'s' if n != 1 else ''}, see run.log." if n else
                  "No library warnings (run.log).", ""]
    parts += ["## Settings", ""]
    # the values that name the scene, its folder and the methods are escaped as names; the
    # others are dbench's own words (a scene file's "max_depth", a folder's file names)
    parts += [f"- {k}: {markdown_text(v) if k in NAMED_SETTINGS else v}"
              for k, v in settings.items()]
    parts += ["", "## Metric definitions", "", metric_definitions_md(), "",
              "## Machine", "", machine_md(info), ""]
    if notes:
        parts += ["## Notes", ""] + [f"- {n}" for n in notes] + [""]
    if sequence:
        parts += ["Files: `metrics.csv`, `per_frame_<method>.csv`, `error_per_frame.png`, "
                  "`comparison.png` (frames × methods), the last frame's outputs as EXR in "
                  "`images/`.", ""]
    elif settings.get("kind") == "transient":  # dbench/report/transient_figures.py
        parts += ["Files: `metrics.csv`, `rmse_per_bin.csv` and `rmse_per_bin.png` (error per "
                  "time bin), `bins.png` (four bins side by side), `streak.png` (an x–t slice), "
                  "one EXR per output in `images/`.", ""]
    else:
        parts += ["Files: `metrics.csv`, `comparison.png`, one EXR per output in `images/`.",
                  ""]
    return "\n".join(parts)


def _headline(table: pd.DataFrame, settings: dict[str, Any], rank_by: str
              ) -> tuple[pd.DataFrame, str, Sequence[str], list[str]]:
    """The run's cells frame, the ranking metric in effect (:func:`verdicts.ranking_metric`:
    another where ``rank_by`` has no value), the kind's headline columns and those of them
    with a value."""
    d = _run_frame(table, settings)
    rank_by = verdicts.ranking_metric(d, rank_by)
    cols = SEQUENCE_COLUMNS if settings.get("kind") == "sequence" else verdicts.HEADLINE
    return d, rank_by, cols, [c for c in cols if c in d.columns and d[c].notna().any()]


def run_summary(table: pd.DataFrame, settings: dict[str, Any], rank_by: str = "relmse",
                failed: dict[str, str] | None = None) -> list[str]:
    """The lines ``dbench run`` prints: the report's ranking, intervals and verdicts laid out
    for a terminal (dbench/report/terminal.py), each time with the device it ran on."""
    from .terminal import run_summary as summary

    asked = rank_by
    d, rank_by, _, shown = _headline(table, settings, rank_by)
    devices = ({str(m): str(v) for m, v in zip(table["method"], table["device"])
                if isinstance(v, str)} if {"method", "device"} <= set(table.columns) else {})
    return summary(d, settings, rank_by, shown, devices, asked=asked, failed=failed)


def _seed_count(d: pd.DataFrame) -> int:
    """How many seeds the run's methods were timed on (its ``n_seeds``; 1 where unknown)."""
    n = pd.to_numeric(d["n_seeds"], errors="coerce").max() if "n_seeds" in d.columns else 1
    return int(n) if np.isfinite(n) and n >= 1 else 1


def _run_frame(table: pd.DataFrame, settings: dict[str, Any]) -> pd.DataFrame:
    """The run's table as a cells frame: rows without a method dropped, values coerced to
    numbers (NaN when malformed), ``ref_spp`` and ``ref_rmse`` from the settings only where the
    rows lack them."""
    cells = []
    for rec in table.to_dict("records"):
        c = {k: v for k, v in rec.items() if not (isinstance(v, float) and np.isnan(v))}
        c.setdefault("scene", settings.get("scene"))
        c.setdefault("spp", settings.get("spp"))
        c.setdefault("ref_spp", settings.get("ref_spp"))
        c.setdefault("ref_rmse", settings.get("reference RMSE (estimated)"))
        cells.append({**c, "status": "ok"})
    return cells_frame(cells)
