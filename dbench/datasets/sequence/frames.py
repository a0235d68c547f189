"""The noisy frames of sequence scenes (README.md, "How renders work"; docs/temporal.md §1):
the colour and its matched (or PSR) G-buffer as the means of 1-spp passes, with the statistics
of the colour samples; the supersampled G-buffer. Used by
:func:`dbench.datasets.sequence.load.load_sequence`, which re-exports the public ones."""
from __future__ import annotations

import numpy as np

from . import psr as _psr
from .. import render as _render
from ..mitsuba_env import mitsuba
from ..nonfinite import zeroed
from .psr import psr_integrator
from ..render_moments import jit_variant, pass_sums
from .scene import SequenceScene
from ..stats import PowerSums

GBUFFER_SPP = _render.DEFAULT_FEATURE_SPP
#: the PSR G-buffers and the roughness below which glossy surfaces get their reflection's normal
#: (0: the rule off)
PSR_GLOSSY_ALPHA = {"psr": 0.0, "psr-glossy": _psr.GLOSSY_ALPHA}
#: How the passes of a noisy frame are summed (part of its cache key and of the scene
#: fingerprint): "kernel-1": on the device on JIT variants (render_moments.pass_sums), the
#: samples unchanged, non-finite colour samples counted as 0 in the colour (before: NaN).
SAMPLES_VERSION = "kernel-1"


def frame_seed(seed: int, i: int) -> int:
    """Seed of the noisy render of frame ``i`` (the gradient frame of i+1 reuses it)."""
    return _render.pass_seed("seq-noisy", seed, i)


#: The noisy colour and its G-buffer come from one render of Mitsuba's ``aov`` integrator with a
#: nested ``path`` integrator: the nested RGB equals a plain path render with the same seed bit
#: for bit (docs/mitsuba.md §5) and the AOVs describe exactly the primary hits of those samples.
#: A second nested ``path`` with max_depth 1 gives the emission of the same primary hits.
#: Nested integrators come out in the order given (keys also sorted alike: color < emission).
def _matched_integrator(path: dict) -> dict:
    return {"type": "aov", "aovs": _render.AOV_STRING, "color": dict(path),
            "emission": {"type": "path", "max_depth": 1}}


#: (buffer, first channel, channel count) of the matched render: colour, emission, the AOVs.
MATCHED_LAYOUT = (("color", 0, 3), ("emission", 3, 3)) + tuple(
    (n, c0 + 6, nc) for n, c0, nc in _render.AOV_LAYOUT)


def _render_dict(d: dict, spp: int, seed: int, integrator=None) -> np.ndarray:
    mi = mitsuba()
    # optimize=False keeps the shapes and emitters in dictionary order. With the default, the
    # order of emitters changes from one load to the next (measured with Mitsuba 3.9.1), which
    # changes which light a random number selects: two renders with the same seed would then
    # differ in scenes with several emitters, and the gradient frames would be wrong.
    scene = mi.load_dict(d, optimize=False)
    kw = {"integrator": integrator} if integrator is not None else {}
    return np.array(mi.render(scene, spp=spp, seed=seed, **kw), dtype=np.float32)


def pass_seeds(seed: int, seed_frame: int, spp: int) -> list[int]:
    """The seeds of the ``spp`` 1-spp passes of a noisy frame: the first is
    :func:`frame_seed` (so a 1-spp frame is one render with the frame's seed), the others come
    from a stream of their own per frame."""
    return [frame_seed(seed, seed_frame)] + [
        _render.pass_seed(f"seq-noisy-{seed_frame}", seed, k) for k in range(1, spp)]


def render_frame(scene: SequenceScene, res, spp: int, seed: int, camera_frame: int,
                 light_frame: int, seed_frame: int, stats: tuple[str, float] | None = None,
                 gbuffer: str = "psr", kernel: bool | None = None,
                 counts: dict | None = None) -> dict[str, np.ndarray]:
    """Noisy colour and matched G-buffer: ``color``, ``emission``, ``albedo``, ``normal``,
    ``depth``, ``position`` (H, W, C), the means of ``spp`` 1-spp passes
    (:func:`pass_seeds`) with the camera of ``camera_frame``, the lights of ``light_frame`` and
    the seeds of ``seed_frame``. With ``stats`` = (transform, lam), the key ``stats`` holds the
    SampleStats of the colour samples (the passes are the individual samples, as for steady
    images, so the colour is the same with or without them).

    The G-buffer is the box-filtered mean over the same samples as the colour: at 1 spp it is
    the G-buffer of the very primary hit each colour sample started from, as a rasteriser
    feeding a real-time path tracer provides it. (A G-buffer supersampled independently mixes
    surfaces at silhouettes while the 1-spp colour sample sees only one of them; dividing such
    a sample by the mixed albedo, e.g. a light's edge or a black conductor's silhouette,
    amplifies it by orders of magnitude — so sequence datasets use the matched G-buffer.)
    With ``gbuffer="psr"`` (default) that G-buffer sees through mirrors and glass
    (:mod:`dbench.datasets.sequence.psr`), with ``"psr-glossy"`` glossy surfaces of roughness < 0.4 also
    get their reflection's normal; otherwise it is Mitsuba's AOVs of the primary hit.

    ``kernel``: True sums the passes on the device (:func:`~dbench.datasets.render_moments.
    pass_sums`: each pass is the same 1-spp render, colour statistics made where the samples
    are), False films every pass to NumPy and sums there (the readable reference, and the
    only path of scalar variants); None picks the kernel wherever the variant compiles
    wavefronts. Both draw the same samples; non-finite colour samples count as 0 in the
    colour, as in its statistics (README.md, "How renders work"), and ``counts``, where given,
    gets their number (one per channel) as ``nonfinite_samples`` (:mod:`dbench.datasets.nonfinite`).
    """
    mi = mitsuba()
    d = scene.frame_dict(mi, res, camera_frame, light_frame)
    integ = mi.load_dict(psr_integrator(d["integrator"], PSR_GLOSSY_ALPHA[gbuffer])
                         if gbuffer in PSR_GLOSSY_ALPHA
                         else _matched_integrator(d["integrator"]), optimize=False)
    # optimize=False: see _render_dict
    loaded = mi.load_dict(d, optimize=False)
    seeds = pass_seeds(seed, seed_frame, spp)
    kernel = jit_variant(mi.variant()) if kernel is None else bool(kernel)
    if kernel:
        sums = pass_sums(loaded, integ, seeds, _film_channels, stats)
        total, acc, nonfinite = sums.channels, None, sums.colour.n_nonfinite
        total[..., 0:3] = sums.colour.plain
        if stats is not None:
            acc = PowerSums((total.shape[0], total.shape[1], 3), *stats)
            c = sums.colour
            acc.add_sums(c.m, c.s1, c.s2, c.s3, c.n_nonfinite, c.n_clamped)
    else:
        total, acc, nonfinite = _host_passes(mi, loaded, integ, seeds, stats)
    if counts is not None:
        counts["nonfinite_samples"] = int(nonfinite)
    mean = (total / spp).astype(np.float32)
    layout = MATCHED_LAYOUT + (_psr.PSR_EXTRA_LAYOUT if gbuffer in PSR_GLOSSY_ALPHA else ())
    buffers = {name: np.ascontiguousarray(mean[..., c0:c0 + nc]) for name, c0, nc in layout}
    if acc is not None:
        buffers["stats"] = acc.finalize()
    return buffers


def _host_passes(mi, loaded, integ, seeds, stats):
    """The passes as films: float64 sums of every channel (non-finite colour samples as 0),
    the PowerSums of the colour, or None, and the number of those non-finite samples."""
    total = acc = None
    nonfinite = 0
    for s in seeds:
        out = np.array(mi.render(loaded, spp=1, seed=s, integrator=integ), dtype=np.float64)
        if stats is not None:
            if acc is None:
                acc = PowerSums(out.shape[:2] + (3,), *stats)
            acc.add(out[..., 0:3])
        # non-finite colour samples count as 0, as the statistics count them (PowerSums)
        out[..., 0:3], n = zeroed(out[..., 0:3])
        nonfinite += n
        total = out if total is None else total + out
    return total, acc, nonfinite


def _film_channels(spec, aovs, names):
    """The channels of ``mi.render``'s output for the frame integrators (checked channel for
    channel in tests/datasets/test_sequence_kernel.py): the ``aov`` integrator's film holds its AOVs
    without the nested integrators' alpha (its own RGB is not in it); the PSR integrator's
    holds its weighted colour, then its AOVs."""
    if names and names[0] == "color.R":
        return [a for a, n in zip(aovs, names) if not n.endswith(".A")]
    return [spec.x, spec.y, spec.z] + list(aovs)


def render_gbuffer(scene: SequenceScene, res, i: int, seed: int,
                   spp: int = GBUFFER_SPP) -> dict[str, np.ndarray]:
    """Supersampled G-buffer of frame ``i``: ``emission``, ``albedo``, ``normal``, ``depth``,
    ``position`` as box-filtered means of ``spp`` samples (noise-free inside surfaces,
    footprint averages at silhouettes; docs/methods/temporal.md §1), independent of the colour samples."""
    mi = mitsuba()
    d = scene.frame_dict(mi, res, i)
    integ = mi.load_dict({"type": "aov", "aovs": _render.AOV_STRING,
                          "emission": {"type": "path", "max_depth": 1}}, optimize=False)
    out = _render_dict(d, spp, _render.pass_seed("seq-aov", seed, i), integrator=integ)
    return {name: np.ascontiguousarray(out[..., c0 - 3:c0 - 3 + nc])
            for name, c0, nc in MATCHED_LAYOUT[1:]}


__all__ = ["MATCHED_LAYOUT", "PSR_GLOSSY_ALPHA", "SAMPLES_VERSION", "frame_seed", "pass_seeds",
           "render_frame", "render_gbuffer"]
