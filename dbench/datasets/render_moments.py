"""Noisy samples and their per-pixel statistics in one Dr.Jit computation per batch of spp
(README.md, "How renders work"; docs/architecture.md).

A batch of ``m`` samples per pixel is one wavefront of W·H·m lanes, pixel-major: lane ``i`` is
sample ``i mod m`` of pixel ``i // m``. Each lane draws its position inside its own pixel, asks
the scene's sensor for a ray and the scene's integrator for the radiance along it, exactly as
Mitsuba's own render loop does (``SamplingIntegrator::render`` in C++, ``ADIntegrator.render`` /
``sample_rays`` in ``mitsuba/python/ad/integrators/common.py``), but instead of splatting into a
film the lane adds its sample to per-pixel float64 sums with ``dr.scatter_reduce``: the plain sum
Σx for the colour and, when statistics are asked for, the power sums S1, S2, S3 of
u = g(x) − g(0) (:mod:`dbench.datasets.stats`). Nothing but those sums leaves the device, so the
per-sample values never cross the bus. Each sample lands in exactly one pixel by construction
(the box filter's one-sample-per-pixel property without a film).

The transforms are written here in Dr.Jit float64 with the same edge rules as
:func:`dbench.datasets.stats.transform_samples` (non-finite samples count as 0 and are counted,
Box-Cox clamps negatives to 0 and counts them); tests/datasets/test_render_moments.py proves the sums
equal a per-sample float64 computation on the samples of the same kernel (``keep_samples``).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..data import check_transform
from ..errors import DbenchInputError
from .mitsuba_env import mitsuba


@dataclass
class BatchSums:
    """What one batch of ``m`` samples per pixel leaves on the host: float64 arrays (H, W, 3)
    of Σx (``plain``) and, with statistics, S1, S2, S3 of u = g(x) − g(0); the counts of
    non-finite and of clamped (Box-Cox, negative) samples; the samples (H, W, m, 3) float32
    themselves only when asked for (tests)."""

    m: int
    plain: np.ndarray
    s1: np.ndarray | None = None
    s2: np.ndarray | None = None
    s3: np.ndarray | None = None
    n_nonfinite: int = 0
    n_clamped: int = 0
    samples: np.ndarray | None = None


def jit_variant(variant: str) -> bool:
    """Whether ``variant`` compiles wavefronts (llvm_*, cuda_*): the one-pass kernel needs it;
    scalar variants render through the host path of :mod:`dbench.datasets.render`."""
    return variant.startswith(("llvm_", "cuda_"))


@lru_cache(maxsize=1)
def _sampler_prototype():
    # independent samples: a pass-based stratification would tie the samples of one pixel
    return mitsuba().load_dict({"type": "independent"})


def _shifted_transform(dr, Float64, x, transform: str, lam: float):
    """u = g(x) − g(0) in float64 (stats.transform_samples minus transform_of_zero)."""
    if transform == "identity":
        return Float64(x)
    if transform == "box-cox":
        # (x^λ − 1)/λ − (−1/λ) = x^λ/λ: one rounding fewer than the shifted difference
        return (dr.sqrt(x) if lam == 0.5 else dr.power(x, lam)) * (1.0 / lam)
    pos = x >= 0
    x_pos, x_neg = dr.select(pos, x, 0.0), dr.select(pos, 0.0, -x)
    xp, xn = x_pos + 1.0, x_neg + 1.0
    if lam == 0.0:
        up = _log1p(dr, x_pos, xp)
    else:
        up = (dr.power(xp, lam) - 1.0) * (1.0 / lam)
    if lam == 2.0:
        un = -_log1p(dr, x_neg, xn)
    else:
        un = -(dr.power(xn, 2.0 - lam) - 1.0) * (1.0 / (2.0 - lam))
    return dr.select(pos, up, un)


def _log1p(dr, t, one_plus_t):
    # log(1+t) to full precision for small t: log(u)·t/(u−1) with u = fl(1+t) (Goldberg's
    # correction of the rounding of 1+t); exactly t where 1+t rounds to 1
    u1 = one_plus_t - 1.0
    return dr.select(u1 == 0.0, t, dr.log(one_plus_t) * (t / dr.select(u1 == 0.0, 1.0, u1)))


def _is_ad_integrator(integrator) -> bool:
    """Whether ``integrator`` is one of Mitsuba's Python (AD) integrators (``prb``), whose
    ``sample`` takes the AD arguments. Told by the class names of its MRO, not by
    ``isinstance``: after a variant switch Mitsuba registers them anew from
    ``mitsuba.python.ad.integrators``, while ``mi.ad`` stays on the first classes once a module
    imported ``mitsuba.ad.integrators`` by name (mitransient does), and the same PRB integrator
    was then no ADIntegrator (its ``sample`` called with the C++ integrators' arguments)."""
    return any(c.__name__ == "ADIntegrator" for c in type(integrator).__mro__)


def _radiance(mi, dr, scene, sensor, sampler, m: int, integrator=None):
    """Per-lane RGB radiance (Color3f) of W·H·m lanes, pixel-major; the pixel index (UInt32);
    (W, H); the integrator's AOVs (a list of Float, unweighted as the film stores them; empty
    for differentiable integrators). ``integrator``: the scene's own when None.

    The same steps as Mitsuba's ``sample_rays`` (common.py) for one sample inside its pixel."""
    film = sensor.film()
    if not film.rfilter().is_box_filter():
        # another filter spreads a sample over its neighbours: not one sample per pixel
        raise DbenchInputError(f"the render kernel needs a box reconstruction filter, not "
                               f"{film.rfilter().class_name()}")
    w, h = (int(v) for v in film.crop_size())
    lanes = w * h * m
    pixel = dr.arange(mi.UInt32, lanes) // dr.opaque(mi.UInt32, m)
    py = pixel // w
    px = pixel - py * w
    pos = mi.Vector2f(mi.Vector2u(px, py)) + sampler.next_2d()
    # relative to the crop window, as sample_rays' fma(pos + offset, 1/size, -offset/size)
    pos = pos * mi.ScalarVector2f(1.0 / w, 1.0 / h)
    aperture = sampler.next_2d() if sensor.needs_aperture_sample() else mi.Point2f(0.5)
    time = mi.Float(sensor.shutter_open())
    if sensor.shutter_open_time() > 0:
        time += sampler.next_1d() * sensor.shutter_open_time()
    wavelength = sampler.next_1d() if mi.is_spectral else mi.Float(0.0)
    ray, weight = sensor.sample_ray_differential(time, wavelength, pos, aperture)
    integrator = scene.integrator() if integrator is None else integrator
    aovs = []
    if _is_ad_integrator(integrator):
        value = integrator.sample(mode=dr.ADMode.Primal, scene=scene, sampler=sampler, ray=ray,
                                  depth=mi.UInt32(0), δL=None, δaovs=None, state_in=None,
                                  active=mi.Bool(True))[0]
    else:
        value, _, aovs = integrator.sample(scene, sampler, ray, sensor.get_medium(),
                                           mi.Bool(True))
    value = value * weight
    if mi.is_spectral:
        value = mi.spectrum_to_srgb(mi.unpolarized_spectrum(value), ray.wavelengths)
    elif mi.is_monochromatic:
        value = mi.Color3f(mi.unpolarized_spectrum(value).x)
    else:
        value = mi.unpolarized_spectrum(value)
    return mi.Color3f(value), pixel, (w, h), list(aovs)


#: Largest per-thread copy set (bytes) the sums may be expanded to on the CPU (ReduceMode.Expand:
#: each thread adds into a copy of its own, no atomics); larger images use Dr.Jit's default.
MAX_EXPAND_BYTES = 1 << 29


def _reduce_mode(dr, target_bytes: int):
    """Expand on LLVM while every thread's copy of the sums fits MAX_EXPAND_BYTES in all:
    Dr.Jit's default expands only targets of up to 2^20 entries and falls back to atomics
    beyond (cornell at 1024², 16 spp, box-cox, 2 busy cores, medians of 4 interleaved rounds:
    10.2 s expanded, 10.9 s with atomics, 10.0 s for a plain render). CUDA ignores the mode
    (Dr.Jit's default there pre-reduces within warps)."""
    if target_bytes * max(1, dr.thread_count()) <= MAX_EXPAND_BYTES:
        return dr.ReduceMode.Expand
    return dr.ReduceMode.Auto


def accumulate(rgb, pixel, n_px: int, stats: tuple[str, float] | None = None):
    """Scatter-add each lane's sample ``rgb`` (Color3f) into pixel ``pixel`` (UInt32) of
    ``n_px`` pixels: float64 arrays ``plain`` (Σx) and, with ``stats``, ``s1``, ``s2``, ``s3``
    (power sums of u = g(x) − g(0)), interleaved as (pixel, channel); and a UInt32 pair of
    counts (non-finite samples, Box-Cox clamps). Symbolic: nothing runs until evaluated, so it
    fuses into the kernel that makes ``rgb``."""
    mi = mitsuba()
    import drjit as dr

    Float64, UInt32 = mi.Float64, mi.UInt32
    channels = (rgb.x, rgb.y, rgb.z)
    finite = [dr.isfinite(c) for c in channels]
    x = [Float64(dr.select(f, c, 0.0)) for f, c in zip(finite, channels)]
    bad = sum(UInt32(dr.select(f, 0, 1)) for f in finite)
    sums = {"plain": dr.zeros(Float64, 3 * n_px)}
    n_clamped = None
    if stats is not None:
        transform, lam = stats[0], float(stats[1])
        if transform == "box-cox":
            n_clamped = sum(UInt32(dr.select(c < 0, 1, 0)) for c in x)
            x_t = [dr.maximum(c, 0.0) for c in x]
        else:
            x_t = x
        u = [_shifted_transform(dr, Float64, c, transform, lam) for c in x_t]
        sums.update(s1=dr.zeros(Float64, 3 * n_px), s2=dr.zeros(Float64, 3 * n_px),
                    s3=dr.zeros(Float64, 3 * n_px))
    counts = dr.zeros(UInt32, 2)
    mode = _reduce_mode(dr, len(sums) * 3 * n_px * 8)
    base = pixel * 3
    for c in range(3):
        idx = base + c
        dr.scatter_reduce(dr.ReduceOp.Add, sums["plain"], x[c], idx, mode=mode)
        if stats is not None:
            u2 = u[c] * u[c]
            dr.scatter_reduce(dr.ReduceOp.Add, sums["s1"], u[c], idx, mode=mode)
            dr.scatter_reduce(dr.ReduceOp.Add, sums["s2"], u2, idx, mode=mode)
            dr.scatter_reduce(dr.ReduceOp.Add, sums["s3"], u2 * u[c], idx, mode=mode)
    # counters only see lanes that have something to count: almost never contended
    dr.scatter_reduce(dr.ReduceOp.Add, counts, bad, UInt32(0), bad > 0)
    if n_clamped is not None:
        dr.scatter_reduce(dr.ReduceOp.Add, counts, n_clamped, UInt32(1), n_clamped > 0)
    return sums, counts


def batch_sums(scene, m: int, seed: int, stats: tuple[str, float] | None = None,
               keep_samples: bool = False) -> BatchSums:
    """One wavefront of ``m`` samples per pixel of the loaded Mitsuba ``scene`` (its first
    sensor and its integrator), seed ``seed`` (31-bit); returns the per-pixel sums.

    Args:
        stats: ``(transform, lam)`` for S1, S2, S3 of the transformed samples, or None.
        keep_samples: also return the samples (H, W, m, 3) float32 (tests: the brute-force
            statistics of exactly the values the sums were made of).
    """
    mi = mitsuba()
    import drjit as dr

    if stats is not None:
        check_transform(*stats)
    with dr.suspend_grad():
        sensor = scene.sensors()[0]
        sampler = _sampler_prototype().clone()
        sampler.set_sample_count(m)
        sampler.set_samples_per_wavefront(m)
        film = sensor.film()
        w, h = (int(v) for v in film.crop_size())
        sampler.seed(dr.opaque(mi.UInt32, seed), w * h * m)
        rgb, pixel, _, _ = _radiance(mi, dr, scene, sensor, sampler, m)
        sums, counts = accumulate(rgb, pixel, w * h, stats)
        kept = mi.Color3f(rgb) if keep_samples else None
        # one kernel: the kept samples are the very values the sums were made of
        dr.eval(sums, counts, kept)
        out = {k: v.numpy().reshape(h, w, 3) for k, v in sums.items()}
        nbad, nclamp = (int(v) for v in counts.numpy())
        samples = None
        if kept is not None:
            samples = np.stack([kept.x.numpy(), kept.y.numpy(), kept.z.numpy()],
                               axis=-1).reshape(h, w, m, 3)
    return BatchSums(m=m, n_nonfinite=nbad, n_clamped=nclamp, samples=samples, **out)


@dataclass
class PassSums:
    """What :func:`pass_sums` leaves on the host: ``channels`` (H, W, C) float64, the sum over
    the passes of every channel the film of ``mi.render`` would hold (non-finite values
    included), and ``colour``, the :class:`BatchSums` of the first three (m = the pass count;
    non-finite samples count as 0 in its sums and are counted)."""

    channels: np.ndarray
    colour: BatchSums


def pass_sums(scene, integrator, seeds, channels, stats: tuple[str, float] | None = None
              ) -> PassSums:
    """One 1-spp wavefront of ``integrator`` on the loaded ``scene`` per seed of ``seeds``,
    summed on the device (float64) and copied to the host once.

    At 1 spp lane ``k`` is pixel ``k`` and draws the random numbers of ``mi.render(scene,
    spp=1, seed=s, integrator=integrator)``'s lane ``k``, so each pass is that render, channel
    for channel (tests/datasets/test_sequence_kernel.py) and a later render with the same seed replays
    it (the re-shaded gradient samples, :mod:`dbench.datasets.sequence.reshade`).

    Args:
        channels: ``channels(spec, aovs, names)`` → the film's channels (a list of Float: the
            colour first) from the weighted spectrum (Color3f), the AOVs and their names.
        stats: ``(transform, lam)`` for the power sums of the colour, or None.
    """
    mi = mitsuba()
    import drjit as dr

    if stats is not None:
        check_transform(*stats)
    names = list(integrator.aov_names())
    with dr.suspend_grad():
        sensor = scene.sensors()[0]
        w, h = (int(v) for v in sensor.film().crop_size())
        total = colour = counts = None
        for s in seeds:
            sampler = _sampler_prototype().clone()
            sampler.set_sample_count(1)
            sampler.set_samples_per_wavefront(1)
            sampler.seed(dr.opaque(mi.UInt32, int(s)), w * h)
            rgb, pixel, _, aovs = _radiance(mi, dr, scene, sensor, sampler, 1, integrator)
            chans = channels(rgb, aovs, names)
            sums, cnt = accumulate(mi.Color3f(chans[0], chans[1], chans[2]), pixel, w * h,
                                   stats)
            # lane k is pixel k: the channel sums need no scatter
            lanes = [mi.Float64(c) for c in chans]
            if total is None:
                total, colour, counts = lanes, sums, cnt
            else:
                total = [a + b for a, b in zip(total, lanes)]
                colour = {k: colour[k] + v for k, v in sums.items()}
                counts = counts + cnt
            # one kernel per pass, as mi.render: the sums stay on the device between passes
            dr.eval(total, colour, counts)
        host = np.stack([c.numpy() for c in total], axis=-1).reshape(h, w, len(total))
        out = {k: v.numpy().reshape(h, w, 3) for k, v in colour.items()}
        nbad, nclamp = (int(v) for v in counts.numpy())
    return PassSums(channels=host, colour=BatchSums(m=len(seeds), n_nonfinite=nbad,
                                                    n_clamped=nclamp, **out))
