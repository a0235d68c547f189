"""Participating media of the transient catalogue (docs/transient.md §3, §5, §7; seed 004) and
the parameters the transient scenes declare (``--scene-param``, dbench.datasets.scenes.params).

Scenes (all ``transient_prbvolpath``, features from the room without the medium):

* ``fog-transient`` (registered in :mod:`dbench.datasets.transient.load`): the open room filled with
  homogeneous fog, σ_s 0.6, σ_a 0.1 /m, Henyey-Greenstein g 0.3 (seed 004 §8.2).
* ``cloud-transient``: a heterogeneous cloud hanging in the room between the light and the
  floor: four nested bumpy shells (:func:`cloud_shells`, triangle meshes built in memory, no
  files) whose regions hold homogeneous media of density 0.2, 0.45, 0.75 and 1 (a
  piecewise-constant density, highest in the core). **Note (mitransient 1.3.1, read and
  measured):** a ``heterogeneous`` medium over a ``gridvolume`` cannot be used: with a
  non-homogeneous medium ``transient_prbvolpath`` tracks by delta tracking and does not add the
  length of a null-collision step to the path's OPL (only real scattering steps and the
  remaining distance to a surface are added), so paths crossing a grid medium arrive early by
  the sum of their null steps: 0.95 m early behind a 1 m box of majorant 20 /m (test
  ``test_gridvolume_media_lose_null_collision_steps``). Homogeneous media have no null
  collisions, and the shells' null surfaces add their segments, so the layered cloud's OPLs are
  exact.
* ``fog-unwarped``: ``fog-transient`` with ``camera_unwarp=True`` (docs/transient.md §3). **Note
  (mitransient 1.3.1, read and measured):** ``transient_prbvolpath`` unwarps by subtracting the
  distance from the camera to the first *surface* along the primary ray (null interfaces such
  as the fog's box skipped), not to the first scattering event. Light scattered by the medium
  in front of that surface therefore lands earlier than its world time by the distance between
  the scattering point and the surface, below OPL 0: 57 % of the scene's energy (24² pilot),
  the earliest at OPL −1.09; directly visible lights land at OPL 0 (test
  ``test_unwarped_media_subtract_the_distance_to_the_first_surface``). No path can land below
  min over primary rays of (distance to the fog's box + box entry to the light − distance to
  the first surface) = −1.105 (1024² rays), whatever σ: the window starts at −1.2.

Parameters (``--scene-param NAME=VALUE``; one line naming the valid values otherwise):

* media scenes: ``sigma_s``, ``sigma_a`` (1/m; the cloud's at density 1; fog ≤ 2 and ≤ 1,
  cloud ≤ 12 and ≤ 2) and ``g`` (−1 < g < 1; seed 004 uses −0.6 … 0.6);
* every transient scene: ``emission=pulse|step`` (:attr:`TransientScene.emission`: the step
  response is the cumsum along T of the pulse response, docs/transient.md §7 check 5, taken on every
  rendered pass, so the per-bin statistics are those of each path's cumulative contributions;
  collector (a) only);
* media scenes: ``scattering=all|single|multiple``. ``transient_prbvolpath`` counts scattering
  vertices, medium or surface, null interfaces excluded, and ``max_depth`` = M keeps paths of
  at most M − 1 of them. ``single`` renders max_depth 2: directly visible lights plus every
  path with exactly one scattering vertex, which is single scattering in the medium *and*
  direct lighting of the surfaces (the integrator cannot tell them apart: exact for the
  vertex count, not a medium-only split). ``multiple`` is all minus single, rendered pass by
  pass with the same seed (:attr:`TransientScene.minus`): a sample index draws the same random
  numbers in both renders up to where max_depth 2 stops, so every path loses exactly its
  contributions of at most one vertex (measured: the difference is never negative and is 0
  wherever a pass has no longer path; float32 rounding where a voxel holds both). Costs a
  second render per pass; collector (a) only.

Windows: the catalogue scenes keep their own windows (:func:`size_window`). A parameter set
that changes the medium or the scattering orders gets the scene's range window
(``range_window``): start as the catalogue's (the camera-to-light distance 3.88 bounds every
warped path from below, and −1.105 every unwarped one, whatever the medium) and an end that holds ≥ 0.99 of the steady energy at
every corner of the declared ranges (measured with :func:`size_window`; tests/
tests/datasets/test_transient_media.py checks them). ``emission`` keeps the window: the step is the pulse's
cumsum over the same bins.
"""
from __future__ import annotations

import dataclasses
from functools import lru_cache
from typing import Any, Callable

import numpy as np

from ..scenes.record import register_scene
from ..scenes.params import Param, non_default
from ..scenes.parts import camera_dict, ceiling_light, diffuse_bsdf, room_shapes
from .scene import TRANSIENT_BUFFERS, TransientScene

#: seed 004 §8.2 (units not stated there; dbench reads them as 1/m)
FOG = {"type": "homogeneous", "sigma_s": 0.6, "sigma_a": 0.1, "g": 0.3, "units": "1/m"}
CLOUD_SEED = 17
#: the cloud's centre and the semi-axes of its unit shell (m); with its bumps (≤ 1.35×) it stays
#: clear of the ball, the walls and the light
CLOUD_BOX = ((-0.2, 0.35, -0.2), (0.55, 0.36, 0.52))
#: (shell scale, density inside it): the density grows inwards in four steps
CLOUD_SHELLS = ((1.0, 0.2), (0.78, 0.45), (0.56, 0.75), (0.34, 1.0))
CLOUD = {"type": "layered homogeneous", "sigma_s": 6.0, "sigma_a": 0.4, "g": 0.3,
         "units": "1/m at density 1",
         "density": f"4 nested bumpy shells, densities 0.2/0.45/0.75/1, seed {CLOUD_SEED}"}

MEDIUM_KEYS = ("sigma_s", "sigma_a", "g")
EMISSION = Param("emission", "pulse", "emitted signal (delta pulse or Heaviside step)",
                 choices=("pulse", "step"))
SCATTERING = Param("scattering", "all", "scattering orders", choices=("all", "single",
                                                                       "multiple"))


def medium_params(defaults: dict, sigma_s_max: float, sigma_a_max: float) -> tuple:
    """σ_s ∈ [0, sigma_s_max], σ_a ∈ [0, sigma_a_max] (1/m), HG g ∈ (−1, 1)."""
    return (Param("sigma_s", defaults["sigma_s"], "scattering coefficient sigma_s (1/m)",
                  lo=0.0, hi=sigma_s_max),
            Param("sigma_a", defaults["sigma_a"], "absorption coefficient sigma_a (1/m)",
                  lo=0.0, hi=sigma_a_max),
            Param("g", defaults["g"], "Henyey-Greenstein g", lo=-1.0, hi=1.0, open_lo=True,
                  open_hi=True))


FOG_PARAMS = medium_params(FOG, 2.0, 1.0) + (EMISSION, SCATTERING)
CLOUD_PARAMS = medium_params(CLOUD, 12.0, 2.0) + (EMISSION, SCATTERING)


def _values(medium: dict | None, defaults: dict) -> dict:
    return {k: float((medium or defaults)[k]) for k in MEDIUM_KEYS}


def homogeneous(m: dict) -> dict:
    """A ``homogeneous`` medium of σ_s, σ_a, g (``m``): σ_t = σ_s + σ_a, albedo σ_s/σ_t."""
    sigma_t = m["sigma_s"] + m["sigma_a"]
    return {"type": "homogeneous", "albedo": m["sigma_s"] / sigma_t if sigma_t > 0 else 0.0,
            "sigma_t": sigma_t, "phase": {"type": "hg", "g": m["g"]}}


def _room_with_ball(mi, res) -> dict:
    d = {"type": "scene",
         "sensor": camera_dict(mi, res, origin=[0, 0, 3.9], target=[0, 0, 0])}
    d.update(room_shapes(mi))
    d["light"] = ceiling_light(mi, 0.15, radiance=(60.0, 50.0, 36.0))
    d["ball"] = {"type": "sphere", "center": [0.3, -0.55, -0.1], "radius": 0.35,
                 "bsdf": diffuse_bsdf((0.7, 0.7, 0.7))}
    return d


def _fog_room(mi, res, with_fog: bool, medium: dict | None = None) -> dict:
    """The open room, a ball, a small bright ceiling light; with fog: a null-BSDF box just
    inside the walls holding a homogeneous medium (``medium``: σ_s, σ_a, g; default FOG)."""
    d = _room_with_ball(mi, res)
    if with_fog:
        d["fog"] = {"type": "cube", "to_world": mi.ScalarTransform4f().scale(0.98),
                    "bsdf": {"type": "null"}, "interior": homogeneous(_values(medium, FOG))}
    return d


# ---------------------------------------------------------------------------------------------
# the cloud


def _sphere_mesh(n_lat: int = 32, n_lon: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """A closed UV sphere of radius 1: vertices (V, 3) float64 and faces (F, 3) uint32, wound
    counter-clockwise seen from outside (normals point out: Mitsuba's ``interior`` is inside)."""
    th = np.pi * np.arange(1, n_lat) / n_lat
    ph = 2.0 * np.pi * np.arange(n_lon) / n_lon
    t, p = np.meshgrid(th, ph, indexing="ij")
    ring = np.stack([np.sin(t) * np.cos(p), np.cos(t), np.sin(t) * np.sin(p)], -1)
    verts = np.concatenate([[[0.0, 1.0, 0.0]], ring.reshape(-1, 3), [[0.0, -1.0, 0.0]]])
    i, j = np.meshgrid(np.arange(n_lat - 2), np.arange(n_lon), indexing="ij")
    a, b = 1 + i * n_lon + j, 1 + i * n_lon + (j + 1) % n_lon
    c, d = b + n_lon, a + n_lon
    south = len(verts) - 1
    j = np.arange(n_lon)
    top = np.stack([np.zeros(n_lon, int), 1 + (j + 1) % n_lon, 1 + j], -1)
    last = 1 + (n_lat - 2) * n_lon
    bottom = np.stack([np.full(n_lon, south), last + j, last + (j + 1) % n_lon], -1)
    quads = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                            np.stack([a, c, d], -1).reshape(-1, 3)])
    return verts, np.concatenate([top, quads, bottom]).astype(np.uint32)


@lru_cache(maxsize=2)
def cloud_shells(seed: int = CLOUD_SEED) -> tuple[tuple[np.ndarray, ...], np.ndarray]:
    """The cloud's nested shells in world space: ((V, 3) float32 vertices per shell, outermost
    first), faces (F, 3) uint32 shared by all. Deterministic from ``seed`` (NumPy's PCG64).

    One bumpy radius r(ω) = 1 + 0.35·B(ω)/max B, B a sum of twelve smooth puffs
    exp(−(1 − ω·c)/w²) on the sphere (random directions c, w 0.35…0.6 rad, heights 0.5…1),
    scaled by CLOUD_SHELLS and stretched to CLOUD_BOX: the shells are star-shaped and nested
    strictly, so they never cross."""
    rng = np.random.default_rng(seed)
    verts, faces = _sphere_mesh()
    dirs = rng.normal(size=(12, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    width, height = rng.uniform(0.35, 0.6, 12), rng.uniform(0.5, 1.0, 12)
    bumps = (height * np.exp(-(1.0 - verts @ dirs.T) / width ** 2)).sum(axis=1)
    radius = 1.0 + 0.35 * bumps / bumps.max()
    centre, half = (np.array(v) for v in CLOUD_BOX)
    shells = tuple((centre + verts * (radius * s)[:, None] * half).astype(np.float32)
                   for s, _ in CLOUD_SHELLS)
    return shells, faces


def _shell(mi, name: str, verts: np.ndarray, faces: np.ndarray, interior, exterior):
    """A null-BSDF triangle mesh built in memory with the media inside and outside it."""
    props = mi.Properties()
    props["bsdf"] = mi.load_dict({"type": "null"})
    props["interior"] = interior
    if exterior is not None:
        props["exterior"] = exterior
    mesh = mi.Mesh(name, len(verts), len(faces), props)
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(verts.ravel())
    params["faces"] = mi.UInt32(faces.ravel())
    params.update()
    return mesh


def _cloud_room(mi, res, with_cloud: bool, medium: dict | None = None) -> dict:
    """The fog scene's room with a layered cloud: nested shells (:func:`cloud_shells`), each
    region a homogeneous medium of density ρ_k (CLOUD_SHELLS): σ_t = ρ_k·(σ_s + σ_a), albedo
    σ_s/(σ_s + σ_a), HG g (``medium``; default CLOUD)."""
    d = _room_with_ball(mi, res)
    if with_cloud:
        m = _values(medium, CLOUD)
        media = [mi.load_dict(homogeneous({"sigma_s": rho * m["sigma_s"],
                                            "sigma_a": rho * m["sigma_a"], "g": m["g"]}))
                 for _, rho in CLOUD_SHELLS]
        shells, faces = cloud_shells()
        for k, verts in enumerate(shells):
            d[f"cloud{k}"] = _shell(mi, f"cloud{k}", verts, faces, media[k],
                                    media[k - 1] if k else None)
    return d


# ---------------------------------------------------------------------------------------------
# parameter sets


def transient_variant(base: TransientScene, values: dict[str, Any], *,
                      room: Callable | None = None,
                      range_window: tuple[float, float] | None = None) -> TransientScene:
    """The scene of one checked set of ``values`` (dbench.datasets.scenes.params.bind):
    ``room(mi, res, with_medium, medium)`` rebuilds the medium from σ_s, σ_a, g;
    ``scattering`` sets max_depth 2 (``single``) or a ``minus`` scene (``multiple``);
    ``emission`` the signal. A changed medium or scattering order moves the window to
    ``range_window`` (module docstring); every declared value goes into ``params``."""
    changed = non_default(base, values)
    changes: dict[str, Any] = {
        "params": dict(values), "declared": (), "variant": None,
        "description": f"{base.description} [" + ", ".join(f"{k}={v}" for k, v in
                                                              changed.items()) + "]",
        "emission": values.get("emission", "pulse")}
    medium = {k: values[k] for k in MEDIUM_KEYS if k in values}
    if room is not None and medium:
        def build(mi, res, _m=medium):
            return room(mi, res, True, _m)
        changes["build"] = build
        changes["medium"] = {**(base.medium or {}), **medium}
    if range_window is not None and set(changed) & {*MEDIUM_KEYS, "scattering"}:
        changes["window_start"], changes["window_end"] = range_window
    scattering = values.get("scattering", "all")
    if scattering == "single":
        changes["max_depth"] = 2
    scene = dataclasses.replace(base, **changes)
    if scattering == "multiple":
        single = dataclasses.replace(scene, name=f"{base.name}:single", max_depth=2,
                                     emission="pulse", minus=None)
        scene = dataclasses.replace(scene, minus=single)
    return scene


def media_variant(room: Callable, range_window: tuple[float, float]) -> Callable:
    def variant(base, values):
        return transient_variant(base, values, room=room, range_window=range_window)
    return variant


# Range windows, measured with size_window(coverage=0.99, res=16, spp=128) at the corners of
# the declared ranges (σ_s ∈ {0, max}, σ_a ∈ {0, max}, g = ±0.95), at σ_s 0.2 and at the
# scattering orders: the latest 99 % end (12.0, 7.5, 12.0: every time the room without any
# medium) plus 0.5 m. Starts: warped, the camera-to-light distance 3.88 bounds every path;
# unwarped fog, min over primary rays of (distance to the fog's box + box entry to the light
# − distance to the first surface) = −1.105 (1024² rays) bounds every path whatever σ.
FOG_RANGE_WINDOW = (3.8, 12.5)
FOG_UNWARPED_RANGE_WINDOW = (-1.2, 8.0)
CLOUD_RANGE_WINDOW = (3.8, 12.5)


def _register(name: str, description: str, build: Callable, **kw: Any) -> TransientScene:
    return register_scene(TransientScene(
        name=name, kind="transient", description=description, build=build,
        provides=TRANSIENT_BUFFERS, integrator="transient_prbvolpath",
        steady_integrator="volpath", max_depth=8, default_bins=200, **kw))


# Windows from size_window(scene, coverage=0.99, res=24, spp=256), as for the rest of the
# catalogue: 0.9908 (cloud) and 0.9926 (fog-unwarped) of the pilot's steady energy inside, none
# before (tests/datasets/test_transient_media.py repeats the sizing).
_register("cloud-transient", "a heterogeneous cloud (nested bumpy shells of density 0.2-1; σs 6, "
          "σa 0.4 /m at density 1, HG g 0.3) in the lit room: transient_prbvolpath",
          lambda mi, res: _cloud_room(mi, res, True), window_start=3.8, window_end=10.5,
          feature_build=lambda mi, res: _cloud_room(mi, res, False), medium=CLOUD,
          declared=CLOUD_PARAMS, variant=media_variant(_cloud_room, CLOUD_RANGE_WINDOW))
_register("fog-unwarped", "fog-transient with camera_unwarp (the first camera segment not "
          "counted; fog in front of a surface lands before OPL 0)",
          lambda mi, res: _fog_room(mi, res, True), window_start=-1.2, window_end=5.5,
          camera_unwarp=True, feature_build=lambda mi, res: _fog_room(mi, res, False),
          medium=FOG, declared=FOG_PARAMS,
          variant=media_variant(_fog_room, FOG_UNWARPED_RANGE_WINDOW))

__all__ = ["FOG", "CLOUD", "FOG_PARAMS", "CLOUD_PARAMS", "EMISSION", "SCATTERING",
           "cloud_shells", "homogeneous", "transient_variant", "media_variant",
           "FOG_RANGE_WINDOW", "FOG_UNWARPED_RANGE_WINDOW", "CLOUD_RANGE_WINDOW"]
