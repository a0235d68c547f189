"""Tables and plots from sweep cells (pandas → CSV / Markdown, matplotlib → PNG).

* convergence: for each metric, scene × spp with a column per method (ProDen's layout);
* error against time: denoise, render and total time per method, scene and spp;
* equal time: the spp at which plain rendering reaches the method's RMSE (from a log-log fit of
  the noisy input's RMSE against spp on the same scene) and the time saved (positive) or lost
  (negative) against rendering that many samples instead.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from .. import io
from .report import markdown_table


def cells_frame(cells: list[dict]) -> pd.DataFrame:
    ok = [c for c in cells if c.get("status") == "ok"]
    cols = ["scene", "method", "spp", "res", "rmse", "relmse", "smape", "psnr", "ssim", "flip",
            "t_rmse", "tpsnr", "time_s", "render_s", "stats_s"]
    df = pd.DataFrame([{k: c.get(k, np.nan) for k in cols} for c in ok], columns=cols)
    df["render_s"] = df["render_s"].astype(float) + df["stats_s"].fillna(0).astype(float)
    df["total_s"] = df["render_s"] + df["time_s"]
    temporal = [c for c in ("t_rmse", "tpsnr") if df[c].isna().all()]  # sequence cells only
    return df.drop(columns=["stats_s"] + temporal)


def convergence_table(df: pd.DataFrame, metric: str) -> pd.DataFrame:
    """Rows (scene, method), columns spp."""
    t = df.pivot_table(index=["scene", "method"], columns="spp", values=metric, aggfunc="first")
    t.columns = [f"{c} spp" for c in t.columns]
    return t.reset_index()


def noisy_fit(df: pd.DataFrame, scene: str) -> tuple[float, float] | None:
    """Least-squares fit log RMSE = a + b log spp of the noisy input on ``scene``."""
    d = df[(df.scene == scene) & (df.method == "noisy")].dropna(subset=["rmse"])
    d = d[d.rmse > 0]
    if len(d) < 2:
        return None
    b, a = np.polyfit(np.log(d.spp.astype(float)), np.log(d.rmse.astype(float)), 1)
    return float(a), float(b)


def render_cost_per_spp(df: pd.DataFrame, scene: str) -> float:
    """Seconds per spp of plain sample rendering on ``scene`` (median over the ladder)."""
    d = df[(df.scene == scene) & (df.method == "noisy")]
    per = (d.render_s / d.spp).replace([np.inf, -np.inf], np.nan).dropna()
    return float(per.median()) if len(per) else float("nan")


def equal_time_table(df: pd.DataFrame) -> pd.DataFrame:
    rows = []
    for scene in sorted(df.scene.unique()):
        fit = noisy_fit(df, scene)
        cost = render_cost_per_spp(df, scene)
        for r in df[(df.scene == scene) & (df.method != "noisy")].itertuples():
            if fit is None or not np.isfinite(r.rmse) or r.rmse <= 0:
                eq_spp = np.nan
            else:
                a, b = fit
                eq_spp = float(np.exp((np.log(r.rmse) - a) / b)) if b < 0 else np.nan
            eq_time = eq_spp * cost
            rows.append({"scene": scene, "method": r.method, "spp": r.spp, "rmse": r.rmse,
                         "equal_rmse_spp": eq_spp, "render_s": r.render_s,
                         "denoise_s": r.time_s, "total_s": r.total_s,
                         "equal_rmse_render_s": eq_time,
                         "time_saved_s": eq_time - r.total_s})
    return pd.DataFrame(rows)


def headline_table(df: pd.DataFrame, spp: int) -> pd.DataFrame:
    d = df[df.spp == spp]
    if d.empty:
        return d
    cols = ["scene", "method", "rmse", "ssim", "flip", "time_s"]
    return d[cols].sort_values(["scene", "method"]).reset_index(drop=True)


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.rcParams.update({"svg.hashsalt": "dbench", "figure.max_open_warning": 0})
    return plt


def _save(fig, path: Path) -> None:
    # Fixed metadata so the same data gives the same PNG bytes.
    with io.atomic_path(path, suffix=".tmp.png") as tmp:
        fig.savefig(tmp, dpi=100, format="png", metadata={"Software": None})


def convergence_plot(df: pd.DataFrame, path: Path) -> None:
    plt = _plt()
    scenes = sorted(df.scene.unique())
    n = len(scenes)
    cols = min(3, n)
    rows = int(np.ceil(n / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.4 * rows), squeeze=False)
    for ax, scene in zip(axes.ravel(), scenes):
        d = df[df.scene == scene]
        for method in sorted(d.method.unique()):
            m = d[d.method == method].sort_values("spp")
            ax.plot(m.spp, m.rmse, marker="o", ms=3, label=method,
                    ls="--" if method == "noisy" else "-")
        ax.set_xscale("log", base=2)
        ax.set_yscale("log")
        ax.set_title(scene, fontsize=10)
        ax.set_xlabel("spp")
        ax.set_ylabel("RMSE")
        ax.grid(True, which="both", alpha=0.3)
    for ax in axes.ravel()[n:]:
        ax.set_axis_off()
    axes[0, 0].legend(fontsize=7)
    fig.tight_layout()
    _save(fig, path)
    plt.close(fig)


def pareto_plot(df: pd.DataFrame, path: Path) -> None:
    """Total time (render + denoise) against RMSE relative to the noisy input at the same spp."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    base = df[df.method == "noisy"].set_index(["scene", "spp"]).rmse
    d = df.copy()
    d["rel_rmse"] = [r.rmse / base.get((r.scene, r.spp), np.nan) for r in d.itertuples()]
    for method in sorted(d.method.unique()):
        m = d[d.method == method]
        ax.scatter(m.total_s, m.rel_rmse, s=14, label=method, alpha=0.8)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.axhline(1.0, color="grey", lw=0.8, ls="--")
    ax.set_xlabel("render + denoise time (s)")
    ax.set_ylabel("RMSE / noisy RMSE at the same spp")
    ax.set_title("error against time (every scene and spp)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    _save(fig, path)
    plt.close(fig)


def write_tables(df: pd.DataFrame, out: Path) -> dict[str, Path]:
    """CSV files of every table under ``out``; returns their paths."""
    from .report import write_csv

    paths = {}
    for metric in ("rmse", "relmse", "smape", "psnr", "ssim", "flip"):
        p = out / f"convergence_{metric}.csv"
        write_csv(p, convergence_table(df, metric))
        paths[f"convergence_{metric}"] = p
    paths["equal_time"] = out / "equal_time.csv"
    write_csv(paths["equal_time"], equal_time_table(df))
    paths["cells"] = out / "cells.csv"
    write_csv(paths["cells"], df.sort_values(["scene", "spp", "method"]))
    return paths


__all__ = ["cells_frame", "convergence_table", "equal_time_table", "headline_table",
           "convergence_plot", "pareto_plot", "write_tables", "markdown_table"]
