"""The ``emitter`` buffer: per pixel, the fraction of its footprint whose primary ray sees a light,
directly or in smooth mirrors.

A sample counts as 1 when its primary ray — after at most 4 reflections in smooth mirrors
(``conductor`` without roughness: a delta reflection and no other lobe) — hits a surface whose
emitter sends radiance > 0 back along the ray (``si.emitter(scene).eval(si)`` non-zero: an area
light seen from its emitting side), or misses every shape while the scene has an environment
emitter with radiance > 0 in that direction; otherwise 0. A light seen in a mirror is as exact
as one seen directly (the reflection is deterministic; only its edge carries coverage noise):
on ``mirrors`` at 256², 1024 spp, the lamp's reflection in the back mirror held 74 % of the
noisy input's squared error in excess in ``oidn+gate``'s output before it counted here. Glass
and smooth plastic choose their lobe at random, so the chain stops at them. Rendered with a box
filter, the pixel value is the share of the pixel's footprint covered by emitters, in [0, 1]
(multiples of 1/spp). Unlike an albedo test
it does not rely on the catalogue's "lights have a black BSDF" convention, and a light that is
switched off (radiance 0) does not count.

The test is a small Mitsuba ``SamplingIntegrator`` written in Python (Dr.Jit code, one ray per
sample, no shading), registered once per variant as ``dbench_emitter_hit``; it runs in
``llvm_ad_rgb`` (vectorised) and ``scalar_rgb`` (slow but correct; Mitsuba warns about Python
integrators in scalar mode).

Example:
    >>> from dbench.datasets import render, scenes
    >>> m, seconds = render.render_emitter(scenes.get("cornell"), 32)    # doctest: +SKIP
    >>> m.shape, float(m.max())                                          # doctest: +SKIP
    ((32, 32, 1), 1.0)
"""
from __future__ import annotations

import numpy as np

from .mitsuba_env import mitsuba

INTEGRATOR_NAME = "dbench_emitter_hit"
#: Version marker of the buffer; part of every cache key of an entry that holds it and of every
#: scene fingerprint (a result's identity). 2: lights seen in smooth mirrors count.
EMITTER_VERSION = "emitter-hit-2"
#: smooth-mirror reflections followed (as the PSR G-buffer's delta chains)
MIRROR_BOUNCES = 4

_registered: set[str] = set()


def register() -> str:
    """Register the ``dbench_emitter_hit`` integrator for the current variant (once); return
    its plugin name."""
    mi = mitsuba()
    variant = mi.variant()
    if variant in _registered:
        return INTEGRATOR_NAME
    import drjit as dr

    jit = dr.is_jit_v(mi.Float)

    def _mirror_only(flags):
        """A smooth mirror: a delta reflection and no other lobe (smooth ``conductor``), the
        one surface whose reflection is deterministic. Glass (a delta transmission too) and
        smooth plastic (a diffuse base) pick their lobe at random, so what they show is Monte
        Carlo noise, and the chain stops there."""
        return (mi.has_flag(flags, mi.BSDFFlags.DeltaReflection)
                & ~mi.has_flag(flags, mi.BSDFFlags.DeltaTransmission)
                & ~mi.has_flag(flags, mi.BSDFFlags.Smooth))

    class EmitterHitIntegrator(mi.SamplingIntegrator):
        """1 where the primary ray, or its reflection in smooth mirrors, sees an emitter with
        radiance > 0 toward the camera, else 0."""

        def __init__(self, props):
            super().__init__(props)
            self.bounces = int(props.get("bounces", MIRROR_BOUNCES))

        def sample(self, scene, sampler, ray, medium=None, active=True):
            ray = mi.Ray3f(ray)
            si = scene.ray_intersect(ray, active)
            if jit:
                alive = mi.Bool(active)
                ctx = mi.BSDFContext()
                for _ in range(self.bounces):
                    mirror = alive & si.is_valid() & _mirror_only(si.bsdf(ray).flags())
                    if not dr.any(mirror):
                        break
                    bs, weight = si.bsdf(ray).sample(ctx, si, sampler.next_1d(mirror),
                                                     sampler.next_2d(mirror), mirror)
                    mirror &= dr.any(weight > 0)
                    next_ray = si.spawn_ray(si.to_world(bs.wo))
                    nxt = scene.ray_intersect(next_ray, mirror)
                    ray[mirror] = next_ray
                    si[mirror] = nxt
                # si.emitter(): the hit shape's area emitter, or the environment where the ray
                # escapes (null where there is neither); eval() is 0 on an emitter's back side.
                radiance = si.emitter(scene, alive).eval(si, alive)
                seen = alive & (dr.max(radiance) > 0.0)
            else:  # scalar variants: one ray, plain control flow
                for _ in range(self.bounces):
                    if not (active and si.is_valid()
                            and bool(_mirror_only(si.bsdf(ray).flags()))):
                        break
                    bs, weight = si.bsdf(ray).sample(mi.BSDFContext(), si, sampler.next_1d(),
                                                     sampler.next_2d(), True)
                    if not dr.any(weight > 0):
                        break
                    ray = si.spawn_ray(si.to_world(bs.wo))
                    si = scene.ray_intersect(ray, active)
                em = si.emitter(scene, active)
                radiance = em.eval(si, active) if em is not None else mi.Spectrum(0.0)
                seen = active and dr.max(radiance) > 0.0
            return mi.Spectrum(dr.select(seen, 1.0, 0.0)), active, []

        def aov_names(self):
            return []

        def to_string(self):
            return "EmitterHitIntegrator[]"

    mi.register_integrator(INTEGRATOR_NAME, lambda props: EmitterHitIntegrator(props))
    _registered.add(variant)
    return INTEGRATOR_NAME


def integrator():
    """A fresh instance of the emitter-hit integrator (registered on first use)."""
    mi = mitsuba()
    return mi.load_dict({"type": register()})


def render_emitter_scene(scene, spp: int, seed: int) -> np.ndarray:
    """The emitter buffer of a loaded Mitsuba scene (its film must use a box filter):
    (H, W, 1) float32 in [0, 1]."""
    mi = mitsuba()
    out = np.array(mi.render(scene, integrator=integrator(), spp=int(spp), seed=int(seed)),
                   dtype=np.float32)
    return np.ascontiguousarray(np.clip(out[..., :1], 0.0, 1.0))


def render_emitter_dict(d: dict, spp: int, seed: int, optimize: bool = True) -> np.ndarray:
    """:func:`render_emitter_scene` of a scene dictionary (``optimize`` as in ``mi.load_dict``)."""
    mi = mitsuba()
    return render_emitter_scene(mi.load_dict(d, optimize=optimize), spp, seed)


__all__ = ["EMITTER_VERSION", "INTEGRATOR_NAME", "MIRROR_BOUNCES", "integrator", "register",
           "render_emitter_dict", "render_emitter_scene"]
