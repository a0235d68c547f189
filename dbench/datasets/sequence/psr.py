"""Primary surface replacement (PSR): a G-buffer that sees through mirrors and glass
(docs/temporal.md §1).

Mitsuba's ``albedo`` AOV is 0 on smooth conductors and dielectrics, and their normal and
position describe the mirror, not what it shows. Demodulating a reflection by that albedo
amplifies it (or, with the fallback a_eff = 1, leaves the reflected texture in the signal), and
the flat mirror's normal and depth let every filter blur the reflected scene across the mirror.
The seed's answer (reflected normals for surfaces with roughness < 0.4, docs/methods/temporal.md §1) and
production's (NVIDIA's primary surface replacement) is the same: describe the pixel by the first
surface along the specular chain that is not a delta (perfectly specular) BSDF.

Per primary sample (:class:`MatchedPSR`, an integrator that wraps the frame's ``path``
integrator so that the colour is the very same sample, bit for bit):

* follow at most ``bounces`` (4) delta reflections / refractions — BSDFs with a delta lobe and no
  diffuse or glossy lobe (smooth ``conductor``, ``dielectric``, ``thindielectric``) — to the
  first other surface, choosing the lobe (reflection or refraction at glass) with uniform
  numbers hashed from the primary ray's direction (:func:`replayable_draw`), not from the
  sampler: any later pass that sees the same camera ray (the re-shaded gradient samples,
  :mod:`dbench.datasets.sequence.reshade`) follows the very same chain, glass included;
* ``albedo`` = throughput of the chain (Fresnel reflectance or transmittance) × that surface's
  diffuse reflectance: the *specular albedo* rule of issue 16 for metals and glass;
* ``emission`` = throughput × radiance that surface emits towards the chain (a lamp seen in a
  mirror is an emitter pixel, kept out of the filters like a directly visible one);
* ``normal`` = that surface's shading normal (the reflected normal);
* ``depth`` = length of the whole chain and ``position`` = camera origin + primary direction ×
  depth: the virtual image point, which is static while the camera moves in front of a planar
  mirror, so the motion vectors of docs/methods/temporal.md §3.1 reproject reflections correctly.

With ``glossy_alpha`` > 0 (the ``"psr-glossy"`` G-buffer of :func:`~dbench.datasets.sequence.load.
load_sequence`, α < 0.4 as seed 001 §1.2.1 says), a pixel whose surface (after the delta chain)
has a glossy lobe with roughness α < ``glossy_alpha`` gets the shading normal of the surface
its mirror direction hits as ``normal`` (the seed's reflected normal for glossy surfaces); its
albedo, depth and position stay its own. The roughness is the BSDF's ``alpha`` attribute per
lane (``eval_attribute_1``; the mean of ``alpha_u`` and ``alpha_v`` for anisotropic ones); a
mirror ray that leaves the scene keeps the surface's own normal.

Two more buffers ride along (seed 001 §1.2.1's feature buffers, offered to BMFR and SVGF):

* ``geo_normal`` — the geometric (face) normal ``si.n`` of the same surface, in world space
  (the seed's "geometry normal buffer" holds the object-space normal; world space keeps it
  comparable between instances and with ``normal``);
* ``reflected_normal`` — the glossy reflected-normal rule above with α < 0.4 whatever
  ``glossy_alpha`` is (the surface's own shading normal where the rule does not apply), so a
  method can use it beside or instead of ``normal`` without a second render.

Surfaces that are not delta keep Mitsuba's own AOVs (the results equal the ``aov`` integrator's
bit for bit; tested). A chain that leaves the scene gives a "no hit" pixel (zeros).
"""
from __future__ import annotations

from ..mitsuba_env import mitsuba

PSR_BOUNCES = 4
#: roughness below which a glossy surface's normal is its reflection's (seed 001 §1.2.1)
GLOSSY_ALPHA = 0.4
#: channel layout of the render: colour, then the G-buffer (same order as sequence.MATCHED_LAYOUT)
PSR_AOVS = ("emission.R", "emission.G", "emission.B", "albedo.R", "albedo.G", "albedo.B",
            "nn.X", "nn.Y", "nn.Z", "dd.T", "pp.X", "pp.Y", "pp.Z",
            "gn.X", "gn.Y", "gn.Z", "rn.X", "rn.Y", "rn.Z")
#: (buffer, first channel, channel count) of the two buffers PSR adds after MATCHED_LAYOUT's
PSR_EXTRA_LAYOUT = (("geo_normal", 16, 3), ("reflected_normal", 19, 3))
_REGISTERED = False


def register() -> str:
    """Register the ``dbench_psr`` integrator once per process; returns its type name."""
    global _REGISTERED
    if _REGISTERED:
        return "dbench_psr"
    mi = mitsuba()
    dr = __import__("drjit")

    class MatchedPSR(mi.SamplingIntegrator):
        """The nested ``color`` integrator's sample and the PSR G-buffer of its primary ray."""

        def __init__(self, props):
            super().__init__(props)
            self.nested = props["color"]
            self.bounces = int(props.get("bounces", PSR_BOUNCES))
            self.glossy_alpha = float(props.get("glossy_alpha", 0.0))

        def sample(self, scene, sampler, ray, medium=None, active=True):
            # the colour first, so that it consumes the sampler exactly as a plain render does
            spec, valid, _ = self.nested.sample(scene, sampler, ray, medium, active)
            ray = mi.Ray3f(ray)
            origin, direction = mi.Point3f(ray.o), mi.Vector3f(ray.d)
            si = scene.ray_intersect(ray, active)
            chain = follow_delta_chain(mi, dr, scene, ray, si, mi.Bool(active) & si.is_valid(),
                                       self.bounces)
            ray, si, length, alive = chain["ray"], chain["si"], chain["length"], chain["alive"]
            throughput, moved = chain["throughput"], chain["moved"]
            hit = alive & si.is_valid()
            albedo = throughput * si.bsdf(ray).eval_diffuse_reflectance(si, hit)
            emission = throughput * si.emitter(scene).eval(si, hit)
            reflected = _glossy_reflected_normal(mi, dr, scene, si, ray, hit, si.sh_frame.n,
                                                 GLOSSY_ALPHA)
            if self.glossy_alpha == GLOSSY_ALPHA:
                normal = reflected
            elif self.glossy_alpha > 0.0:
                normal = _glossy_reflected_normal(mi, dr, scene, si, ray, hit, si.sh_frame.n,
                                                  self.glossy_alpha)
            else:
                normal = si.sh_frame.n
            geo_normal = si.n
            length = dr.select(hit, length, 0.0)
            # the hit point itself where no delta surface was followed (Mitsuba's AOV, bit for
            # bit), the virtual point along the primary ray otherwise
            position = dr.select(moved, origin + direction * length, si.p)
            values = (emission[0], emission[1], emission[2], albedo[0], albedo[1], albedo[2],
                      normal.x, normal.y, normal.z, length, position.x, position.y, position.z,
                      geo_normal.x, geo_normal.y, geo_normal.z,
                      reflected.x, reflected.y, reflected.z)
            return spec, valid, [dr.select(hit, mi.Float(v), 0.0) for v in values]

        def aov_names(self):
            return list(PSR_AOVS)

    mi.register_integrator("dbench_psr", lambda props: MatchedPSR(props))
    _REGISTERED = True
    return "dbench_psr"


def delta_only(mi, flags):
    """A delta BSDF without a smooth lobe: smooth conductor, dielectric, thin dielectric (the
    surfaces PSR looks through)."""
    return mi.has_flag(flags, mi.BSDFFlags.Delta) & ~mi.has_flag(flags, mi.BSDFFlags.Smooth)


def replayable_draw(mi, dr, ray):
    """``draw(bounce)`` -> (sample1 Float, sample2 Point2f): uniform numbers in [0, 1) for the
    lobe of each ``bounce`` of the delta chain of the camera ray ``ray``, hashed (Mitsuba's TEA)
    from the bits of its direction, which differ between pixels and between passes (each pass
    jitters its rays with its own seed). Why not the sampler: PSR draws after the colour's path,
    whose length varies, so a re-shaded path (:mod:`dbench.datasets.sequence.reshade`) could not replay
    those draws and aimed at the pixel's mean point behind glass; a hash of the ray it sees
    again gives each pass its own chain there too. The choice keeps the sampler's distribution
    (reflection with the Fresnel probability)."""
    bits = [dr.reinterpret_array(mi.UInt32, c) for c in (ray.d.x, ray.d.y, ray.d.z)]
    key = mi.sample_tea_32(bits[0], bits[1])[0] ^ bits[2]

    def draw(bounce: int):
        first = 3 * bounce
        return (mi.sample_tea_float32(key, mi.UInt32(first)),
                mi.Point2f(mi.sample_tea_float32(key, mi.UInt32(first + 1)),
                           mi.sample_tea_float32(key, mi.UInt32(first + 2))))

    return draw


def follow_delta_chain(mi, dr, scene, ray, si, alive, bounces: int) -> dict:
    """Follow at most ``bounces`` delta reflections / refractions (BSDFs with a delta lobe and
    no smooth one) from ``si``, the first hit of the camera ray ``ray``, on the lanes
    ``alive``, each lobe drawn by :func:`replayable_draw` of ``ray``, so the chain is a
    function of the camera ray alone. Returns ``ray`` and ``si`` (the last segment and the
    first surface that is not delta), ``length`` (the whole chain's), ``alive`` (False where the
    chain left the scene), ``throughput`` (the delta lobes' weights) and ``moved`` (a delta
    surface was followed). The PSR G-buffer's chain, and the one the re-shaded samples follow
    again (:mod:`dbench.datasets.sequence.reshade`)."""
    draw = replayable_draw(mi, dr, ray)
    length = dr.select(alive, si.t, 0.0)
    throughput = mi.Spectrum(1.0)
    moved = mi.Bool(False)
    ctx = mi.BSDFContext()
    for bounce in range(bounces):
        flags = si.bsdf(ray).flags()
        delta = alive & delta_only(mi, flags)
        sample1, sample2 = draw(bounce)
        bs, weight = si.bsdf(ray).sample(ctx, si, sample1, sample2, delta)
        delta &= dr.any(weight > 0)
        next_ray = si.spawn_ray(si.to_world(bs.wo))
        nxt = scene.ray_intersect(next_ray, delta)
        throughput[delta] = throughput * weight
        moved |= delta
        length[delta] = length + dr.select(nxt.is_valid(), nxt.t, 0.0)
        alive &= ~(delta & ~nxt.is_valid())
        ray[delta] = next_ray
        si[delta] = nxt
    return {"ray": ray, "si": si, "length": length, "alive": alive, "throughput": throughput,
            "moved": moved}


def _glossy_reflected_normal(mi, dr, scene, si, ray, hit, normal, glossy_alpha: float):
    """``normal``, replaced on the lanes whose BSDF is glossy with roughness below
    ``glossy_alpha`` by the shading normal of the first surface along the mirror direction."""
    bsdf = si.bsdf(ray)
    glossy = hit & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Glossy)
    iso = bsdf.has_attribute("alpha", glossy)
    aniso = bsdf.has_attribute("alpha_u", glossy) & ~iso
    alpha = dr.select(iso, bsdf.eval_attribute_1("alpha", si, glossy & iso),
                      dr.select(aniso, 0.5 * (bsdf.eval_attribute_1("alpha_u", si, aniso)
                                              + bsdf.eval_attribute_1("alpha_v", si, aniso)),
                                dr.inf))
    smooth = glossy & (alpha < glossy_alpha)
    mirror = si.spawn_ray(si.to_world(mi.reflect(si.wi)))
    seen = scene.ray_intersect(mirror, smooth)
    return dr.select(smooth & seen.is_valid(), seen.sh_frame.n, normal)


def psr_integrator(path: dict, glossy_alpha: float = 0.0) -> dict:
    """The integrator dictionary of a PSR render around the frame's ``path`` integrator;
    ``glossy_alpha`` > 0 adds the glossy reflected-normal rule (module docstring)."""
    d = {"type": register(), "color": dict(path), "bounces": PSR_BOUNCES}
    if glossy_alpha > 0.0:
        d["glossy_alpha"] = float(glossy_alpha)
    return d


__all__ = ["GLOSSY_ALPHA", "PSR_AOVS", "PSR_BOUNCES", "PSR_EXTRA_LAYOUT", "delta_only",
           "follow_delta_chain", "psr_integrator", "register", "replayable_draw"]
