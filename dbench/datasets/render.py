"""Steady renders: noisy color with exact per-pixel sample statistics, AOV features, reference.

The noisy color at n spp is always the mean of n individual samples per pixel, each inside its
own pixel (box filter), in batches of ``copies`` samples per pixel with distinct seeds. On JIT
variants a batch is one Dr.Jit kernel that adds each sample to per-pixel float64 sums where it
is made (:mod:`dbench.datasets.render_moments`; README.md, "How renders work"); on scalar
variants it is a 1-spp render of a ``batch`` sensor of camera copies, summed on the host.
Statistics, when asked for, are the power sums of those same samples
(:mod:`dbench.datasets.stats`), which makes the color identical whether or not statistics were
collected, and runs of different methods see the same input.

Features come from a separate pass of Mitsuba's ``aov`` integrator (no nested integrator:
cheaper, docs/mitsuba.md §3); the ``emitter`` buffer (:mod:`dbench.datasets.emitter`) from
another pass at the same spp, stored in the same cache entry.

References are rendered in K independent chunks (:func:`reference_chunks`: K ≥ 16 whenever
spp ≥ 16), which bounds memory and gives the variance of the reference mean from the spread of
the chunk means (:class:`ChunkMoments`, docs/judging.md §2): with chunk means m_i of n_i spp,
N = Σ n_i, m = Σ n_i m_i / N, the per-sample variance is σ² ≈ Σ n_i (m_i − m)² / (K − 1) and
the variance of the mean v_r = σ² / N (0 where K < 2).
"""
from __future__ import annotations

import hashlib
import time

import numpy as np

from .mitsuba_env import mitsuba, scene_cache
from .nonfinite import zeroed
from .scenes.record import Scene
from .render_moments import batch_sums, jit_variant
from .stats import PowerSums
from ..data import SampleStats
from ..resolution import Res, parse_res

AOV_STRING = "albedo:albedo,nn:sh_normal,dd:depth,pp:position"
#: (buffer, first channel, channel count) in the aov integrator's output.
AOV_LAYOUT = (("albedo", 0, 3), ("normal", 3, 3), ("depth", 6, 1), ("position", 7, 3))
DEFAULT_FEATURE_SPP = 64
DEFAULT_REFERENCE_CHUNK = 256
#: References are split into at least this many chunks (when spp allows) for their variance.
MIN_REFERENCE_CHUNKS = 16
#: Marker in the cache key of reference entries that hold ``reference_var`` (chunk variance).
REFERENCE_VAR_VERSION = "chunk-var-1"
#: How the steady noisy samples and reference chunks are drawn (part of their cache keys):
#: since "kernel-1", in the one-pass kernel of render_moments on JIT variants (pixel-major
#: wavefronts of an ``independent`` sampler), whose random numbers differ from the ``batch``
#: sensor's before it; entries made before are never mixed with new ones.
SAMPLES_VERSION = "kernel-1"


def feature_spp(spp: int) -> int:
    """Samples per pixel of the feature buffers (albedo, normal, depth, position, emitter) of a
    steady frame whose colour has ``spp``: max(DEFAULT_FEATURE_SPP, spp).

    A renderer accumulates its AOVs with the beauty pass, so a guide is never noisier than the
    colour it guides. Fixed 64-spp features under a 256- or 1024-spp colour put the albedo's own
    sampling noise (≈ 10 % per pixel on pixel-frequency texture) into every method that
    demodulates by or is guided by it: measured on ``textured`` at 64², 1024 spp, the
    autoencoder's relMSE was 5.3x the noisy input's with 64-spp features and 1.4x with
    1024-spp ones, OIDN's 3.1x and 1.3x (results/learned.md)."""
    return max(DEFAULT_FEATURE_SPP, int(spp))


def pass_seed(stream: str, seed: int, index: int) -> int:
    """A 31-bit seed for pass ``index`` of a render ``stream`` (``noisy``, ``aov``, ``reference``).

    Hashing keeps the streams of every (stream, seed) pair disjoint, so a reference never reuses
    the random numbers of the noisy image it is compared with.
    """
    digest = hashlib.sha256(f"{stream}:{seed}:{index}".encode()).digest()
    return int.from_bytes(digest[:4], "little") & 0x7FFFFFFF


@scene_cache()
def loaded_scene(scene: Scene, res: Res):
    mi = mitsuba()
    return mi.load_dict(scene.scene_dict(mi, res))


def _progress(total: int, desc: str, enabled: bool):
    from tqdm.auto import tqdm

    return tqdm(total=total, desc=desc, unit="pass", leave=False,
                disable=(not enabled) or total < 8, mininterval=0.5)


#: Upper bound on the pixels of one batched film (copies × W × H), which bounds memory.
MAX_BATCH_PIXELS = 1 << 22


def batch_size(res, spp: int) -> int:
    """Camera copies per call: the largest divisor of ``spp`` whose film fits MAX_BATCH_PIXELS."""
    cap = max(1, MAX_BATCH_PIXELS // parse_res(res).pixels)
    return max(d for d in range(1, min(spp, cap) + 1) if spp % d == 0)


@scene_cache()
def loaded_batch_scene(scene: Scene, res: Res, copies: int):
    """The scene seen through a ``batch`` sensor of ``copies`` identical cameras.

    One 1-spp render of it gives ``copies`` independent samples in every pixel, side by side in
    an (H, copies·W) film; with the box filter each sample stays in its own pixel, so this is
    the 1-spp pass method with the per-call overhead divided by ``copies``.
    """
    mi = mitsuba()
    d = scene.scene_dict(mi, res)
    camera = dict(d["sensor"])
    camera.pop("sampler", None)
    batch = {"type": "batch", "sampler": {"type": "independent"},
             "film": {**camera["film"], "width": res.width * copies, "height": res.height}}
    for i in range(copies):
        batch[f"camera{i:03d}"] = dict(camera)
    d["sensor"] = batch
    return mi.load_dict(d)


def sample_batches(scene: Scene, res: Res, spp: int, seed: int = 0):
    """Yield the individual samples: arrays (H, copies, W, 3), ``copies`` samples per pixel
    each, ``spp`` in all; the values :func:`render_passes` sums for the same seed (from the
    same kernel on JIT variants, :func:`dbench.datasets.render_moments.batch_sums` with
    ``keep_samples``; from the batch sensor on scalar ones)."""
    res = parse_res(res)
    copies = batch_size(res, spp)
    if not _kernel_path():
        yield from _host_sample_batches(scene, res, spp, seed)
        return
    sc = loaded_scene(scene, res)
    for k in range(spp // copies):
        b = batch_sums(sc, copies, pass_seed("noisy", seed, k), keep_samples=True)
        yield np.moveaxis(b.samples, 2, 1)


def _host_sample_batches(scene: Scene, res: Res, spp: int, seed: int = 0):
    """The samples of scalar variants: 1-spp renders of the ``batch`` sensor, films to NumPy."""
    mi = mitsuba()
    copies = batch_size(res, spp)
    sc = loaded_batch_scene(scene, res, copies)
    for k in range(spp // copies):
        film = np.array(mi.render(sc, spp=1, seed=pass_seed("noisy", seed, k)))
        yield film.reshape(res.height, copies, res.width, 3)


def _kernel_path() -> bool:
    return jit_variant(mitsuba().variant())


_WARM: set[tuple] = set()


def _warm_up(scene: Scene, res: Res, copies: int, stats=None, kernel: bool = True) -> None:
    """One untimed batch the first time a (scene, res, kernel) is rendered in this process:
    scene loading and Dr.Jit's kernel compilation stay out of ``render_s``, as a method's
    warm-up call stays out of its time (its samples are not used). The one-pass kernel is the
    same for every batch size (the count per pixel is an opaque value), so 1 spp warms it."""
    key = (scene.name, id(scene), res, mitsuba().variant(),
           ("kernel", stats) if kernel else ("host", copies))
    if key in _WARM:
        return
    if kernel:
        batch_sums(loaded_scene(scene, res), 1, pass_seed("warmup", 0, 0), stats)
    else:
        mitsuba().render(loaded_batch_scene(scene, res, copies), spp=1,
                         seed=pass_seed("warmup", 0, 0))
    _WARM.add(key)


def render_passes(scene: Scene, res: Res, spp: int, seed: int = 0,
                  stats: tuple[str, float] | None = None, progress: bool = True,
                  kernel: bool | None = None
                  ) -> tuple[np.ndarray, SampleStats | None, dict]:
    """Render ``spp`` independent samples per pixel; return the mean color, optional statistics
    of the individual samples, and timings.

    Args:
        stats: ``(transform, lam)`` to accumulate sample statistics, or None.
        kernel: True for the one-pass kernel (:mod:`dbench.datasets.render_moments`), False
            for the host path (``batch`` sensor films to NumPy, :class:`PowerSums` there: the
            readable reference, and the only path of scalar variants); None picks the kernel
            wherever the variant compiles wavefronts. The two draw different random numbers.
    Returns:
        color (H, W, 3) float32, SampleStats of shape (H, W, 3) or None, and a dict with
        ``render_s`` (the batches, after an untimed warm-up render the first time the scene
        is rendered in the process; on JIT variants the statistics are made in the same
        kernel and counted here), ``stats_s`` (host-side work for the statistics: adding the
        batches' sums and the moments, or on scalar variants the whole accumulation),
        ``copies`` (samples per pixel per batch) and ``nonfinite_samples``: sample values
        (one per channel) that were NaN or ±Inf and, as in the statistics, counted as 0, where
        Mitsuba's film would hold NaN (README.md, "How renders work").
    """
    if spp < 1:
        raise ValueError(f"spp must be >= 1, got {spp}")
    res = parse_res(res)
    copies = batch_size(res, spp)
    total = np.zeros((res.height, res.width, 3), np.float64)
    acc = PowerSums((res.height, res.width, 3), *stats) if stats else None
    render_s = stats_s = 0.0
    nonfinite = 0
    kernel = _kernel_path() if kernel is None else bool(kernel)
    if kernel and not _kernel_path():
        raise ValueError(f"the one-pass kernel needs a JIT variant, not {mitsuba().variant()}")
    _warm_up(scene, res, copies, stats, kernel)
    batches = (_kernel_batches(scene, res, spp, seed, stats) if kernel
               else _host_sample_batches(scene, res, spp, seed))
    with _progress(spp, f"{scene.name} {spp} spp", progress) as bar:
        while True:
            t0 = time.perf_counter()
            batch = next(batches, None)
            if batch is None:
                break
            t1 = time.perf_counter()
            if kernel:
                total += batch.plain
                nonfinite += batch.n_nonfinite
                if acc is not None:
                    acc.add_sums(batch.m, batch.s1, batch.s2, batch.s3, batch.n_nonfinite,
                                 batch.n_clamped)
            elif acc is not None:
                total += acc.add_batch(batch, axis=1)
            else:
                part = batch.sum(axis=1, dtype=np.float64)
                if not np.isfinite(part).all():
                    # non-finite samples count as 0, as the statistics count them (PowerSums)
                    clean, n = zeroed(batch)
                    nonfinite += n
                    part = clean.sum(axis=1, dtype=np.float64)
                total += part
            render_s += t1 - t0
            stats_s += time.perf_counter() - t1
            bar.update(copies)
    t1 = time.perf_counter()
    color = (total / spp).astype(np.float32)
    out = acc.finalize() if acc else None
    if acc is not None and not kernel:
        # the host path's PowerSums counted them, as zeroed counts them without statistics:
        # the same number for the same samples (tests/datasets/test_nonfinite_samples.py)
        nonfinite = acc.n_nonfinite
    stats_s += time.perf_counter() - t1
    return color, out, {"render_s": render_s, "stats_s": stats_s, "copies": copies,
                        "nonfinite_samples": int(nonfinite)}


def _kernel_batches(scene: Scene, res: Res, spp: int, seed: int, stats):
    """The per-pixel sums of each batch (:class:`~dbench.datasets.render_moments.BatchSums`)."""
    copies = batch_size(res, spp)
    sc = loaded_scene(scene, res)
    for k in range(spp // copies):
        yield batch_sums(sc, copies, pass_seed("noisy", seed, k), stats)


def render_plain(scene: Scene, res: Res, spp: int, seed: int = 0) -> tuple[np.ndarray, float]:
    """One ordinary ``spp``-spp render (the baseline the statistics cost is measured against)."""
    mi = mitsuba()
    sc = loaded_scene(scene, parse_res(res))
    t0 = time.perf_counter()
    img = np.array(mi.render(sc, spp=spp, seed=pass_seed("plain", seed, 0)))
    return img.astype(np.float32), time.perf_counter() - t0


def render_features(scene: Scene, res: Res, spp: int = DEFAULT_FEATURE_SPP, seed: int = 0
                    ) -> tuple[dict[str, np.ndarray], float]:
    """Albedo, shading normal, depth and position from the ``aov`` integrator (box filter).

    Returns ({buffer: (H, W, C) float32}, seconds). Depth is 0 where nothing is hit.
    """
    mi = mitsuba()
    sc = loaded_scene(scene, parse_res(res))
    integrator = mi.load_dict({"type": "aov", "aovs": AOV_STRING})
    t0 = time.perf_counter()
    out = np.array(mi.render(sc, integrator=integrator, spp=spp,
                             seed=pass_seed("aov", seed, 0)))
    seconds = time.perf_counter() - t0
    return {name: np.ascontiguousarray(out[..., c0:c0 + nc], dtype=np.float32)
            for name, c0, nc in AOV_LAYOUT}, seconds


def render_emitter(scene, res, spp: int | None = None, seed: int = 0
                   ) -> tuple[np.ndarray, float]:
    """The emitter buffer of catalogue ``scene`` at ``res`` (default spp: the features'),
    seed stream ``emitter`` (:mod:`dbench.datasets.emitter`). Returns ((H, W, 1) float32,
    seconds)."""
    from .emitter import render_emitter_scene

    spp = DEFAULT_FEATURE_SPP if spp is None else int(spp)
    sc = loaded_scene(scene, res)
    t0 = time.perf_counter()
    out = render_emitter_scene(sc, spp, pass_seed("emitter", seed, 0))
    return out, time.perf_counter() - t0


def feature_description(description: dict) -> dict:
    """The cache key of a feature entry: the caller's ``description`` plus the marker of the
    ``emitter`` buffer it holds (entries written before it existed are not reused)."""
    from .emitter import EMITTER_VERSION

    return {**description, "emitter": EMITTER_VERSION}


def cached_features(cache, description: dict, scene: Scene, res: Res, seed: int,
                    meta: dict, spp: int = DEFAULT_FEATURE_SPP) -> dict[str, np.ndarray]:
    """:func:`render_features` and the ``emitter`` buffer of ``scene`` (both at ``spp``, box
    filter) through ``cache`` (kind ``features``, one entry holding
    albedo, normal, depth, position and emitter), recording ``features`` in
    ``meta["cache_hits"]`` or ``meta["rendered"]``. ``description`` is the caller's part of the
    cache key (scene description, spp, seed and AOV string); the emitter marker is added here."""
    description = feature_description(description)
    entry = cache.get("features", description)
    if entry is not None:
        images = entry.images()
        if "emitter" in images:
            meta["cache_hits"].append("features")
            return images
    feats, seconds = render_features(scene, res, spp=spp, seed=seed)
    feats["emitter"], emitter_s = render_emitter(scene, res, spp, seed=seed)
    cache.put("features", description, images=feats,
              meta={"render_s": seconds + emitter_s, "aov_s": seconds, "emitter_s": emitter_s})
    meta["rendered"].append("features")
    return feats


def reference_chunks(spp: int, chunk: int = DEFAULT_REFERENCE_CHUNK) -> list[int]:
    """The spp of each reference chunk: ``c = max(1, min(chunk, spp // 16))`` repeated, plus the
    remainder; K ≥ 16 chunks whenever spp ≥ 16 (4096 spp with chunk 256: 16 × 256)."""
    spp = int(spp)
    c = max(1, min(int(chunk), spp // MIN_REFERENCE_CHUNKS))
    return [c] * (spp // c) + ([spp % c] if spp % c else [])


class ChunkMoments:
    """Weighted mean and spread of chunk means (float64), for ``reference_var``
    (docs/judging.md §2).

    ``add(m_i, n_i)`` takes a chunk mean of n_i samples; :meth:`mean` is Σ n_i m_i / N (the same
    sum as a plain chunked render, so the pixels do not depend on the variance being computed)
    and :meth:`var_mean` is Σ n_i (m_i − m)² / ((K − 1) N), 0 when K < 2, accumulated with
    West's weighted update (no cancellation).
    """

    def __init__(self, shape: tuple[int, ...]):
        self.k = 0
        self.n = 0.0
        self._total = np.zeros(shape, np.float64)
        self._running = np.zeros(shape, np.float64)
        self._m2 = np.zeros(shape, np.float64)

    def add(self, chunk_mean: np.ndarray, n: int) -> None:
        x = np.asarray(chunk_mean, np.float64)
        self.k += 1
        self.n += float(n)
        self._total += x * n
        delta = x - self._running
        self._running += delta * (float(n) / self.n)
        self._m2 += float(n) * delta * (x - self._running)

    def mean(self) -> np.ndarray:
        return self._total / max(self.n, 1.0)

    def var_mean(self) -> np.ndarray:
        if self.k < 2:
            return np.zeros_like(self._m2)
        return np.maximum(self._m2, 0.0) / ((self.k - 1) * self.n)


def render_reference(scene: Scene, res: Res, spp: int, seed: int = 0,
                     chunk: int = DEFAULT_REFERENCE_CHUNK, progress: bool = True,
                     counts: dict | None = None) -> tuple[np.ndarray, np.ndarray, float]:
    """A high-spp reference, rendered as :func:`reference_chunks` with independent seeds
    (stream ``reference``, ``seed`` = the reference seed): on JIT variants each chunk is the
    mean of one-pass kernel batches (:mod:`dbench.datasets.render_moments`, at most
    MAX_BATCH_PIXELS lanes each, which bounds memory at any chunk size), elsewhere one
    ``mi.render`` call per chunk.

    Returns (reference (H, W, 3) float32, reference_var (H, W, 3) float32: variance of
    the reference mean from the chunk spread, seconds); ``counts``, where given, gets
    ``nonfinite_samples``: the values counted as 0 for being NaN or ±Inf (README.md, "How
    renders work"), kernel batches' samples, or a ``mi.render`` chunk's pixel values, each of
    which stands for at least one such sample (:func:`dbench.datasets.nonfinite.zeroed`, as
    the sequence and transient references count them)."""
    res = parse_res(res)
    acc = ChunkMoments((res.height, res.width, 3))
    t0 = time.perf_counter()
    from tqdm.auto import tqdm

    with tqdm(total=spp, desc=f"{scene.name} reference {spp} spp", unit="spp", leave=False,
              disable=not progress, mininterval=0.5) as bar:
        tally = {"nonfinite_samples": 0}
        for n, mean in _reference_chunk_means(scene, res, spp, seed, chunk, tally):
            acc.add(mean, n)
            bar.update(n)
    if counts is not None:
        counts.update(tally)
    return (acc.mean().astype(np.float32), acc.var_mean().astype(np.float32),
            time.perf_counter() - t0)


def _reference_chunk_means(scene: Scene, res: Res, spp: int, seed: int, chunk: int,
                           tally: dict):
    """Yield (n_i, chunk mean (H, W, 3) float64) for each chunk of :func:`reference_chunks`.
    Kernel batches take seeds pass_seed("reference", seed, k) for k = 0, 1, ... across all
    chunks; ``mi.render`` chunks take pass_seed("reference", seed, i)."""
    sc = loaded_scene(scene, res)
    chunks = reference_chunks(spp, chunk)
    if not _kernel_path():
        mi = mitsuba()
        for i, n in enumerate(chunks):
            # Mitsuba's film holds NaN where a sample was non-finite: without this, one such
            # sample made the reference's pixel NaN, which fails every method
            img = mi.render(sc, spp=n, seed=pass_seed("reference", seed, i))
            mean, bad = zeroed(np.array(img, dtype=np.float64))
            tally["nonfinite_samples"] += bad
            yield n, mean
        return
    k = 0
    for n in chunks:
        copies = batch_size(res, n)
        total = np.zeros((res.height, res.width, 3), np.float64)
        for _ in range(n // copies):
            batch = batch_sums(sc, copies, pass_seed("reference", seed, k))
            total += batch.plain
            tally["nonfinite_samples"] += batch.n_nonfinite
            k += 1
        yield n, total / n
