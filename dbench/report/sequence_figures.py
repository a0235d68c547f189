"""Figures of sequence runs (matplotlib, PNG): the error of every frame per method
(:func:`plot_errors`) and a strip of chosen frames side by side (:func:`strip`). ``dbench run``
writes both for sequence scenes; the runs come from :func:`dbench.run.sequence_run.run_sequence`."""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Iterable

import numpy as np

from .. import metrics
from ..data import Sequence
from ..errors import DbenchInputError

if TYPE_CHECKING:  # the runs' type only: results are written, never computed, here
    from ..run.sequence_run import SequenceResult


def _warmup(results: dict[str, SequenceResult]) -> int:
    """The warm-up the runs were judged with (``summary["warmup"]``; 0 when none says)."""
    return next((int(r.summary["warmup"]) for r in results.values() if "warmup" in r.summary), 0)


def plot_errors(results: dict[str, SequenceResult], path: str | Path, metric: str = "rmse",
                warmup: int | None = None, title: str = "", events: dict | None = None) -> Path:
    """Error against frame index, one line per method; the warm-up is shaded (``warmup``
    frames; None: the one the runs were judged with, ``summary["warmup"]``)."""
    if warmup is None:
        warmup = _warmup(results)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 3.6), dpi=120)
    for name, r in results.items():
        ax.plot(r.series(metric), label=name, lw=1.4)
    ax.axvspan(-0.5, warmup - 0.5, color="0.9", label="warm-up")
    for label, frame in (events or {}).items():
        ax.axvline(frame, color="k", ls=":", lw=1)
        ax.text(frame + 0.3, ax.get_ylim()[1], label, va="top", fontsize=7)
    ax.set_xlabel("frame")
    ax.set_ylabel(metric)
    if metric in ("rmse",):
        ax.set_yscale("log")
    ax.set_title(title, fontsize=9)
    ax.legend(fontsize=7, ncol=3)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path


def strip(seq: Sequence, results: dict[str, SequenceResult], path: str | Path,
          frames: Iterable[int] | None = None, crop: tuple[slice, slice] | None = None,
          title: str = "") -> Path:
    """A labelled grid (PNG): rows = methods and the reference, columns = frames, tone-mapped
    with the metrics' tone map (EV of the scene)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ev = seq.meta.get("ev", 0.0)
    n = len(seq)
    frames = list(frames) if frames is not None else sorted({0, 2, _warmup(results), n // 2, n - 1} &
                                                             set(range(n)))
    crop = crop or (slice(None), slice(None))
    rows = []
    for name, r in results.items():
        if r.outputs is None:
            raise DbenchInputError(f"{name}: run with keep_outputs=True to draw a strip")
        rows.append((name, [r.outputs[i][crop] for i in frames]))
    if seq.has("reference"):
        rows.append(("reference", [seq[i].reference[crop] for i in frames]))
    h, w = rows[0][1][0].shape[:2]
    scale = max(1.0, 96 / max(h, w))
    fig, axes = plt.subplots(len(rows), len(frames), squeeze=False, dpi=100,
                             figsize=(len(frames) * w * scale / 100 + 0.9,
                                      len(rows) * h * scale / 100 + 0.5))
    for a, (name, images) in enumerate(rows):
        for b, im in enumerate(images):
            ax = axes[a, b]
            ax.imshow(metrics.tonemap(np.nan_to_num(im), ev), interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            if b == 0:
                ax.set_ylabel(name, fontsize=8)
            if a == 0:
                ax.set_title(f"frame {frames[b]}", fontsize=8)
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout(pad=0.2, rect=(0, 0, 1, 1 - 0.35 / fig.get_figheight()) if title else None)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path
