"""The sequence scene record (:class:`SequenceScene`: static geometry, a camera and lights per
frame) and its camera geometry (docs/mitsuba.md §9, docs/methods/temporal.md §3.1): Mitsuba's
``look_at`` matrix, projection to pixels and motion vectors. The catalogue and the loader are in
:mod:`dbench.datasets.sequence.load`."""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from ...resolution import parse_res
from .psr import PSR_EXTRA_LAYOUT
from ..scenes.record import Scene
from ..scenes.params import Param, non_default
from ..scenes.parts import camera_dict

SEQUENCE_BUFFERS = frozenset({"color", "albedo", "normal", "depth", "position", "motion",
                              "gradient", "emission", "emitter", "stats", "reference",
                              "geo_normal", "reflected_normal"})
FOV = 39.3
#: the G-buffers :func:`dbench.datasets.sequence.load.load_sequence` can attach to the colour
GBUFFERS = ("psr", "psr-glossy", "matched", "supersampled")
#: the G-buffers of the PSR render (dbench.datasets.sequence.psr), and the buffers only they carry
PSR_GBUFFERS = ("psr", "psr-glossy")
PSR_ONLY_BUFFERS = frozenset(name for name, _, _ in PSR_EXTRA_LAYOUT)
#: ``--scene-param gbuffer=…`` of every catalogue sequence: which G-buffer the frames carry
#: (a data choice, so part of the scene's identity through ``Scene.params``)
GBUFFER_PARAM = Param("gbuffer", "psr", doc="G-buffer", choices=GBUFFERS)


def gbuffer_variant(base: "SequenceScene", values: dict[str, Any]) -> "SequenceScene":
    """The sequence scene of a checked ``--scene-param`` set (dbench.datasets.scenes.params.bind):
    the same frames, with ``params`` naming the G-buffer :func:`load_sequence` attaches."""
    changed = non_default(base, values)
    provides = base.provides
    if values.get(GBUFFER_PARAM.name, GBUFFER_PARAM.default) not in PSR_GBUFFERS:
        # geo_normal and reflected_normal come with the PSR render only: a method that needs
        # them is skipped on the other G-buffers before anything is rendered
        provides = frozenset(provides) - PSR_ONLY_BUFFERS
    return dataclasses.replace(
        base, params=dict(values), declared=(), variant=None, provides=provides,
        description=f"{base.description} [" + ", ".join(f"{k}={v}" for k, v in changed.items())
        + "]")


@dataclass(frozen=True, eq=False)
class SequenceScene(Scene):
    """A catalogue entry whose camera and lights change per frame (geometry is static).

    Attributes (beyond :class:`~dbench.datasets.scenes.record.Scene`):
        n_frames: length of the sequence.
        geometry: ``geometry(mi) -> dict`` of the static shapes (emitters included, with their
            radiance set per frame by ``lights``).
        camera: ``camera(i) -> (origin, target)`` of frame i (up is +y).
        lights: ``lights(i) -> {shape key: (r, g, b) radiance}`` of frame i.
        events: frame indices of notable changes, e.g. ``{"light_change": 16}``.
    """

    n_frames: int = 48
    geometry: Callable[[Any], dict] | None = None
    camera: Callable[[int], tuple] | None = None
    lights: Callable[[int], dict] | None = None
    events: dict = field(default_factory=dict)
    fov: float = FOV

    def frame_dict(self, mi, res, camera_frame: int, light_frame: int | None = None) -> dict:
        """The Mitsuba dictionary with the camera of ``camera_frame`` and the lights of
        ``light_frame`` (default: the same frame)."""
        light_frame = camera_frame if light_frame is None else light_frame
        origin, target = self.camera(camera_frame)
        d = {"type": "scene",
             "sensor": camera_dict(mi, res, origin=list(origin), target=list(target),
                               fov=self.fov),
             "integrator": {"type": "path", "max_depth": self.max_depth}}
        d.update(self.geometry(mi))
        for key, radiance in self.lights(light_frame).items():
            d[key]["emitter"] = {"type": "area",
                                 "radiance": {"type": "rgb", "value": [float(v) for v in radiance]}}
        return d

    def scene_dict(self, mi, res) -> dict:  # frame 0, for code written for steady scenes
        return self.frame_dict(mi, res, 0)


def look_at_matrix(origin, target, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """Camera→world 4×4 matrix of Mitsuba's ``look_at`` (camera looks along its local +z,
    local x = up × dir): float64 (4, 4)."""
    o = np.asarray(origin, np.float64)
    d = np.asarray(target, np.float64) - o
    d /= np.linalg.norm(d)
    left = np.cross(np.asarray(up, np.float64), d)
    left /= np.linalg.norm(left)
    new_up = np.cross(d, left)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, new_up, d, o
    return m


def camera_info(scene: SequenceScene, res, i: int) -> dict:
    """The camera of frame ``i``: ``to_world`` (4×4 list), ``origin``, ``fov`` (degrees),
    ``fov_axis`` (``x`` or ``y``: the axis ``fov`` spans, the smaller side of a non-square
    image, dbench.resolution), ``width``, ``height`` (JSON-able)."""
    res = parse_res(res)
    origin, target = scene.camera(i)
    m = look_at_matrix(origin, target)
    return {"to_world": m.tolist(), "origin": m[:3, 3].tolist(), "fov": float(scene.fov),
            "fov_axis": "x" if res.width <= res.height else "y",
            "width": res.width, "height": res.height}


def project(points: np.ndarray, camera: dict) -> tuple[np.ndarray, np.ndarray]:
    """Continuous pixel coordinates of world ``points`` (…, 3) seen by ``camera`` (docs/methods/temporal.md §3.1).

    Returns ``(p, c_z)``: p (…, 2) with (x, y), integer values at pixel centres (pixel (i, j)
    spans [i − 0.5, i + 0.5)); c_z (…) the camera-space depth, the point being in front of the
    camera only where c_z > 0.
    """
    pts = np.asarray(points, np.float64)
    inv = np.linalg.inv(np.asarray(camera["to_world"], np.float64))
    c = pts @ inv[:3, :3].T + inv[:3, 3]
    w, h = float(camera["width"]), float(camera["height"])
    t = math.tan(math.radians(camera["fov"]) / 2.0)
    sx, sy = (t, t * h / w) if camera.get("fov_axis", "x") == "x" else (t * w / h, t)
    cz = c[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = 0.5 - 0.5 * c[..., 0] / (cz * sx)
        v = 0.5 - 0.5 * c[..., 1] / (cz * sy)
    return np.stack([u * w - 0.5, v * h - 0.5], axis=-1), cz


def motion_vectors(position: np.ndarray, depth: np.ndarray, prev_camera: dict, camera: dict
                   ) -> np.ndarray:
    """Offsets (H, W, 2) float32 from every pixel to where its surface point was in the frame
    seen by ``prev_camera`` (docs/methods/temporal.md §3.1), exact for static geometry.

    ``motion[y, x] = project(P, prev_camera) − project(P, camera)`` in pixels (x right, y down),
    P the pixel's world position: the motion of the surface point, without the sub-pixel jitter
    of the sample that found it. A pixel's 1-spp G-buffer sample lies anywhere in its footprint,
    so ``project(P, prev_camera) − (x, y)`` (the form used before) moved every history fetch by
    a random offset of up to half a pixel, a blur that builds up over the history (a static
    camera got non-zero motion): on ``orbit`` at 64², 1 spp, plain accumulation's relMSE was
    0.056 with it and 0.034 without (results/temporal.md). Real-time renderers remove the
    jitter from their motion vectors the same way. NaN where nothing is hit (depth 0 or
    non-finite) or the point is behind either camera.
    """
    h, w = depth.shape[:2]
    position = np.asarray(position, np.float64).reshape(h, w, 3)
    depth = np.asarray(depth, np.float64).reshape(h, w)
    p_prev, cz_prev = project(position, prev_camera)
    p_now, cz_now = project(position, camera)
    motion = p_prev - p_now
    bad = ~(np.isfinite(depth) & (depth > 0) & (cz_prev > 0) & (cz_now > 0)
            & np.isfinite(position).all(-1) & np.isfinite(motion).all(-1))
    motion[bad] = np.nan
    return motion.astype(np.float32)
