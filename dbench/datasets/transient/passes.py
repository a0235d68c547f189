"""Collector (a) of transient videos (docs/methods/statistical.md §11; the loader is
:mod:`dbench.datasets.transient.load`, which re-exports these): 1-spp passes with a box filter,
whose film histogram holds, per pixel and bin, exactly one sample, transformed and added to
float64 power sums on the host; and :class:`TransientRender`, what either collector returns."""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ...data import SampleStats, check_count
from ...errors import DbenchInputError
from ...resolution import parse_res
from .. import render as _render
from ..nonfinite import zeroed
from ..stats import PowerSums, stats_from_sums, variance_of_mean
from .render import _mitransient, batch_copies, render_signal
from .scene import TransientScene


@dataclass
class TransientRender:
    """The noisy video and what was collected with it."""

    color: np.ndarray                   # (H, W, T, 3) float32, mean of the samples
    steady: np.ndarray                  # (H, W, 3) float32, same samples, all path lengths
    stats: SampleStats | None = None    # (H, W, T, 3)
    non_zero: np.ndarray | None = None  # (H, W, T, 3) int32
    timing: dict = field(default_factory=dict)
    #: float64 power sums of u = g(x) − g(0): ``s1``, ``s2``, ``s3`` (H, W, T, 3), and ``n``
    sums: dict | None = None
    emission: str = "pulse"             # the scene's (TransientScene.emission)
    #: (H, W, 3) float64 variance of the mean of the per-path sums over the window's bins
    total_var: np.ndarray | None = None
    rows: dict | None = None  # {"stats", "color"}: (H, W, T) bool, rows the cache stores
    #: {"stats", "color"}: {array name: (kept rows, 3)}, those rows already gathered (collector
    #: (b): Cache.put's ``kept``)
    kept: dict | None = None

    @property
    def energy_fraction(self) -> float:
        return energy_fraction(self.color, self.steady, self.emission)


def energy_fraction(video: np.ndarray, steady: np.ndarray, emission: str = "pulse") -> float:
    """Share of the steady energy inside the window: Σ video / Σ steady (all pixels, channels);
    a step video (the cumsum of the pulse's) holds it in its last bin: Σ video[..., -1, :]."""
    total = float(np.sum(steady, dtype=np.float64))
    if emission == "step":
        video = video[..., -1, :]
    return float(np.sum(video, dtype=np.float64)) / total if total > 0 else float("nan")


def pass_samples(scene: TransientScene, res, spp: int, seed: int = 0,
                 bins: int | None = None, copies: int | None = None):
    """Yield the individual samples of collector (a): (transient (H, copies, W, T, 3),
    steady (H, copies, W, 3)) float32 per 1-spp call, ``spp`` samples per pixel in all.

    Call k uses seed :func:`render.pass_seed` ("transient", seed, k); the same seeds drive
    collector (b) in its 1-spp-pass mode (tests compare the two bit for bit). Each sample is
    the scene's signal (:func:`render_signal`: a step scene's is the cumsum along T of the
    path's pulse contributions)."""
    _mitransient()
    res = parse_res(res)
    window = scene.window(bins)
    copies = copies or batch_copies(res, window.bins, spp)
    if spp % copies:
        raise DbenchInputError(f"copies: expected a divisor of spp = {spp}, got {copies}")
    for k in range(spp // copies):
        steady, video = render_signal(scene, res, window, copies, 1,
                                      _render.pass_seed("transient", seed, k))
        yield (video.reshape(res.height, copies, res.width, window.bins, 3),
               steady.reshape(res.height, copies, res.width, 3))


def collect_passes(scene: TransientScene, res, spp: int, seed: int = 0,
                   bins: int | None = None, stats: tuple[str, float] | None = None,
                   copies: int | None = None, progress: bool = False) -> TransientRender:
    """Collector (a): ``spp`` 1-spp samples per pixel, statistics on the host.

    Args:
        stats: ``(transform, lam)`` to accumulate per-bin statistics and ``non_zero``; None
            gives the color and steady image only (same samples, so the same color).
        copies: camera copies per call (default :func:`batch_copies`); 1 = plain passes.
    Returns:
        :class:`TransientRender` with timings ``render_s`` (rendering), ``stats_s``
        (host-side accumulation) and ``nonfinite_samples``: the passes' NaN or ±Inf values
        (one per channel), each counted as 0 (:mod:`dbench.datasets.nonfinite`), over all
        bins of the video and in the steady image: mitransient's film gives a 1-spp pass's
        non-finite value as 0 where it lands in an empty bin (its scatter-add keeps it only
        where the bin already holds a value), so its steady image is where they show, once
        per path and channel, in the window or not; collector (b) counts one per bin
        (README.md, "How renders work"; the warning says which).
    """
    check_count("spp", spp)
    res = parse_res(res)
    window = scene.window(bins)
    shape = (res.height, res.width, window.bins, 3)
    acc = PowerSums(shape, *stats) if stats else None
    total = np.zeros(shape, np.float64)
    steady = np.zeros((res.height, res.width, 3), np.float64)
    # per-path sums over the window's bins (identity): the noisy total's own variance
    totals = PowerSums((res.height, res.width, 3), "identity") if stats else None
    non_zero = np.zeros(shape, np.int32) if stats else None
    clamp = stats is not None and stats[0] == "box-cox"
    render_s = stats_s = 0.0
    nonfinite = 0  # without statistics; with them, the PowerSums count the video's
    copies = copies or batch_copies(res, window.bins, spp)
    samples = pass_samples(scene, res, spp, seed, bins, copies)
    with _render._progress(spp, f"{scene.name} {spp} spp (a)", progress) as bar:
        while True:
            t0 = time.perf_counter()
            item = next(samples, None)
            if item is None:
                break
            video, st = item
            t1 = time.perf_counter()
            st, bad = zeroed(st)
            nonfinite += bad
            steady += st.sum(axis=1, dtype=np.float64)
            if acc is not None:
                total += acc.add_batch(video, axis=1)
                totals.add_batch(video.sum(axis=3, dtype=np.float64), axis=1)
                nz = (video > 0) if clamp else (video != 0)
                if acc.n_nonfinite:
                    nz &= np.isfinite(video)
                non_zero += nz.sum(axis=1, dtype=np.int32)
            else:
                video, bad = zeroed(video)
                nonfinite += bad
                total += video.sum(axis=1, dtype=np.float64)
            render_s += t1 - t0
            stats_s += time.perf_counter() - t1
            bar.update(copies)
    out = TransientRender(color=(total / spp).astype(np.float32),
                          steady=(steady / spp).astype(np.float32), emission=scene.emission,
                          stats=(stats_from_sums(acc.n, acc.s1, acc.s2, acc.s3, acc.transform,
                                                 acc.lam, {"n_nonfinite": acc.n_nonfinite,
                                                           "n_clamped": acc.n_clamped})
                                 if acc else None), non_zero=non_zero,
                          timing={"render_s": render_s, "stats_s": stats_s, "copies": copies,
                                  "collector": "a", "nonfinite_samples": nonfinite + (
                                      acc.n_nonfinite if acc else 0)},
                          sums=({"s1": acc.s1, "s2": acc.s2, "s3": acc.s3, "n": acc.n}
                                if acc else None),
                          total_var=variance_of_mean(totals.n, totals.s1, totals.s2)
                          if totals is not None else None)
    return out


__all__ = ["TransientRender", "collect_passes", "energy_fraction", "pass_samples"]
