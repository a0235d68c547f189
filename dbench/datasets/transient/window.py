"""The time window of a transient scene: :func:`size_window` (start at the earliest direct
arrival from the geometry, end where a pilot render has gathered ``coverage`` of the steady
energy) and the direct-arrival test scene of docs/transient.md §7 with its expected bins."""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from .. import render as _render
from ..mitsuba_env import mitsuba
from ..scenes.build import call_build
from ..scenes.parts import diffuse_bsdf
from .render import render_reference
from .scene import TransientScene, Window, transient_film

#: Near clip of the direct-arrival test camera (Mitsuba's default is 0.01 m).
DIRECT_NEAR_CLIP = 1e-4


def direct_arrival_dict(mi, res: int = 33, window: Window | None = None, unwarp: bool = False,
                        plane_z: float = 2.0, fov: float = 20.0,
                        near_clip: float = DIRECT_NEAR_CLIP) -> dict:
    """docs/transient.md §7 check 2: camera and point light at the origin looking down +z, a
    diffuse plane facing the camera at ``plane_z``, ``transient_path`` max_depth 2.

    **Note (measured):** Mitsuba's perspective sensor starts camera rays on the near-clip
    plane, so a warped OPL misses ``near_clip/cos θ`` of the camera segment (0.01 m with the
    default near clip: the centre pixel's OPL is 3.99, not 4.0, right at a bin edge of the
    spec's window). This scene uses ``near_clip`` = 1e-4 and :func:`expected_direct_bins`
    accounts for it."""
    window = window or Window(1.49, 0.02, 200)
    T = mi.ScalarTransform4f
    return {
        "type": "scene",
        "integrator": {"type": "transient_path", "max_depth": 2, "camera_unwarp": bool(unwarp)},
        "sensor": {"type": "perspective", "fov": fov, "fov_axis": "x", "near_clip": near_clip,
                   "to_world": T().look_at(origin=[0, 0, 0], target=[0, 0, 1], up=[0, 1, 0]),
                   "film": transient_film(res, res, window),
                   "sampler": {"type": "independent"}},
        "light": {"type": "point", "position": [0.0, 0.0, 0.0],
                  "intensity": {"type": "rgb", "value": [1.0, 1.0, 1.0]}},
        "plane": {"type": "rectangle",
                  "to_world": T().translate([0, 0, plane_z]).rotate([0, 1, 0], 180).scale(5.0),
                  "bsdf": diffuse_bsdf((0.5, 0.5, 0.5))},
    }


def direct_opl(ex, ey, unwarp: bool, plane_z: float = 2.0,
               near_clip: float = DIRECT_NEAR_CLIP):
    """OPL of the direct path through tan-plane coordinates (ex, ey) in
    :func:`direct_arrival_dict`: a plane point at distance d = z·sqrt(1 + ex² + ey²) from the
    camera (and the light) gives 2d − near_clip·sqrt(1 + ex² + ey²) warped, d unwarped."""
    r = np.sqrt(1.0 + np.square(ex) + np.square(ey))
    d = plane_z * r
    return d if unwarp else 2.0 * d - near_clip * r


def expected_direct_bins(res: int, window: Window, unwarp: bool, plane_z: float = 2.0,
                         fov: float = 20.0, near_clip: float = DIRECT_NEAR_CLIP
                         ) -> tuple[np.ndarray, np.ndarray]:
    """(lowest, highest) direct-arrival bin per pixel of :func:`direct_arrival_dict`
    (docs/transient.md §7 checks 2-3), from the OPL range over each pixel's footprint."""
    t = math.tan(math.radians(fov) / 2.0)
    edges = (1.0 - 2.0 * np.arange(res + 1) / res) * t      # tan-plane coordinate of pixel edges
    ex, ey = np.meshgrid(edges, edges)                        # (res+1, res+1)
    opl = direct_opl(ex, ey, unwarp, plane_z, near_clip)
    corners = np.stack([opl[:-1, :-1], opl[:-1, 1:], opl[1:, :-1], opl[1:, 1:]])
    lo_opl, hi_opl = corners.min(0), corners.max(0)
    # footprints that contain an axis (ex = 0 or ey = 0) reach lower OPLs than their corners
    cols = (edges[:-1] >= 0) & (edges[1:] <= 0)               # pixel spans ex = 0 / ey = 0
    axis_x = direct_opl(0.0, np.minimum(np.abs(ey[:-1, :-1]), np.abs(ey[1:, :-1])), unwarp,
                        plane_z, near_clip)
    axis_y = direct_opl(np.minimum(np.abs(ex[:-1, :-1]), np.abs(ex[:-1, 1:])), 0.0, unwarp,
                        plane_z, near_clip)
    lo_opl = np.where(cols[None, :], np.minimum(lo_opl, axis_x), lo_opl)
    lo_opl = np.where(cols[:, None], np.minimum(lo_opl, axis_y), lo_opl)
    lo_opl = np.where(cols[:, None] & cols[None, :],
                      direct_opl(0.0, 0.0, unwarp, plane_z, near_clip), lo_opl)
    lo = np.floor((lo_opl - window.start_opl) / window.bin_width_opl).astype(int)
    hi = np.floor((hi_opl - window.start_opl) / window.bin_width_opl).astype(int)
    return lo, hi


def _emitter_boxes(mi, sc) -> list[tuple[np.ndarray, np.ndarray]]:
    boxes = []
    for em in sc.emitters():
        shape = em.get_shape()
        if shape is not None:
            bb = shape.bbox()
            boxes.append((np.array(bb.min, np.float64).ravel(),
                          np.array(bb.max, np.float64).ravel()))
        else:
            p = np.array(em.world_transform().translation(), np.float64).ravel()
            boxes.append((p, p))
    return boxes


def direct_arrivals(scene: TransientScene, res: int = 32, seed: int = 0) -> np.ndarray:
    """(res, res) warped OPL of the earliest direct arrival per pixel from the geometry:
    camera → first hit (depth AOV) + first hit → nearest point of an emitter's bounding box;
    NaN where nothing is hit. A lower bound on every path's OPL in the pixel (up to the pixel
    footprint), used to place ``window_start``."""
    mi = mitsuba()
    # one sample per pixel: with the box filter the AOVs are then single hits, not averages
    # of a hit and the background at silhouettes
    feats, _ = _render.render_features(scene.feature_scene, res, spp=1, seed=seed)
    sc = mi.load_dict(call_build(scene.build, mi, res, f"scene {scene.name}"))
    depth = feats["depth"][..., 0].astype(np.float64)
    pos = feats["position"].astype(np.float64)
    best = np.full(depth.shape, np.inf)
    for lo, hi in _emitter_boxes(mi, sc):
        gap = np.maximum(np.maximum(lo - pos, pos - hi), 0.0)
        best = np.minimum(best, np.sqrt((gap ** 2).sum(-1)))
    out = depth + best
    out[depth <= 0] = np.nan
    return out


def size_window(scene: TransientScene, coverage: float = 0.99, res: int = 24, spp: int = 256,
                horizon: float = 40.0, bins: int = 4000, seed: int = 0) -> dict:
    """Choose a window for ``scene``: start at the earliest direct arrival (geometry, rounded
    down to 0.1 m) and end where ``coverage`` of the steady energy has arrived (pilot transient
    render of ``res``² px at ``spp`` over [start, start + ``horizon``), rounded up to 0.5 m).

    Unwarped scenes (``camera_unwarp``) have no geometric start (in media, mitransient's
    unwarping puts energy below OPL 0, dbench.datasets.transient.media): the pilot covers
    [−horizon/4, 3·horizon/4) and the start is its first bin holding energy, rounded down to
    0.1 m, less 0.1 m (an empirical bound: a pilot sees a finite set of paths).

    The pilot renders the scene as it is (medium, ``minus`` scene, max_depth) with pulse
    emission (a step's window is its pulse's). Returns start, end, the first arrival, the
    fraction of the pilot's steady energy inside [start, end) and before start (which must
    be 0)."""
    if scene.camera_unwarp:
        lo, hi = -horizon / 4.0, 0.75 * horizon
    else:
        first = float(np.nanmin(direct_arrivals(scene, res=max(res, 64), seed=seed)))
        start = math.floor(first * 10.0) / 10.0
        lo, hi = 0.0, start + horizon
    pilot = dataclasses.replace(scene, name=f"{scene.name}:pilot", window_start=lo,
                                window_end=hi, default_bins=bins, emission="pulse")
    video, _, steady, _ = render_reference(pilot, res, spp, seed=seed, chunk=64)
    window = pilot.window()
    per_bin = video.astype(np.float64).sum(axis=(0, 1, 3))
    total = float(steady.astype(np.float64).sum())
    if scene.camera_unwarp:
        first = float(window.start_opl + np.flatnonzero(per_bin > 0)[0] * window.bin_width_opl)
        start = math.floor(first * 10.0) / 10.0 - 0.1
    cum = np.cumsum(per_bin) / total
    first_bin = window.bin_of(start)
    before = float(cum[first_bin - 1]) if first_bin > 0 else 0.0
    inside = cum - before
    idx = int(np.searchsorted(inside, coverage))
    end = window.start_opl + (min(idx, window.bins - 1) + 1) * window.bin_width_opl
    end = math.ceil(end * 2.0) / 2.0
    last = window.bin_of(end)
    frac = float(cum[min(last, window.bins) - 1] - before)
    return {"scene": scene.name, "first_arrival": first, "start_opl": start, "end_opl": end,
            "fraction_inside": frac, "fraction_before_start": before,
            "fraction_in_pilot_window": float(cum[-1])}
