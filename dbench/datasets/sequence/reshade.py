"""A-SVGF's temporal-gradient samples as the seed describes them (docs/methods/svgf.md §6.1;
docs/temporal.md §2):
the brightest sample of every 3×3 stratum of frame i−1 is re-shaded from frame i's camera,
under frame i's lights, with frame i−1's random numbers.

How the random numbers are reused: Mitsuba's independent sampler gives wavefront lane k of a
render with seed s the same random stream every time (lane k is pixel k at 1 spp). The re-shading
render therefore runs the frame-(i−1) wavefront again with the frame-(i−1) seed, and lane q —
which sampled the camera jitter of pixel q exactly as before — replaces its camera ray by the ray
from the *current* camera origin to the surface point P_{i−1}(q) that pixel q hit. The nested
path integrator then continues with the random numbers pixel q used for its path in frame i−1.
Lanes outside the selection are inactive (no ray is traced for them), so the cost is the ray
generation of a frame plus one path per stratum (about 1/9 of a frame's paths).

Which point each pass aims at: the render runs in a scene with frame i−1's camera and frame i's
lights, so lane q's camera ray is, bit for bit, the ray pixel q traced in that pass of frame i−1
(the same random numbers; the geometry is static), and its first hit is that pass's own point
P_{i−1}(q), the target of the re-shaded path. Where that hit is a mirror or glass (a delta
BSDF) the target is that pass's own PSR virtual point (:mod:`dbench.datasets.sequence.psr`: the chain
of delta reflections and refractions followed again from the same ray; PSR draws each lobe
from a hash of the camera ray, so the same ray makes the same choice at glass), reached
through the delta surface the new ray meets: the re-shaded sample then
sees the same reflected point as before, not whatever the mirror shows from the new camera
(aimed at the mirror's own surface point instead, mirror-pan at 128² lost a third of A-SVGF's
and BMFR's gain). A pass whose ray left the scene is traced along the same direction from the
new origin (the environment is a function of direction). At 1 spp the targets are the
G-buffer's positions exactly, as before; above 1 spp every pass used to aim at the pixel's
*mean* position, so each re-shaded sample started from another point than the sample it is
compared with, and a static light showed gradients (orbit, 128², 4 spp: mean G 0.0098 against
6·10⁻⁵ at 1 spp; A-SVGF and BMFR then shortened their histories and lost to plain accumulation
in relMSE). Behind glass every pass aimed at the mean point until PSR's lobe choice became
replayable (RESHADE_VERSION 6, PSR_VERSION 4): it was drawn from the sampler after the
colour's path.

A sample is dropped (NaN in the buffer) when its point is hidden from the current camera (the
first hit along the new ray is more than 0.1 % of the distance short of it, and not a mirror or
glass: disocclusion). View-dependent changes — a highlight moving over a glossy sphere as the
camera moves — show up as gradients.

Public: :func:`select_strata` (the brightest hit pixel per stratum) and :func:`render_reshade`
(the (H, W, 3) gradient buffer: re-shaded colour at the selected pixels, NaN elsewhere).
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ..mitsuba_env import mitsuba
from .psr import PSR_BOUNCES, delta_only, follow_delta_chain

STRATUM = 3
#: a re-shaded sample is visible when its first hit is within this fraction of the distance
OCCLUSION_TOLERANCE = 1e-3
_REGISTERED = False
_INTEGRATORS: dict[str, Any] = {}


def select_strata(color: np.ndarray, depth: np.ndarray, size: int = STRATUM) -> np.ndarray:
    """(H, W) bool: in every ``size``×``size`` stratum (aligned at the top-left corner; partial
    strata at the right and bottom borders), the pixel of highest Rec. 709 luminance among those
    with a hit (depth > 0) and a finite colour; the first in row-major order on ties; none in a
    stratum without such a pixel.

    Args:
        color: (H, W, 3) noisy colour of frame i−1.
        depth: (H, W) or (H, W, 1) depth of frame i−1 (0 where no hit).
    """
    color = np.asarray(color, np.float64)
    h, w = color.shape[:2]
    depth = np.asarray(depth, np.float64).reshape(h, w)
    lum = color @ np.array([0.2126, 0.7152, 0.0722])
    usable = (depth > 0) & np.isfinite(lum)
    score = np.where(usable, lum, -np.inf)
    hs, ws = -(-h // size), -(-w // size)
    padded = np.full((hs * size, ws * size), -np.inf)
    padded[:h, :w] = score
    blocks = padded.reshape(hs, size, ws, size).transpose(0, 2, 1, 3).reshape(hs, ws, size * size)
    arg = blocks.argmax(-1)
    has = np.isfinite(np.take_along_axis(blocks, arg[..., None], -1)[..., 0])
    sy, sx = np.nonzero(has)
    qy = sy * size + arg[sy, sx] // size
    qx = sx * size + arg[sy, sx] % size
    out = np.zeros((h, w), bool)
    out[qy, qx] = True
    return out


def _own_virtual_point(mi, dr, scene, ray, si, active):
    """(point, exact): this pass's PSR virtual point — the camera ray's origin plus its direction
    times the length of its chain of delta surfaces, followed by PSR's own code
    (:func:`dbench.datasets.sequence.psr.follow_delta_chain`, whose lobes at glass are drawn from the
    camera ray itself, so the chain is the one PSR followed for this pass) — for the lanes
    ``active`` whose first hit ``si`` along ``ray`` is a delta surface. ``exact`` is False where
    the chain leaves the scene (such lanes keep the G-buffer's position)."""
    ray = mi.Ray3f(ray)
    origin, direction = mi.Point3f(ray.o), mi.Vector3f(ray.d)
    chain = follow_delta_chain(mi, dr, scene, ray, si, mi.Bool(active), PSR_BOUNCES)
    return origin + direction * chain["length"], chain["alive"]


def _register(mi) -> None:
    """Register the ``dbench_reshade`` integrator once per process."""
    global _REGISTERED
    if _REGISTERED:
        return
    dr = __import__("drjit")

    class Reshade(mi.SamplingIntegrator):
        """Lane k: the nested integrator's path from ``origin`` to the first hit of lane k's
        camera ray (``targets[k]`` where that hit is a delta surface) where ``selected[k]``;
        the AOV ``valid`` says where a path was traced."""

        def __init__(self, props):
            super().__init__(props)
            self.nested = props["color"]
            self.origin = mi.Point3f(0.0)
            self.targets = mi.Point3f(0.0)
            self.selected = mi.Bool(False)

        def sample(self, scene, sampler, ray, medium=None, active=True):
            # lane index = pixel index at 1 spp (mi.render's wavefront is row-major)
            idx = dr.arange(mi.UInt32, dr.width(ray.o))
            stored = dr.gather(mi.Point3f, self.targets, idx)
            chosen = dr.gather(mi.Bool, self.selected, idx) & mi.Bool(active)
            # ``ray`` is this pass's camera ray of frame i−1 (the scene holds that camera): its
            # first hit is the sample's own point, the target of the re-shaded path; behind a
            # mirror or glass the target is this pass's own PSR virtual point
            own = scene.ray_intersect(mi.Ray3f(ray), chosen)
            hit = own.is_valid()
            behind = delta_only(mi, own.bsdf(mi.Ray3f(ray)).flags())
            virtual, exact = _own_virtual_point(mi, dr, scene, ray, own, chosen & hit & behind)
            target = dr.select(behind, dr.select(exact, virtual, stored), own.p)
            to_target = target - self.origin
            dist = dr.norm(to_target)
            direction = dr.select(hit, to_target / dr.maximum(dist, 1e-12), ray.d)
            new_ray = mi.Ray3f(self.origin, direction, ray.time, ray.wavelengths)
            first = scene.ray_intersect(new_ray, chosen & hit)
            # a virtual point is reached through the mirror or glass the new ray meets first
            through = delta_only(mi, first.bsdf(new_ray).flags())
            visible = chosen & (~hit | (first.is_valid() & (
                through | (first.t > dist * (1.0 - OCCLUSION_TOLERANCE)))))
            spec, _, _ = self.nested.sample(scene, sampler, new_ray, medium, visible)
            spec = dr.select(visible, spec, 0.0)
            return spec, mi.Bool(True), [dr.select(visible, mi.Float(1.0), mi.Float(0.0))]

        def aov_names(self):
            return ["valid.V"]

    mi.register_integrator("dbench_reshade", lambda props: Reshade(props))
    _REGISTERED = True


def render_reshade(scene_dict: dict, path: dict, origin, targets: np.ndarray,
                   selected: np.ndarray, seeds: list[int]) -> np.ndarray:
    """Re-shade the ``selected`` (H, W) pixels: (H, W, 3) float32, the mean over ``seeds`` (one
    1-spp pass each, the seeds of frame i−1's passes) of the path from ``origin`` (frame i's
    camera position) to each pass's first hit along the camera ray of ``scene_dict`` (frame
    i−1's camera, frame i's lights) — to that pass's own PSR virtual point where that hit is a
    mirror or glass (``targets``, frame i−1's G-buffer positions (H, W, 3), where its chain
    leaves the scene), along the same direction where the ray left the scene; NaN where not
    selected or, in any pass, hidden.

    ``path``: the nested integrator's dictionary (the frame's ``path`` integrator)."""
    mi = mitsuba()
    _register(mi)
    dr = __import__("drjit")
    h, w = selected.shape
    loaded = mi.load_dict(scene_dict, optimize=False)  # optimize=False: see sequence._render_dict
    key = repr(sorted(path.items()))
    integ: Any = _INTEGRATORS.get(key)
    if integ is None:  # one object per nested integrator: Dr.Jit then reuses its kernels
        integ = _INTEGRATORS[key] = mi.load_dict({"type": "dbench_reshade", "color": dict(path)},
                                                 optimize=False)
    # opaque: a literal origin would be baked into the traced kernel, which Dr.Jit would then
    # compile anew for every frame of a moving camera (0.7 s each at 64 px)
    integ.origin = mi.Point3f(*[float(v) for v in origin])
    dr.make_opaque(integ.origin)
    t = np.ascontiguousarray(np.nan_to_num(np.asarray(targets, np.float32)).reshape(-1, 3))
    integ.targets = mi.Point3f(mi.Float(t[:, 0]), mi.Float(t[:, 1]), mi.Float(t[:, 2]))
    integ.selected = mi.Bool(np.ascontiguousarray(selected.reshape(-1)))
    total = np.zeros((h, w, 3))
    valid = np.ones((h, w), bool)
    for s in seeds:
        out = np.array(mi.render(loaded, spp=1, seed=int(s), integrator=integ), np.float64)
        total += out[..., :3]
        valid &= out[..., 3] > 0.5
    dr.sync_thread()
    res = np.where(valid[..., None], total / len(seeds), np.nan)
    return res.astype(np.float32)


def reshade_frame(scene, res, i: int, prev: dict, seeds: list[int]) -> np.ndarray:
    """The gradient buffer of frame ``i`` of a sequence ``scene``: :func:`render_reshade` of
    :func:`select_strata` of frame i−1's colour and depth (``prev``), each pass aimed at its
    own hit of frame i−1 (behind mirrors and glass at its own PSR virtual point), traced from
    frame i's camera under frame i's lights with frame i−1's pass ``seeds``."""
    d = scene.frame_dict(mitsuba(), res, i - 1, i)  # frame i−1's camera rays, frame i's lights
    selected = select_strata(prev["color"], prev["depth"])
    return render_reshade(d, d["integrator"], scene.camera(i)[0], prev["position"], selected,
                          seeds)


__all__ = ["OCCLUSION_TOLERANCE", "STRATUM", "render_reshade", "reshade_frame", "select_strata"]
