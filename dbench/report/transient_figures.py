"""Figures of transient videos (matplotlib, PNG): per-bin RMSE curves (:func:`per_bin_table`,
:func:`plot_error_per_bin`), a few bins side by side (:func:`plot_bins`) and an x–t streak image
(one image row over time, :func:`plot_streak`) for noisy, denoised and reference.
:func:`write_figures` writes all three for one run (``dbench run`` on a transient scene, whose
steady comparison grid cannot show a video, and results/transient.md)."""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np
import pandas as pd

from .. import io, metrics
from ..data import TransientFrame


def per_bin_table(outputs: dict[str, np.ndarray], reference: np.ndarray,
                  time_axis: np.ndarray, metric: str = "rmse") -> pd.DataFrame:
    """(T rows) bin, OPL at its centre and the per-bin ``metric`` of every output."""
    table = pd.DataFrame({"bin": np.arange(reference.shape[2]), "opl": time_axis})
    for name, out in outputs.items():
        table[name] = metrics.per_bin(metric, out, reference)
    return table


def _exposure(reference: np.ndarray, percentile: float = 99.5) -> float:
    """EV mapping the reference's ``percentile`` value to 1 (0 if the reference is black)."""
    v = np.percentile(np.asarray(reference, np.float64).mean(axis=-1), percentile)
    return float(-np.log2(v)) if v > 0 else 0.0


def plot_error_per_bin(path: str | Path, table: pd.DataFrame, title: str = "",
                       metric: str = "RMSE") -> None:
    """Per-bin error curves (log scale) against OPL."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.6), dpi=110)
    for name in table.columns[2:]:
        ax.plot(table["opl"], table[name], label=name, lw=1.2)
    ax.set_yscale("log")
    ax.set_xlabel("optical path length (m)")
    ax.set_ylabel(f"{metric} per bin")
    ax.set_title(title)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    with io.atomic_path(path, suffix=".tmp.png") as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)


def plot_bins(path: str | Path, videos: Sequence[tuple[str, np.ndarray]], bins: Sequence[int],
              reference: np.ndarray, time_axis: np.ndarray | None = None,
              title: str = "") -> None:
    """A grid: one row per video, one column per bin, tone-mapped with one exposure per bin
    (from the reference's bin)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows, cols = len(videos), len(bins)
    fig, axes = plt.subplots(rows, cols, figsize=(1.9 * cols, 1.9 * rows + 0.4), dpi=110,
                             squeeze=False)
    for j, t in enumerate(bins):
        ev = _exposure(reference[:, :, t])
        for i, (name, video) in enumerate(videos):
            ax = axes[i, j]
            ax.imshow(metrics.tonemap(np.nan_to_num(video[:, :, t]), ev), interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            if i == 0:
                label = f"bin {t}" if time_axis is None else f"bin {t} ({time_axis[t]:.2f} m)"
                ax.set_title(label, fontsize=8)
            if j == 0:
                ax.set_ylabel(name, fontsize=8)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    with io.atomic_path(path, suffix=".tmp.png") as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)


def streak(video: np.ndarray, row: int) -> np.ndarray:
    """The x–t slice of one image row: (T, W, 3), time going down."""
    return np.transpose(np.asarray(video)[row], (1, 0, 2))


def plot_streak(path: str | Path, videos: Sequence[tuple[str, np.ndarray]], row: int,
                reference: np.ndarray, time_axis: np.ndarray | None = None,
                title: str = "") -> None:
    """Streak images (x horizontal, OPL down) of one row for each video, side by side."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ev = _exposure(streak(reference, row))
    fig, axes = plt.subplots(1, len(videos), figsize=(2.4 * len(videos), 4.2), dpi=110,
                             squeeze=False)
    for ax, (name, video) in zip(axes[0], videos):
        img = metrics.tonemap(np.nan_to_num(streak(video, row)), ev)
        extent = None
        if time_axis is not None:
            half = 0.5 * (time_axis[1] - time_axis[0]) if len(time_axis) > 1 else 0.5
            extent = (0, video.shape[1], time_axis[-1] + half, time_axis[0] - half)
        ax.imshow(img, aspect="auto", interpolation="nearest", extent=extent)
        ax.set_title(name, fontsize=8)
        ax.set_xlabel("x (px)", fontsize=8)
    axes[0, 0].set_ylabel("optical path length (m)" if time_axis is not None else "bin",
                          fontsize=8)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    with io.atomic_path(path, suffix=".tmp.png") as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)


def _pick_bins(reference: np.ndarray, k: int = 4) -> list[int]:
    """Bins at 5 %, 25 %, 50 % and 80 % of the cumulative energy (distinct, sorted)."""
    e = np.asarray(reference, np.float64).sum(axis=(0, 1, 3))
    c = np.cumsum(e) / max(e.sum(), 1e-30)
    qs = (0.05, 0.25, 0.5, 0.8)[:k]
    return sorted({int(np.searchsorted(c, q)) for q in qs})


def write_figures(out_dir: str | Path, frame: TransientFrame, outputs: dict[str, np.ndarray],
                  prefix: str = "", title: str = "") -> list[int]:
    """The three transient figures of a run, written under ``out_dir``:
    ``<prefix>rmse_per_bin.png`` (error per bin), ``<prefix>bins.png`` (four bins side by side,
    at 5/25/50/80 % of the reference's cumulative energy) and ``<prefix>streak.png`` (x–t slice
    of the middle row), each for the outputs (noisy included when given) and the reference.
    Also ``<prefix>rmse_per_bin.csv``. Returns the bins shown."""
    from .formats import write_csv

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    title = title or str(frame.meta.get("scene", ""))
    ta = frame.time_axis
    table = per_bin_table(outputs, frame.reference, ta)
    write_csv(out_dir / f"{prefix}rmse_per_bin.csv", table)
    plot_error_per_bin(out_dir / f"{prefix}rmse_per_bin.png", table,
                       title=f"{title}: RMSE per bin")
    shown = [(n, outputs[n]) for n in outputs] + [("reference", frame.reference)]
    pick = _pick_bins(frame.reference)
    plot_bins(out_dir / f"{prefix}bins.png", shown, pick, frame.reference, ta, title=title)
    row = frame.shape[0] // 2
    plot_streak(out_dir / f"{prefix}streak.png", shown, row, frame.reference, ta,
                title=f"{title}: streak image of row {row}")
    return pick
