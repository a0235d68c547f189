"""Running a method over a :class:`~dbench.data.Sequence`: per-frame metrics, the mean after a
warm-up, temporal stability, plots, strip comparisons and the 720p speed benchmark.

* :func:`run_sequence` — ``reset()`` then ``denoise(frame)`` for every frame in order; per-frame
  time (``time.perf_counter`` around each call; rendering excluded) and metrics against the
  frame's reference. Frames 0-1 are run twice, untimed once: before the run where the
  untimed warm-up runs (below), else again after the run, each time after ``reset()``; their
  outputs are compared with the run's, and a difference is
  :attr:`SequenceResult.nondeterministic`.
* Summary (:class:`SequenceResult.summary`): mean of every metric over frames ≥ ``warmup``
  (default 8, the history-filling "slow start" of docs/methods/svgf.md §8 is excluded), median time per
  frame after the warm-up, and temporal stability (:func:`temporal_stability`).
* Temporal stability (like noisebase's tPSNR): the error of the frame-to-frame differences
  against the reference's, ``d_i = out_i − out_{i−1}`` vs ``r_i = ref_i − ref_{i−1}``:
  ``t_rmse`` on linear values, and ``tpsnr`` = PSNR of the tone-mapped differences
  ``T(out_i) − T(out_{i−1})`` vs ``T(ref_i) − T(ref_{i−1})`` (peak 1, T = dbench tone map),
  both over frames i ≥ max(warmup, 1), or i ≥ 1 on a sequence no longer than the warm-up
  (whose metrics average all its frames: :func:`after_warmup`); ``cvvdp``, ColorVideoVDP's
  JOD of the frames after the warm-up (dbench/metrics/video_quality.py), on small sequences
  unless asked for.
* :func:`plot_errors`, :func:`strip` — matplotlib figures; :func:`benchmark` — per-frame time at
  1280×720 on a synthetic moving sequence; :func:`main` writes results/temporal figures.

Example:
    >>> from dbench.run.sequence_run import run_sequence
    >>> from dbench.synthetic import synthetic_sequence
    >>> seq = synthetic_sequence(16, 24, frames=10)
    >>> res = run_sequence("accumulate", seq)
    >>> {"mean_rmse", "mean_ssim", "mean_rmse_surface"} <= set(res.summary), len(res.per_frame)
    (True, 10)
"""
from __future__ import annotations

import statistics
import time
from dataclasses import dataclass, field
from typing import Any, Iterable

import numpy as np

from .. import metrics
from ..data import Sequence
from ..device import download, timed, upload
from ..errors import DbenchInputError
from ..metrics import video_quality
from . import fpenv
from .inputs import (check_output, check_unchanged, input_guard, merge_difference,
                     output_copy, output_difference, private_copy)

WARMUP = 8
SEQUENCE_METRICS = ("rmse", "ssim")
TEMPORAL_METHODS = ("noisy", "accumulate", "svgf", "asvgf", "bmfr")
#: frames whose calls compile a temporal method's paths: frame 0 (no history) and frame 1 (the
#: reprojection and, in A-SVGF, the gradient); from frame 2 on no call compiled anything
COMPILING_FRAMES = 2


def after_warmup(items: list, warmup: int = WARMUP) -> list:
    """The per-frame ``items`` a sequence's figures average: those after the warm-up, or all
    of them when the sequence is no longer than it (one home for the window, so that the
    summary, the cells and the run's settings judge the same frames)."""
    return items[warmup:] if len(items) > warmup else items


@dataclass
class SequenceResult:
    """Outcome of one method on one sequence.

    Attributes:
        method, params: the method's name and parameters.
        per_frame: list of dicts ``{"frame", "time_s", <metric>: value}``, one per frame.
        summary: ``mean_<metric>`` after the warm-up, ``median_time_s``, ``t_rmse``, ``tpsnr``,
            ``warmup``, ``frames``.
        outputs: the denoised frames (H, W, 3) float32 when kept, else None.
    """

    method: str
    params: dict[str, Any]
    per_frame: list[dict[str, float]]
    summary: dict[str, float] = field(default_factory=dict)
    outputs: list[np.ndarray] | None = None
    #: the judgements of the frames after the warm-up (intervals resample their pixel blocks)
    judgements: list[Any] = field(default_factory=list)
    #: where frames 0-1 of the untimed pass (the warm-up, or a second pass after the run)
    #: differ from the run's (:func:`warm_up_difference`, and ``pass``: which); None where
    #: they are equal
    nondeterministic: dict[str, Any] | None = None

    def series(self, metric: str) -> np.ndarray:
        return np.array([r.get(metric, np.nan) for r in self.per_frame], np.float64)


def _method(method) -> Any:
    if isinstance(method, str):
        from .. import registry
        return registry.get(method)
    return method


def _warm_up(m, seq: Sequence, mine: Sequence, stateless: bool, on_device: bool, device: str,
             available: set) -> list:
    """Run ``m`` untimed over the first :data:`COMPILING_FRAMES` frames of ``mine`` and reset
    it: its first calls compile (Numba, Triton) or load its kernels and models, seconds per
    frame against milliseconds after, and a sequence no longer than the warm-up would
    otherwise time them (README.md, "Usage": one warm-up call before timing). Returns copies
    of their outputs: the same frames after the reset must give the same ones."""
    outs = []
    for i in range(min(COMPILING_FRAMES, len(seq))):
        if stateless:
            m.reset()
        with input_guard(m.name, None if on_device else seq[i],
                         lambda spare: fpenv.denoise(m, spare)):
            if on_device:
                outs.append(download(fpenv.denoise_device(
                    m, upload(mine[i], device, m.wants(available)))))
            else:
                outs.append(output_copy(fpenv.denoise(m, mine[i])))
    m.reset()  # the history of the warm-up frames is not the sequence's (README: reset())
    return outs


def warm_up_difference(warm: list, outs: list) -> dict[str, Any] | None:
    """The largest :func:`~dbench.run.inputs.output_difference` between the warm-up's outputs
    and those of the same frames in the run (after ``reset()``), with the frames that differ;
    None where every one is equal (or there was no warm-up)."""
    found: dict[str, Any] = {}
    for i, (before, after) in enumerate(zip(warm, outs)):
        before = np.asarray(before)  # as the run keeps its outputs: float32
        diff = output_difference(before.astype(np.float32) if before.dtype.kind == "f"
                                 else before, after)
        if diff is not None:
            found.setdefault("frames", []).append(i)
            found = merge_difference(found, diff)
    return found or None


def temporal_stability(outputs: list[np.ndarray], references: list[np.ndarray],
                       warmup: int = WARMUP, ev: float = 0.0) -> dict[str, float]:
    """``t_rmse`` (linear) and ``tpsnr`` (tone-mapped, dB) of the frame-to-frame differences of
    ``outputs`` against those of ``references`` over frames i ≥ max(warmup, 1), or i ≥ 1 where
    the sequence is no longer than the warm-up (the frames its metrics average,
    :func:`after_warmup`); NaN when there are fewer than two frames or any output is
    non-finite."""
    start = max(int(warmup), 1) if len(outputs) > int(warmup) else 1
    if len(outputs) != len(references):
        raise DbenchInputError(f"outputs: expected {len(references)} frames, got {len(outputs)}")
    if len(outputs) <= start:
        return {"t_rmse": float("nan"), "tpsnr": float("nan")}
    if not all(np.isfinite(o).all() for o in outputs[start - 1:]):
        return {"t_rmse": float("nan"), "tpsnr": float("nan")}
    se_lin, se_ldr, count = 0.0, 0.0, 0
    tm_prev_o = metrics.tonemap(outputs[start - 1], ev)
    tm_prev_r = metrics.tonemap(references[start - 1], ev)
    for i in range(start, len(outputs)):
        do = np.asarray(outputs[i], np.float64) - np.asarray(outputs[i - 1], np.float64)
        dr = np.asarray(references[i], np.float64) - np.asarray(references[i - 1], np.float64)
        se_lin += float(((do - dr) ** 2).sum())
        tm_o, tm_r = metrics.tonemap(outputs[i], ev), metrics.tonemap(references[i], ev)
        se_ldr += float((((tm_o - tm_prev_o) - (tm_r - tm_prev_r)) ** 2).sum())
        tm_prev_o, tm_prev_r = tm_o, tm_r
        count += do.size
    mse_ldr = se_ldr / count
    return {"t_rmse": float(np.sqrt(se_lin / count)),
            "tpsnr": float(min(100.0, 10 * np.log10(1.0 / mse_ldr)) if mse_ldr > 0 else 100.0)}


def run_sequence(method, seq: Sequence, metric_names: Iterable[str] = SEQUENCE_METRICS,
                 warmup: int = WARMUP, keep_outputs: bool = False,
                 device: str = "cpu", cvvdp: bool | None = None) -> SequenceResult:
    """Run ``method`` (name or Denoiser) over ``seq`` in order and score every frame.

    ``cvvdp``: score the frames after the warm-up with ColorVideoVDP (summary ``cvvdp``, JOD;
    dbench/metrics/video_quality.py) at ``seq.meta["fps"]`` (default 30); None: only when
    scored frames × pixels is at most 24 × 128² (README.md, "Metrics").

    With ``device="cuda"`` and a method with a device path, every frame is uploaded before its
    call and the output downloaded after it, those copies timed apart (the summary's
    ``transfer_s``, the median per frame), the call itself timed with the device synchronised.

    Where the timed frames (those after the warm-up, or all of a sequence no longer than it)
    include frame 0 or 1, the method first runs untimed over frames 0-1 and is reset, so that
    the times hold no compilation. A temporal method is reset once and keeps its history; a
    steady (single-frame) method is reset before every frame
    (:meth:`dbench.registry.Denoiser.per_frame`). Frames without a reference get times but no
    metrics. Returns a :class:`SequenceResult`.
    """
    m = _method(method)
    if not isinstance(seq, Sequence):
        raise DbenchInputError(f"seq: expected a dbench.data.Sequence, got {type(seq).__name__}")
    from ..data import BUFFER_NAMES
    available = {b for b in BUFFER_NAMES if seq.has(b)}
    ok, why = m.applies_to("sequence", available)
    if not ok:
        raise DbenchInputError(f"{m.name}: cannot run on this sequence: {why}")
    names = list(metric_names)
    ev = seq.meta.get("ev", seq[0].meta.get("ev", 0.0))
    from .scoring import judge_frame

    m.reset()
    rows, outs, judgements = [], [], []
    stateless = m.per_frame("sequence")  # a steady method: every frame alone
    on_device = device != "cpu" and m.runs_on_device()
    transfers = []
    mine = private_copy(seq)  # read-only; compared with seq after the run (run/inputs.py)
    warm = []
    if after_warmup(list(range(len(seq))), warmup)[0] < COMPILING_FRAMES:
        warm = _warm_up(m, seq, mine, stateless, on_device, device, available)
    for i, frame in enumerate(seq):
        given = mine[i]
        if stateless:
            m.reset()
        with input_guard(m.name, None if on_device else frame,
                         lambda spare: fpenv.denoise(m, spare)):
            if on_device:
                data, up_s = timed(lambda: upload(given, device, m.wants(available)), device)
                out, dt = timed(lambda: fpenv.denoise_device(m, data), device)
                out, down_s = timed(lambda: download(out), device)
                transfers.append(up_s + down_s)
            else:
                t0 = time.perf_counter()
                out = fpenv.denoise(m, given)
                dt = time.perf_counter() - t0
        out = check_output(m.name, out, frame.color.shape)
        row: dict[str, float] = {"frame": i, "time_s": dt}
        if frame.reference is not None:
            j = judge_frame(out, frame, names)
            row.update(j.values)
            judgements.append(j)
        rows.append(row)
        outs.append(out.astype(np.float32))
    if not warm:
        # a sequence longer than the warm-up had no untimed pass before it: frames 0-1 again,
        # untimed, after a reset, so that its calls are compared too (README.md, "Usage")
        m.reset()
        again = _warm_up(m, seq, mine, stateless, on_device, device, available)
    check_unchanged(m.name, mine, seq)  # (the second pass read the frames too)
    differed = warm_up_difference(warm or again, outs)
    if differed:
        differed["pass"] = ("the untimed warm-up" if warm
                            else "an untimed second pass after the run")
    res = SequenceResult(m.name, dict(m.params), rows, outputs=outs if keep_outputs else None,
                         judgements=after_warmup(judgements, warmup),
                         nondeterministic=differed)
    after = after_warmup(rows, warmup)
    summary: dict[str, float] = {"warmup": int(warmup), "frames": len(rows)}
    scored = [k for k in (rows[0] if rows else {}) if k not in ("frame", "time_s")]
    for name in dict.fromkeys(list(names) + scored):
        vals = [r[name] for r in after if name in r]
        summary[f"mean_{name}"] = float(np.mean(vals)) if vals else float("nan")
    summary["median_time_s"] = float(statistics.median(r["time_s"] for r in after))
    if transfers:
        summary["transfer_s"] = float(statistics.median(transfers))
    if seq.has("reference"):
        refs = [f.reference for f in seq]
        summary.update(temporal_stability(outs, refs, warmup, ev))
        summary.update(video_quality.sequence_cvvdp(
            outs, refs, warmup, ev, seq.meta.get("fps", video_quality.DEFAULT_FPS), cvvdp))
    res.summary = summary
    return res


def compare(seq: Sequence, method_names: Iterable[str] = TEMPORAL_METHODS,
            params: dict[str, dict] | None = None, warmup: int = WARMUP,
            keep_outputs: bool = True) -> dict[str, SequenceResult]:
    """Run several methods on one sequence; returns {name: SequenceResult}."""
    from .. import registry

    params = params or {}
    return {n: run_sequence(registry.get(n, **params.get(n, {})), seq, warmup=warmup,
                            keep_outputs=keep_outputs) for n in method_names}


def summary_rows(results: dict[str, SequenceResult], scene: str = "") -> list[dict[str, Any]]:
    return [{"scene": scene, "method": n, **r.summary} for n, r in results.items()]


def window_mean(result: SequenceResult, metric: str, start: int, length: int) -> float:
    """Mean of ``metric`` over frames [start, start + length)."""
    return float(np.nanmean(result.series(metric)[start:start + length]))


# ---------------------------------------------------------------------------------------------
# figures


# ---------------------------------------------------------------------------------------------
# synthetic sequences and the speed benchmark


# ---------------------------------------------------------------------------------------------
# results/temporal figures
