"""Per-frame renders of sequence scenes that need nothing of the loader's internals: the
reference of a frame (chunked, with the variance of its mean) and the ``emitter`` buffer. Used
by :func:`dbench.datasets.sequence.load.load_sequence`, which re-exports the public ones."""
from __future__ import annotations

import numpy as np

from ...resolution import parse_res
from .. import render as _render
from ..mitsuba_env import mitsuba
from ..nonfinite import zeroed
from .scene import SequenceScene

REFERENCE_CHUNK = _render.DEFAULT_REFERENCE_CHUNK
GBUFFER_SPP = _render.DEFAULT_FEATURE_SPP


def render_reference(scene: SequenceScene, res, i: int, seed: int, spp: int,
                     chunk: int = REFERENCE_CHUNK, counts: dict | None = None
                     ) -> tuple[np.ndarray, np.ndarray]:
    """The reference of frame ``i``: ``spp`` samples in :func:`~dbench.datasets.render.
    reference_chunks` (K ≥ 16 when spp ≥ 16), a seed stream disjoint from the noisy frames'
    (``seed`` is the reference seed).

    A chunk's NaN or ±Inf pixel values (each stands for at least one such sample) count as 0,
    as the noisy frames count their samples (:func:`dbench.datasets.nonfinite.zeroed`), and
    ``counts``, where given, gets their number as ``nonfinite_samples``.

    Returns (reference (H, W, 3) float32, reference_var (H, W, 3) float32: variance of
    the mean from the chunk spread)."""
    mi = mitsuba()
    res = parse_res(res)
    # Loaded once for all chunks (loading is the expensive part of a small chunk's render);
    # optimize=False as in _render_dict, so the pixels equal a per-chunk load bit for bit.
    loaded = mi.load_dict(scene.frame_dict(mi, res, i), optimize=False)
    acc = _render.ChunkMoments((res.height, res.width, 3))
    nonfinite = 0
    for c, n in enumerate(_render.reference_chunks(spp, chunk)):
        img = mi.render(loaded, spp=n, seed=_render.pass_seed(f"seq-reference-{i}", seed, c))
        img, bad = zeroed(np.array(img, dtype=np.float32))
        nonfinite += bad
        acc.add(img, n)
    if counts is not None:
        counts["nonfinite_samples"] = nonfinite
    return acc.mean().astype(np.float32), acc.var_mean().astype(np.float32)


def render_emitter(scene: SequenceScene, res, i: int, seed: int,
                   spp: int = GBUFFER_SPP) -> np.ndarray:
    """The ``emitter`` buffer of frame ``i`` (H, W, 1) float32 (its lights: a light switched
    off does not count), seed stream ``seq-emitter``."""
    from ..emitter import render_emitter_dict

    d = scene.frame_dict(mitsuba(), res, i)
    return render_emitter_dict(d, spp, _render.pass_seed("seq-emitter", seed, i), optimize=False)


__all__ = ["render_emitter", "render_reference"]
