"""Rendering transient scenes: Mitsuba then mitransient, a scene loaded behind a ``batch`` sensor
of camera copies, one plain render (the collectors' timing baseline) and the chunked reference
with its per-bin variance."""
from __future__ import annotations

import time

import numpy as np

from ...resolution import parse_res
from .. import render as _render
from ..mitsuba_env import mitsuba, require_llvm, scene_cache
from ..nonfinite import zeroed
from .scene import TransientScene, Window

#: float32 voxels of one batched pass (copies × H × W × T × 3): bounds the pass memory (64 MB).
MAX_BATCH_VOXELS = 1 << 24
DEFAULT_REFERENCE_CHUNK = 64


def _mitransient():
    """Mitsuba with the variant set, then mitransient (import order: docs/transient.md §4)."""
    require_llvm("transient rendering (mitransient)")
    mi = mitsuba()
    import mitransient  # noqa: F401

    return mi


@scene_cache()
def loaded_transient(scene: TransientScene, res, window: Window, copies: int = 1):
    """The transient scene; with ``copies`` > 1 seen through a ``batch`` sensor of that many
    identical cameras (film (H, copies·W, T, 3)), as in :func:`render.loaded_batch_scene`."""
    mi = _mitransient()
    res = parse_res(res)
    d = scene.transient_dict(mi, res, window)
    if copies > 1:
        camera = dict(d["sensor"])
        camera.pop("sampler", None)
        # every camera keeps its own W × H film: it sets the camera's aspect ratio (without
        # one a camera falls back to a 768 × 576 film and sees a different view)
        film = dict(camera["film"])
        film["width"] = res.width * copies
        batch = {"type": "batch", "sampler": {"type": "independent"}, "film": film}
        for i in range(copies):
            batch[f"camera{i:03d}"] = dict(camera)
        d["sensor"] = batch
    return mi.load_dict(d)


def render_signal(scene: TransientScene, res, window: Window, copies: int, spp: int,
                  seed: int) -> tuple[np.ndarray, np.ndarray]:
    """One ``mi.render`` of ``spp`` samples turned into the scene's signal: (steady (H, copies·W,
    3), video (H, copies·W, T, 3)) float32. A ``scene.minus`` is rendered with the same seed and
    subtracted (the same sample indices draw the same random numbers, so each path loses exactly
    its part in ``minus``), then :meth:`TransientScene.signal` applies (step: cumsum along T)."""
    mi = _mitransient()
    steady, video = mi.render(loaded_transient(scene, res, window, copies), spp=int(spp),
                              seed=seed)
    steady, video = np.array(steady, dtype=np.float32), np.array(video, dtype=np.float32)
    if scene.minus is not None:
        st2, v2 = mi.render(loaded_transient(scene.minus, res, window, copies), spp=int(spp),
                            seed=seed)
        steady = (steady.astype(np.float64) - np.array(st2, np.float64)).astype(np.float32)
        video = (video.astype(np.float64) - np.array(v2, np.float64)).astype(np.float32)
    return steady, scene.signal(video)


def batch_copies(res, bins: int, spp: int) -> int:
    """Camera copies per 1-spp call: the largest divisor of spp whose pass fits the budgets."""
    pixels = parse_res(res).pixels
    cap = max(1, min(_render.MAX_BATCH_PIXELS // pixels,
                     MAX_BATCH_VOXELS // (pixels * bins * 3)))
    return max(d for d in range(1, min(spp, cap) + 1) if spp % d == 0)


def render_plain(scene: TransientScene, res, spp: int, seed: int = 0,
                 bins: int | None = None) -> tuple[np.ndarray, np.ndarray, float]:
    """One ordinary transient render of ``spp`` (the baseline of the collector benchmark).

    Returns (video (H, W, T, 3), steady (H, W, 3), seconds)."""
    window = scene.window(bins)
    loaded_transient(scene, res, window, 1)  # loading is not part of the time
    t0 = time.perf_counter()
    steady, video = render_signal(scene, res, window, 1, spp, _render.pass_seed("plain", seed, 0))
    return video, steady, time.perf_counter() - t0


def render_reference(scene: TransientScene, res, spp: int, seed: int = 0,
                     bins: int | None = None, chunk: int = DEFAULT_REFERENCE_CHUNK,
                     progress: bool = False, counts: dict | None = None
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """High-spp video in :func:`~dbench.datasets.render.reference_chunks` (K ≥ 16 chunks of at
    most ``chunk`` spp when spp ≥ 16) with independent seeds (same window). A chunk's NaN or
    ±Inf values, in any bin of its video or in its steady image (each stands for at least one
    such sample), count as 0 (:func:`dbench.datasets.nonfinite.zeroed`), and ``counts``, where
    given, gets their number as ``nonfinite_samples``.

    Returns (video (H, W, T, 3), video_var (H, W, T, 3): variance of the video mean per bin from
    the chunk spread, steady (H, W, 3), seconds), float32 arrays."""
    res = parse_res(res)
    window = scene.window(bins)
    chunks = _render.reference_chunks(spp, chunk)
    video = _render.ChunkMoments((res.height, res.width, window.bins, 3))
    steady = np.zeros((res.height, res.width, 3), np.float64)
    t0 = time.perf_counter()
    nonfinite = 0
    with _render._progress(len(chunks), f"{scene.name} reference {spp} spp",
                           progress and len(chunks) >= 8) as bar:
        for i, n in enumerate(chunks):
            # the chunk spread of the signal (a step's cumsum per chunk) gives its variance
            st, tr = render_signal(scene, res, window, 1, n,
                                   _render.pass_seed("reference", seed, i))
            (st, bad_steady), (tr, bad) = zeroed(st), zeroed(tr)
            nonfinite += bad_steady + bad
            video.add(tr.astype(np.float64), n)
            steady += st.astype(np.float64) * n
            bar.update(1)
    if counts is not None:
        counts["nonfinite_samples"] = nonfinite
    return (video.mean().astype(np.float32), video.var_mean().astype(np.float32),
            (steady / spp).astype(np.float32), time.perf_counter() - t0)
