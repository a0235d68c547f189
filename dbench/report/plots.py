"""Figures from sweep cells (matplotlib → PNG with fixed metadata, so the same cells give the
same bytes).

* :func:`convergence_plot`: RMSE against spp, one panel per scene;
* :func:`error_time_plot`: error against total time (render + denoise), one panel per scene, one
  line per method label through its spp points, the noisy input dashed, and the lower envelope
  over every point ("best method for a budget of t seconds").

Every method label gets a distinct colour *and* marker / line style from a fixed assignment by
sorted label (:func:`method_styles`), and the legend is shared, outside the panels.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from .. import io

COLORS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2",
          "#bcbd22", "#17becf", "#7f7f7f", "#393b79", "#637939", "#8c6d31", "#843c39",
          "#7b4173", "#3182bd")
MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*", "<", ">", "h", "p", "d")
LINESTYLES = ("-", "-.", ":", (0, (5, 1.5)))
NOISY_STYLE = {"color": "#333333", "marker": "x", "ls": "--"}
ENVELOPE_LABEL = "best method for a budget of t seconds"


def method_styles(labels) -> dict[str, dict]:
    """label → {color, marker, ls}: the noisy input dark grey and dashed; the others by their
    position among the sorted labels, so that neighbours (``statistical``,
    ``statistical+gate``) differ in colour, marker and line style."""
    others = sorted({str(lab) for lab in labels} - {"noisy"})
    styles = {"noisy": dict(NOISY_STYLE)}
    for i, lab in enumerate(others):
        styles[lab] = {"color": COLORS[i % len(COLORS)], "marker": MARKERS[i % len(MARKERS)],
                       "ls": LINESTYLES[i % len(LINESTYLES)]}
    return styles


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.rcParams.update({"svg.hashsalt": "dbench", "figure.max_open_warning": 0})
    return plt


def save(fig, path: Path, dpi: int = 100) -> None:
    """PNG with fixed metadata (no software version or date), written atomically."""
    with io.atomic_path(path, suffix=".tmp.png") as tmp:
        fig.savefig(tmp, dpi=dpi, format="png", metadata={"Software": None},
                    bbox_inches="tight")


def _panels(plt, n: int, extra_w: float = 2.6):
    cols = max(1, min(3, n))
    rows = max(1, int(np.ceil(n / cols)))
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols + extra_w, 3.5 * rows),
                             squeeze=False)
    for ax in axes.ravel()[n:]:
        ax.set_axis_off()
    return fig, axes


def _plain_log_ticks(ax) -> None:
    """No labels on minor log ticks (they overlap on narrow ranges)."""
    from matplotlib.ticker import NullFormatter

    ax.xaxis.set_minor_formatter(NullFormatter())
    ax.yaxis.set_minor_formatter(NullFormatter())


def _legend(fig, handles: dict) -> None:
    if handles:
        fig.legend(list(handles.values()), list(handles.keys()), loc="center left",
                   bbox_to_anchor=(1.0, 0.5), fontsize=8, frameon=False)


def _log_axes(ax, title: str, xlabel: str, ylabel: str, xbase: float = 10) -> None:
    """Log-log axes with plain tick labels, a title, labels and a light grid."""
    ax.set_xscale("log", base=xbase)
    ax.set_yscale("log")
    _plain_log_ticks(ax)
    ax.set_title(title, fontsize=10)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(True, which="both", alpha=0.3)


def _drawable(df: pd.DataFrame, metric: str) -> pd.DataFrame:
    """The rows a log axis can show: a finite, positive ``metric``."""
    if metric not in df.columns or not len(df):
        return df.iloc[0:0]
    v = pd.to_numeric(df[metric], errors="coerce")
    return df[np.isfinite(v) & (v > 0)]


def convergence_plot(df: pd.DataFrame, path: Path, metric: str = "rmse") -> bool:
    """``metric`` against spp (log-log), one panel per scene with a value; returns False when
    no cell has a finite, positive one (no finished cell, every value NaN) and then draws
    nothing and removes the figure an earlier report drew at ``path``, as
    :func:`error_time_plot` does."""
    ok = _drawable(df, metric)
    scenes = sorted(ok.scene.unique())
    if not scenes:
        Path(path).unlink(missing_ok=True)
        return False
    plt = _plt()
    styles = method_styles(df.method.unique())
    fig, axes = _panels(plt, len(scenes))
    handles = {}
    for ax, scene in zip(axes.ravel(), scenes):
        d = ok[ok.scene == scene]
        for method in sorted(d.method.unique()):
            m = d[d.method == method].sort_values("spp")
            st = styles[method]
            (h,) = ax.plot(m.spp, m[metric], ms=4, lw=1.2, label=method, **st)
            handles.setdefault(method, h)
        _log_axes(ax, scene, "spp", metric, xbase=2)
    fig.tight_layout()
    _legend(fig, dict(sorted(handles.items())))
    save(fig, path)
    plt.close(fig)
    return True


def lower_envelope(points: pd.DataFrame, metric: str) -> pd.DataFrame:
    """For each point's total time t (ascending): the lowest ``metric`` among points with
    total_s ≤ t, and the method that owns it (rows where the envelope changes)."""
    p = points[np.isfinite(points.total_s) & (points.total_s > 0)
               & np.isfinite(points[metric]) & (points[metric] > 0)]
    p = p.sort_values(["total_s", metric, "method"])
    rows, best = [], None
    for _, r in p.iterrows():
        if best is None or r[metric] < best[1]:
            best = (r.method, float(r[metric]))
            rows.append({"total_s": float(r.total_s), metric: best[1], "method": best[0],
                         "spp": int(r.spp)})
    return pd.DataFrame(rows, columns=["total_s", metric, "method", "spp"])


def error_time_plot(df: pd.DataFrame, metric: str, path: Path) -> bool:
    """Error (log) against render + denoise time (log), one panel per scene; returns False
    when no cell has both, and then removes the figure an earlier report drew at ``path`` (the
    README says there is none, and the results page shows every PNG of the sweep folder)."""
    plt = _plt()
    ok = df[np.isfinite(df.get(metric, pd.Series(np.nan, index=df.index)))
            & np.isfinite(df.total_s)] if metric in df.columns else df.iloc[0:0]
    ok = ok[(ok[metric] > 0) & (ok.total_s > 0)] if len(ok) else ok
    scenes = sorted(ok.scene.unique())
    if not scenes:
        Path(path).unlink(missing_ok=True)
        return False
    styles = method_styles(df.method.unique())
    fig, axes = _panels(plt, len(scenes), extra_w=3.2)
    handles = {}
    for ax, scene in zip(axes.ravel(), scenes):
        d = ok[ok.scene == scene]
        for method in sorted(d.method.unique()):
            m = d[d.method == method].sort_values("spp")
            (h,) = ax.plot(m.total_s, m[metric], ms=4, lw=1.1, alpha=0.9, label=method,
                           **styles[method])
            handles.setdefault(method, h)
        env = lower_envelope(d, metric)
        if len(env):
            xs = list(env.total_s) + [float(d.total_s.max()) * 1.15]
            ys = list(env[metric]) + [float(env[metric].iloc[-1])]
            (h,) = ax.step(xs, ys, where="post", color="black", lw=2.4, alpha=0.35, zorder=0)
            handles.setdefault(ENVELOPE_LABEL, h)
            owners = env[env.method.ne(env.method.shift())]
            if len(owners) <= 6:
                for _, r in owners.iterrows():
                    ax.annotate(r.method, (r.total_s, r[metric]), xytext=(2, -9),
                                textcoords="offset points", fontsize=6,
                                color=styles[r.method]["color"])
        _log_axes(ax, scene, "render + denoise time (s)", metric)
    fig.suptitle(f"{metric} against time (points: spp ladder of each method)", fontsize=10)
    fig.tight_layout()
    env_h = handles.pop(ENVELOPE_LABEL, None)
    ordered = dict(sorted(handles.items()))
    if env_h is not None:
        ordered[ENVELOPE_LABEL] = env_h
    _legend(fig, ordered)
    save(fig, path)
    plt.close(fig)
    return True


__all__ = ["method_styles", "convergence_plot", "error_time_plot", "lower_envelope", "save",
           "ENVELOPE_LABEL"]
