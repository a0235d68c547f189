"""Animated sequence datasets: moving cameras, switching lights, motion vectors, gradient frames.

Sequence scenes (kind ``sequence``) are static geometry seen by an animated camera and/or lit by
animated lights (docs/methods/temporal.md §1: object motion is out of scope). Frame ``i`` of a scene is a
Mitsuba dictionary built from the camera state of one frame and the light state of another
(:meth:`SequenceScene.frame_dict`), which is what the A-SVGF gradient frame needs.

Per frame (float32, row 0 = top), rendered and cached one frame at a time through
:class:`~dbench.datasets.cache.Cache`:

===========  ==========  ====================================================================
buffer       shape       source
===========  ==========  ====================================================================
color        (H, W, 3)   ``spp`` samples, seed ``pass_seed("seq-noisy", seed, i)``, box filter
albedo …     (H, W, C)   albedo, sh_normal, depth, position of the *same* samples (one render of
                         the ``aov`` integrator with a nested ``path``; :func:`render_frame`)
emission     (H, W, 3)   radiance emitted at those primary hits (nested ``path``, max_depth 1)
emitter      (H, W, 1)   fraction of the footprint whose primary ray sees an emitter with
                         radiance > 0, directly or in smooth mirrors (64 spp, box filter,
                         dbench/datasets/emitter.py; cached per frame, kind
                         ``seq-emitter``); comes with ``reference``
motion       (H, W, 2)   :func:`motion_vectors`: the world position seen by the previous camera
                         minus the same point seen by this frame's (no sub-pixel jitter)
gradient     (H, W, 3)   lights of frame i, camera of frame i−1, seed of frame i−1 (docs/methods/svgf.md
                         §6.4): every pixel re-traces the path of frame i−1 under the new
                         lighting. Frame 0: equal to ``color``.
reference    (H, W, 3)   ``ref_spp`` samples per frame in K ≥ 16 chunks (at most 256 spp each),
                         seed ``ref_seed`` (not ``seed``: noisy seeds share one reference)
reference_   (H, W, 3)   variance of the reference mean from the chunk spread
var                      (docs/judging.md §2), in the reference's cache entry
camera       meta        ``frame.meta["camera"]``: ``to_world`` (4×4 camera→world), ``origin``,
                         ``fov``, ``fov_axis``, ``width``, ``height``
===========  ==========  ====================================================================

The gradient frame is the spec's emulation of A-SVGF's seed reuse (docs/methods/svgf.md §6.4): with a
static camera it is exactly "the current frame shaded with the previous frame's random numbers";
with a moving camera the re-traced paths start at the previous camera, so view-dependent changes
caused by the camera motion are not seen (stated limitation). The mapping of the chosen samples
into the current frame is done by the method (dbench/methods/svgf: gathered through the motion
vectors, identical to the forward projection for a static camera).

Deviation from docs/methods/temporal.md §1 (G-buffer at ≥ 16 spp): by default the G-buffer is *matched*
to the colour samples (``gbuffer="matched"``: the albedo, normal, depth and position of the very
primary hits the colour samples started from, as a rasteriser feeding a real-time path tracer
gives them). A supersampled G-buffer mixes surfaces at silhouettes while a 1-spp colour sample
sees only one of them, and demodulating such a sample by the mixed albedo (a light's edge, a black
conductor) amplified it by orders of magnitude in our first renders (outputs near 1000 where
the reference was 3). ``gbuffer="supersampled"`` gives the
spec's 64-spp footprint averages (emission included) for comparison; the colour is identical.

Determinism: scenes are loaded with ``mi.load_dict(..., optimize=False)``. With the default
Mitsuba 3.9.1 reorders the emitters from one load to the next, which changes which light a given
random number picks: the same seed then renders different images in scenes with several lights,
and a gradient frame would not re-trace the previous frame's paths.

Lights are placed out of the cameras' direct view (they appear in reflections): a visible emitter
aliases at 1 spp (a jittered sample sees the light or the ceiling, the reference their average),
an error no denoiser removes and which dominated every RMSE in our first renders.

Scenes: ``orbit`` (camera arc through a room with diffuse and glossy objects; disocclusion behind
a tall box and at the image borders), ``flicker`` (static camera; the warm left ceiling light goes
off and a cool right one comes on at frame 16), ``mirror-pan`` (lateral camera pan in front of a
mirror wall, a chrome ball and a glossy brown wall: reflections move unlike their surfaces).

Example:
    >>> from dbench import datasets
    >>> seq = datasets.load("flicker", spp=1, res=16, frames=4)  # doctest: +SKIP
    >>> len(seq), seq[1].motion.shape, seq[1].meta["camera"]["fov"]  # doctest: +SKIP
    (4, (16, 16, 2), 39.3)
"""
from __future__ import annotations

import math
import time
from typing import Any, Callable, Iterable

import numpy as np

from ...data import Frame, Sequence, check_transform
from ...errors import DbenchInputError
from ...resolution import parse_res
from .. import emitter as _emitter
from .. import render as _render
from ..scenes import catalogue as _scenes
from ..cache import Cache
from ..mitsuba_env import mitsuba, versions
from ..scenes.record import Scene, register_scene
from ..scenes.parts import diffuse_bsdf, mirror_objects, rect_shape, room_shapes
from .scene import (GBUFFER_PARAM, GBUFFERS, PSR_ONLY_BUFFERS, SEQUENCE_BUFFERS, SequenceScene,
                    camera_info, gbuffer_variant, look_at_matrix, motion_vectors, project)
from .reshade import reshade_frame
from .frames import (MATCHED_LAYOUT, PSR_GLOSSY_ALPHA,  # noqa: F401 - re-exported
                     SAMPLES_VERSION, _matched_integrator, _render_dict, frame_seed,
                     pass_seeds, render_frame, render_gbuffer)
from .render import render_emitter, render_reference
from ..nonfinite import NONFINITE_VERSION, note_nonfinite, total
from ..references import check_ref_seed, check_render_args, reference_meta, reference_spp
from ..stats import stats_from_arrays, stats_to_arrays

FEATURES = ("albedo", "normal", "depth", "position")
REFERENCE_CHUNK = _render.DEFAULT_REFERENCE_CHUNK
GBUFFER_SPP = _render.DEFAULT_FEATURE_SPP
#: 3: the render adds ``geo_normal`` and ``reflected_normal`` (psr.py); 4: the lobe at glass
#: drawn from a hash of the camera ray, not the sampler (psr.replayable_draw)
PSR_VERSION = 4
GRADIENTS = ("reshade", "frame")
#: 4: each pass re-shaded from its own hit of frame i−1 (the virtual point behind mirrors and
#: glass), not from the pixel's mean position; 5: behind mirrors, each pass's own virtual point;
#: 6: behind glass too (PSR_VERSION 4)
RESHADE_VERSION = 6
#: 2: motion of the surface point without the sample's sub-pixel jitter (motion_vectors)
MOTION_VERSION = 2


def _sequence_scene(name: str, description: str, **kw: Any):
    def wrap(geometry: Callable[[Any], dict]) -> Callable[[Any], dict]:
        sc = SequenceScene(name=name, kind="sequence", description=description,
                           build=lambda mi, res, _n=name: _scenes.get(_n).frame_dict(mi, res, 0),
                           provides=SEQUENCE_BUFFERS, geometry=geometry,
                           declared=(GBUFFER_PARAM,), variant=gbuffer_variant, **kw)
        register_scene(sc)
        return geometry
    return wrap


# ---------------------------------------------------------------------------------------------
# the sequence catalogue

def _objects(mi) -> dict:
    """A tall diffuse box (occluder), a glossy (rough plastic) sphere and a small blue diffuse
    ball. Glossy surfaces are rough plastic, not rough conductors: Mitsuba's ``albedo`` AOV of a
    rough conductor is a view-dependent BSDF evaluation (measured values from 1e-18 to 15 on one
    sphere), which no albedo demodulation survives; rough plastic reports its diffuse albedo."""
    T = mi.ScalarTransform4f
    return {
        "tall_box": {"type": "cube",
                     "to_world": T().translate([-0.38, -0.45, -0.3]).rotate([0, 1, 0], 20)
                     .scale([0.25, 0.55, 0.25]),
                     "bsdf": diffuse_bsdf((0.75, 0.75, 0.72))},
        "glossy_ball": {"type": "sphere", "center": [0.42, -0.65, 0.2], "radius": 0.35,
                        "bsdf": {"type": "roughplastic", "distribution": "ggx", "alpha": 0.08,
                                 "diffuse_reflectance": {"type": "rgb",
                                                         "value": [0.55, 0.5, 0.45]}}},
        "blue_ball": {"type": "sphere", "center": [-0.05, -0.82, 0.55], "radius": 0.18,
                      "bsdf": diffuse_bsdf((0.1, 0.2, 0.65))},
    }


def _light_shape(mi, x: float, size: float = 0.2, z: float = 0.74) -> dict:
    """A ceiling light near the open front of the room, outside the cameras' view: visible
    emitters alias at 1 spp (a jittered sample sees the light or the ceiling, the reference
    their average), an error no denoiser can remove and which would dominate every RMSE.
    The lights still appear in reflections."""
    T = mi.ScalarTransform4f
    return rect_shape(mi, T().translate([x, 0.99, z]).rotate([1, 0, 0], 90).scale(size),
                 diffuse_bsdf((0, 0, 0)))


def _orbit_camera(i: int) -> tuple:
    theta = math.radians(-14.0 + 0.6 * i)
    r = 3.7
    return ((r * math.sin(theta), 0.1, r * math.cos(theta)), (0.0, -0.2, 0.0))


@_sequence_scene("orbit", "camera arc around a room with a tall box, a glossy sphere and a "
                 "ball: moving camera, disocclusion, static light", n_frames=48,
                 camera=_orbit_camera, lights=lambda i: {"light": (50.0, 36.0, 12.0)},
                 max_depth=6)
def orbit(mi) -> dict:
    d = room_shapes(mi)
    d.update(_objects(mi))
    d["light"] = _light_shape(mi, 0.0, 0.25, z=0.74)
    return d


FLICKER_SWITCH = 16


def _flicker_lights(i: int) -> dict:
    on_left = i < FLICKER_SWITCH
    return {"light_left": (72.0, 48.0, 18.0) if on_left else (0.0, 0.0, 0.0),
            "light_right": (0.0, 0.0, 0.0) if on_left else (24.0, 42.0, 78.0)}


@_sequence_scene("flicker", f"static camera; the warm left ceiling light goes off and a cool "
                 f"right one comes on at frame {FLICKER_SWITCH}", n_frames=48,
                 camera=lambda i: ((0.0, -0.1, 3.9), (0.0, -0.3, 0.0)), lights=_flicker_lights,
                 events={"light_change": FLICKER_SWITCH}, max_depth=6)
def flicker(mi) -> dict:
    d = room_shapes(mi)
    d.update(_objects(mi))
    d["light_left"] = _light_shape(mi, -0.5)
    d["light_right"] = _light_shape(mi, 0.5)
    return d


def _pan_camera(i: int) -> tuple:
    x = -0.6 + 1.2 * i / 47.0
    return ((x, -0.1, 3.9), (0.35 * x, -0.3, 0.0))


@_sequence_scene("mirror-pan", "lateral camera pan in front of a mirror back wall, a chrome "
                 "ball and a glossy wall: reflections move unlike their surfaces",
                 n_frames=48, camera=_pan_camera,
                 lights=lambda i: {"light": (50.0, 36.0, 12.0)}, max_depth=8)
def mirror_pan(mi) -> dict:
    d = room_shapes(mi, back_bsdf={"type": "conductor", "material": "Ag"},
              right_bsdf={"type": "roughplastic", "distribution": "ggx", "alpha": 0.05,
                          "diffuse_reflectance": {"type": "rgb",
                                                  "value": [0.45, 0.25, 0.12]}})
    d["light"] = _light_shape(mi, 0.0, 0.3)
    d.update(mirror_objects(mi))
    return d


# ---------------------------------------------------------------------------------------------
# rendering: the noisy frames are in sequence_frames.py


#: Images of an entry kind stored uncompressed beside its others (a part of their own in the
#: EXR): a frame's noisy colour, whose float mantissas are noise, where ZIP kept 83 % of its
#: bytes for 5× the write time (256², 9.5 ms against 1.9 ms); the G-buffer shrinks 5×
RAW_IMAGES = {"seq-frame": ("color",)}


def _cached_entry(cache: Cache, kind: str, desc: dict, render: Callable[[], dict[str, np.ndarray]],
                  meta: dict, name: str, time_key: str = "render_s", counts: dict | None = None
                  ) -> tuple[dict[str, np.ndarray], float | None]:
    """``render()`` through ``cache``; returns (images, seconds the render took, from the entry's
    meta on a hit). The seconds of a new render are added to ``meta[time_key]``. A frame's
    noisy colour is stored uncompressed (:data:`RAW_IMAGES`). ``counts``: the dict the render
    fills (``nonfinite_samples``, :mod:`dbench.datasets.nonfinite`), kept in the entry's meta
    and filled from it on a hit (the entries that hold it are keyed by
    :data:`~dbench.datasets.nonfinite.NONFINITE_VERSION`, so one made before the count was
    kept is never hit)."""
    entry = cache.get(kind, desc)
    if entry is not None:
        meta["cache_hits"].append(name)
        if counts is not None:
            counts["nonfinite_samples"] = entry.meta.get("nonfinite_samples")
        return entry.images(), entry.meta.get("render_s")
    t0 = time.perf_counter()
    images = render()
    seconds = time.perf_counter() - t0
    cache.put(kind, desc, images=images, meta={"render_s": seconds, **(counts or {})},
              raw_images=RAW_IMAGES.get(kind, ()))
    meta["rendered"].append(name)
    meta[time_key] = meta.get(time_key, 0.0) + seconds
    return images, seconds


def _frame_with_stats(cache: Cache, noisy_desc: dict, transform: str, lam: float, meta: dict,
                      i: int, render: Callable[[], dict], counts: dict
                      ) -> tuple[dict[str, np.ndarray], Any]:
    """A noisy frame and the statistics of its samples, each through the cache (``seq-frame``
    and ``seq-stats``); rendered once for both when either is missing (the passes are
    deterministic, so a frame cached without statistics gets the same colour again).
    ``counts`` as for :func:`_cached_entry`, kept with the frame's entry."""
    stats_desc = {**noisy_desc, "what": "stats", "transform": transform, "lam": float(lam)}
    frame_entry = cache.get("seq-frame", noisy_desc)
    stats_entry = cache.get("seq-stats", stats_desc)
    if frame_entry is not None and stats_entry is not None:
        meta["cache_hits"] += [f"frame{i}", f"stats{i}"]
        counts["nonfinite_samples"] = frame_entry.meta.get("nonfinite_samples")
        return (frame_entry.images(),
                stats_from_arrays(stats_entry.arrays(), transform, float(lam)))
    t0 = time.perf_counter()
    images = render()
    seconds = time.perf_counter() - t0
    stats = images.pop("stats")
    if frame_entry is None:
        cache.put("seq-frame", noisy_desc, images=images,
                  meta={"render_s": seconds, **counts}, raw_images=RAW_IMAGES["seq-frame"])
    cache.put("seq-stats", stats_desc, arrays=stats_to_arrays(stats),
              meta={"render_s": seconds, "diagnostics": stats.diagnostics})
    meta["rendered"] += [f"frame{i}", f"stats{i}"]
    meta["render_s"] = meta.get("render_s", 0.0) + seconds
    return images, stats


def _cached(cache: Cache, kind: str, desc: dict, render: Callable[[], dict[str, np.ndarray]],
            meta: dict, name: str) -> dict[str, np.ndarray]:
    return _cached_entry(cache, kind, desc, render, meta, name)[0]


def load_sequence(scene: str | SequenceScene, spp: int = 1, res=64,
                  needs: Iterable[str] | None = None, seed: int = 0, ref_spp: int | None = None,
                  cache: Cache | None = None, progress: bool = True,
                  frames: int | None = None, gbuffer: str | None = None,
                  ref_seed: int | None = None, transform: str = "box-cox",
                  lam: float = 0.5, gradient: str = "reshade") -> Sequence:
    """Render (or read from the cache) the first ``frames`` frames of a sequence scene.

    Args:
        scene: name or :class:`SequenceScene`.
        spp: samples per pixel of the noisy color (1 for real-time denoisers).
        res: image size (a side in pixels, ``"WxH"`` or (width, height)).
        needs: buffers wanted (``color`` always comes); None = all of SEQUENCE_BUFFERS.
        seed: base seed; noisy frames, features and references use disjoint seed streams.
        ref_spp: reference spp per frame (default ``DBENCH_REF_SPP`` or 4096).
        frames: how many frames from the start (default: the whole sequence).
        transform, lam: sample transform of the per-frame statistics (``stats`` in ``needs``;
            docs/methods/statistical.md §3), Box-Cox by default as for steady images.
        gbuffer: None (default): the scene's ``gbuffer`` parameter (``--scene-param
            gbuffer=…``; "psr" unless set). ``"psr"``: the G-buffer and emission of the colour
            samples themselves, seen through mirrors and glass (primary surface replacement,
            :mod:`dbench.datasets.sequence.psr`); ``"psr-glossy"``: the same, and glossy surfaces with
            roughness < 0.4 get the normal of what their mirror direction sees (seed 001's
            reflected normal); ``"matched"``: the same samples' plain AOVs (the
            mirror itself); ``"supersampled"``: independent 64-spp footprint averages
            (:func:`render_gbuffer`). The colour is the same in all three.
        gradient: the A-SVGF gradient buffer: ``"reshade"`` (default; docs/temporal.md §2,
            :mod:`dbench.datasets.sequence.reshade`): the brightest sample of each 3×3 stratum of frame
            i−1 re-shaded from camera i under the lights of i with the random numbers of i−1,
            NaN elsewhere; ``"frame"``: the older emulation, a whole frame rendered from camera
            i−1 with the lights of i and the seeds of i−1 (§6.4). The seconds spent rendering
            it are in the sequence's ``meta["gradient_s"]`` (new renders only) and, per frame
            and whether cached or not, ``meta["gradient_per_frame_s"]``.
    Returns:
        :class:`~dbench.data.Sequence`; each frame's ``meta`` holds ``frame`` and ``camera``;
        the sequence's ``meta`` holds the settings, ``events`` and cache hits. With
        ``reference`` (which brings ``reference_var`` and ``emitter``), the sequence's and each
        frame's ``meta`` add ``ref_spp``, ``ref_seed``, ``ref_render_s`` (seconds of the
        reference renders, from the cache entries when cached; not in ``render_s``) and
        ``ref_rmse`` = sqrt(mean(reference_var)) (over all frames for the sequence). Each
        frame's ``meta`` holds ``nonfinite_samples`` and ``ref_nonfinite_samples``, its NaN or
        ±Inf samples counted as 0 (:mod:`dbench.datasets.nonfinite`); the sequence's holds
        their sums over the frames and, where either is above 0, ``nonfinite_warning``.
    """
    sc = scene if isinstance(scene, Scene) else _scenes.get(scene)
    if not isinstance(sc, SequenceScene):
        raise DbenchInputError(f"scene: {sc.name} is a {sc.kind} scene, not a sequence")
    seed = check_render_args(spp, seed, ref_spp)
    res = parse_res(res)
    n = sc.n_frames if frames is None else frames
    if not isinstance(n, (int, np.integer)) or not 1 <= n <= sc.n_frames:
        raise DbenchInputError(f"frames: {sc.name} has {sc.n_frames} frames; expected an "
                               f"integer in [1, {sc.n_frames}], got {frames!r}")
    if gradient not in GRADIENTS:
        raise DbenchInputError(f"gradient: expected one of {GRADIENTS}, got {gradient!r}")
    declared = sc.params.get("gbuffer", GBUFFER_PARAM.default)
    if gbuffer is None:
        gbuffer = declared
    elif gbuffer != declared and declared != GBUFFER_PARAM.default:
        raise DbenchInputError(f"gbuffer: {gbuffer!r} given, but scene {sc.name} was bound "
                               f"with gbuffer={declared!r}; give one of them")
    if gbuffer not in GBUFFERS:
        raise DbenchInputError(f"gbuffer: expected one of {GBUFFERS}, got {gbuffer!r}")
    wanted = set(SEQUENCE_BUFFERS if needs is None else needs) | {"color"}
    unknown = wanted - SEQUENCE_BUFFERS
    if unknown:
        raise DbenchInputError(f"needs: scene {sc.name} cannot provide {sorted(unknown)}; "
                               f"it provides {sorted(SEQUENCE_BUFFERS)}")
    if "reference" in wanted:
        wanted.add("emitter")
    if "stats" in wanted:
        check_transform(transform, lam)
    ref_seed = check_ref_seed(ref_seed)
    cache = cache or Cache()
    ref_spp = int(ref_spp or reference_spp())
    # frames are the means of 1-spp passes (render_frame), summed as SAMPLES_VERSION says; the
    # marker keeps them apart from entries rendered as one call of spp samples or summed on
    # the host before non-finite colour samples counted as 0
    samples = {"samples": f"1-spp passes, {SAMPLES_VERSION}"}
    psr = {}
    if gbuffer in PSR_GLOSSY_ALPHA:  # with the glossy rule, other cache entries than the default's
        psr = {"psr": PSR_VERSION}
        if PSR_GLOSSY_ALPHA[gbuffer] > 0.0:
            psr["glossy_alpha"] = PSR_GLOSSY_ALPHA[gbuffer]
    frame_gbuffer = gbuffer if gbuffer in PSR_GLOSSY_ALPHA else "matched"
    mi = mitsuba()
    vers = versions()
    meta: dict = {"scene": sc.name, "kind": "sequence", "spp": int(spp), "res": res.key,
                  "seed": int(seed), "frames": int(n), "gbuffer": gbuffer, "ev": sc.ev, "events": dict(sc.events),
                  "versions": vers, "cache_hits": [], "rendered": [], "render_s": 0.0}
    if "reference" in wanted:
        meta.update(ref_spp=ref_spp, ref_seed=ref_seed, ref_render_s=0.0)
    ref_vars: list[np.ndarray] = []

    # the G-buffer choice is keyed by ``psr`` in the frames' entries only: references, emitter
    # buffers and gradient samples do not depend on it, and are shared
    data_params = {k: v for k, v in sc.params.items() if k != GBUFFER_PARAM.name}

    def base(i: int, what: str, **extra) -> dict:
        return {"scene": sc.name, "res": res.key, "frame": i, "what": what,
                "dict": sc.frame_dict(mi, res, i), "params": data_params, "versions": vers,
                **extra}

    out: list[Frame] = []
    prev_camera, prev_noisy = None, None
    gradient_seconds: list[float] = []  # per frame, cached or not: the cost of the samples
    from tqdm.auto import tqdm

    for i in tqdm(range(n), desc=f"{sc.name} frames", leave=False,
                  disable=not progress or n < 4, mininterval=0.5):
        camera = camera_info(sc, res, i)
        noisy_desc = base(i, "noisy+gbuffer+emission", spp=int(spp), seed=int(seed),
                          aovs=_render.AOV_STRING, nonfinite=NONFINITE_VERSION, **samples,
                          **psr)
        stats = None
        counts: dict = {}  # the frame's non-finite colour samples (datasets/nonfinite.py)
        if "stats" in wanted:
            noisy, stats = _frame_with_stats(cache, noisy_desc, transform, lam, meta, i,
                                             lambda: render_frame(sc, res, spp, seed, i, i, i,
                                                                  stats=(transform, lam),
                                                                  gbuffer=frame_gbuffer,
                                                                  counts=counts), counts)
        else:
            noisy = _cached_entry(cache, "seq-frame", noisy_desc,
                                  lambda: render_frame(sc, res, spp, seed, i, i, i,
                                                       gbuffer=frame_gbuffer, counts=counts),
                                  meta, f"frame{i}", counts=counts)[0]
        gbuf = noisy
        if gbuffer == "supersampled" and wanted & (set(FEATURES) | {"emission", "motion"}):
            gbuf = _cached(cache, "seq-gbuffer",
                           base(i, "gbuffer+emission", spp=GBUFFER_SPP, seed=int(seed),
                                aovs=_render.AOV_STRING),
                           lambda: render_gbuffer(sc, res, i, seed), meta, f"gbuffer{i}")
        buffers = {"color": noisy["color"]}
        buffers.update({k: gbuf[k] for k in ("emission",) + FEATURES if k in wanted})
        # geo_normal and reflected_normal: PSR G-buffers only (None with the others)
        buffers.update({k: noisy[k] for k in PSR_ONLY_BUFFERS if k in wanted and k in noisy})
        if "motion" in wanted:
            buffers["motion"] = motion_vectors(gbuf["position"], gbuf["depth"],
                                               prev_camera or camera, camera)
        if "gradient" in wanted:
            if i == 0:
                buffers["gradient"] = noisy["color"]
            elif gradient == "frame":
                desc = base(i, "gradient", spp=int(spp), seed=int(seed), aovs=_render.AOV_STRING,
                            gdict=sc.frame_dict(mi, res, i - 1, i), **samples)
                buffers["gradient"] = _cached(
                    cache, "seq-gradient", desc,
                    lambda: {"gradient": render_frame(sc, res, spp, seed, i - 1, i, i - 1)["color"]},
                    meta, f"gradient{i}")["gradient"]
            else:
                # the samples re-shade frame i-1's paths (its camera, lights and noisy
                # G-buffer) in frame i: its dictionary is part of what they are
                desc = base(i, "gradient-reshade", spp=int(spp), seed=int(seed),
                            aovs=_render.AOV_STRING, reshade=RESHADE_VERSION,
                            previous=sc.frame_dict(mi, res, i - 1), **samples, **psr)
                images, seconds = _cached_entry(
                    cache, "seq-gradient", desc,
                    lambda: {"gradient": reshade_frame(sc, res, i, prev_noisy,
                                                        pass_seeds(seed, i - 1, spp))},
                    meta, f"gradient{i}", time_key="gradient_s")
                buffers["gradient"] = images["gradient"]
                if seconds is not None:
                    gradient_seconds.append(float(seconds))
        if "emitter" in wanted:
            buffers["emitter"] = _cached_entry(
                cache, "seq-emitter",
                base(i, "emitter", spp=GBUFFER_SPP, seed=int(seed),
                     emitter=_emitter.EMITTER_VERSION),
                lambda: {"emitter": render_emitter(sc, res, i, seed)},
                meta, f"emitter{i}", time_key="emitter_s")[0]["emitter"]
        fmeta = {"scene": sc.name, "kind": "sequence", "frame": i, "spp": int(spp), "gbuffer": gbuffer,
                 "res": res.key, "seed": int(seed), "ev": sc.ev, "camera": camera,
                 "nonfinite_samples": counts.get("nonfinite_samples")}
        if "reference" in wanted:
            ref_counts: dict = {}
            ref, ref_s = _cached_entry(
                cache, "seq-reference",
                base(i, "reference", spp=ref_spp, seed=ref_seed, chunk=REFERENCE_CHUNK,
                     var=_render.REFERENCE_VAR_VERSION, nonfinite=NONFINITE_VERSION),
                lambda: dict(zip(("reference", "reference_var"),
                                 render_reference(sc, res, i, ref_seed, ref_spp,
                                                  counts=ref_counts))),
                meta, f"reference{i}", time_key="_ref_rendered_s", counts=ref_counts)
            buffers["reference"], buffers["reference_var"] = ref["reference"], ref["reference_var"]
            ref_vars.append(ref["reference_var"])
            meta["ref_render_s"] += float(ref_s or 0.0)
            fmeta.update(reference_meta(ref_spp, ref_seed, ref["reference_var"]),
                         ref_render_s=ref_s,
                         ref_nonfinite_samples=ref_counts.get("nonfinite_samples"))
        out.append(Frame(meta=fmeta, stats=stats, **buffers))
        prev_camera, prev_noisy = camera, noisy
    meta.pop("_ref_rendered_s", None)
    if gradient_seconds:
        meta["gradient_per_frame_s"] = float(np.mean(gradient_seconds))
    if ref_vars:
        meta.update(reference_meta(ref_spp, ref_seed, ref_vars))
    # the sequence's counts are its frames' sums, and its warning says them once
    for key in ("nonfinite_samples", "ref_nonfinite_samples"):
        meta[key] = total(f.meta.get(key) for f in out)
    return Sequence(out, meta=note_nonfinite(meta))


__all__ = ["SequenceScene", "SEQUENCE_BUFFERS", "FLICKER_SWITCH", "camera_info", "frame_seed",
           "load_sequence", "look_at_matrix", "motion_vectors", "project", "render_emitter",
           "render_frame", "render_reference"]
