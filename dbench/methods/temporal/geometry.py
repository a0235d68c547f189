"""One frame's G-buffer in the planar layout of the temporal methods (:class:`Geometry`), built
and checked from a Frame (:func:`frame_geometry`), and the expected distance of a pixel from the
previous camera (docs/methods/temporal.md §3.1)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ...data import check_buffer
from ...errors import DbenchInputError
from ..kernels.arrays import kernel_input


try:  # Numba is a dependency; the NumPy/Python reference still works without it
    import numba
    from numba import njit, prange
except ImportError:  # pragma: no cover
    numba = None


@dataclass
class Geometry:
    """One frame's G-buffer in the planar layout of this module (docs/methods/temporal.md §1).

    Attributes:
        hit: (H, W) bool, a surface was hit (depth > 0, everything finite).
        depth: (H, W) float32 distance along the camera ray, 0 where no hit.
        normal: (3, H, W) float32 world-space shading normal, 0 where no hit.
        position: (3, H, W) float32 world position or None.
        motion: (2, H, W) float32 offset (x, y) in pixels to the previous position, NaN where
            unknown; None when the frame carries no motion vectors.
        origin: (3,) camera origin of this frame or None.
    """

    hit: np.ndarray
    depth: np.ndarray
    normal: np.ndarray
    position: np.ndarray | None = None
    motion: np.ndarray | None = None
    origin: np.ndarray | None = None

    @property
    def shape(self) -> tuple[int, int]:
        return tuple(self.hit.shape)

    @classmethod
    def flat(cls, h: int, w: int, depth: float = 1.0, motion: tuple[float, float] | None = None
             ) -> "Geometry":
        """A fronto-parallel plane at ``depth`` with normal +z and a constant motion (tests)."""
        normal = np.zeros((3, h, w), np.float32)
        normal[2] = 1.0
        mot = None
        if motion is not None:
            mot = np.empty((2, h, w), np.float32)
            mot[0], mot[1] = motion
        return cls(hit=np.ones((h, w), bool), depth=np.full((h, w), depth, np.float32),
                   normal=normal, motion=mot)


def _frame_array(frame: Any, name: str, h: int, w: int, c: int, required: bool):
    value = getattr(frame, name, None)
    if value is None:
        if required:
            raise DbenchInputError(f"{name}: missing; expected an array of shape ({h}, {w}, {c})")
        return None
    value = np.asarray(value)
    if name == "depth" and value.ndim == 2:
        value = value[..., None]
    return check_buffer(name, value, (h, w, c))


#: The normal buffers a filter may read for its feature normals (seed 001 §1.2.1): the shading
#: normal, the geometric (face) normal, the glossy reflected normal (dbench.datasets.sequence.psr).
NORMAL_BUFFERS = ("normal", "geo_normal", "reflected_normal")


def feature_normal(frame: Any, geo: Geometry, name: str, why: str) -> np.ndarray:
    """The (3, H, W) float32 planar normal buffer ``name`` of ``frame`` for a filter's weights or
    features: ``geo.normal`` for "normal", else the frame's buffer, 0 where ``geo`` has no hit or
    the value is not finite. A missing buffer is a DbenchInputError naming it and ``why`` (the
    parameter that asked for it)."""
    if name == "normal":
        return geo.normal
    if name not in NORMAL_BUFFERS:
        raise DbenchInputError(f"normal buffer: expected one of {NORMAL_BUFFERS}, got {name!r}")
    h, w = geo.shape
    value = _frame_array(frame, name, h, w, 3, False)
    if value is None:
        raise DbenchInputError(f"{name}: missing, and {why} needs it; the sequence scenes' PSR "
                               f"G-buffers (gbuffer=psr or psr-glossy) provide it")
    ok = geo.hit & np.isfinite(value).all(-1)
    return np.ascontiguousarray(np.where(ok[..., None], value, 0).transpose(2, 0, 1),
                                dtype=np.float32)


def frame_geometry(frame: Any, position: bool = True, backend: str = "numba") -> Geometry:
    """Validate a Frame's G-buffers (errors name the buffer) and return its :class:`Geometry`.

    Needs ``depth`` (H, W, 1) and ``normal`` (H, W, 3), and ``position`` (H, W, 3) when
    ``position`` is True; ``motion`` (H, W, 2) is optional (None: no reprojection possible).
    The camera origin comes from ``frame.meta["camera"]["origin"]`` when present.
    """
    color = getattr(frame, "color", None)
    if color is None or np.ndim(color) != 3:
        raise DbenchInputError("color: expected shape (H, W, 3), got "
                               f"{None if color is None else np.shape(color)}")
    h, w = np.shape(color)[:2]
    depth = _frame_array(frame, "depth", h, w, 1, True)[..., 0]
    normal = _frame_array(frame, "normal", h, w, 3, True)
    pos = _frame_array(frame, "position", h, w, 3, True) if position else None
    motion = _frame_array(frame, "motion", h, w, 2, False)
    origin = None
    cam = (getattr(frame, "meta", None) or {}).get("camera")
    if isinstance(cam, dict) and cam.get("origin") is not None:
        origin = np.asarray(cam["origin"], np.float64).reshape(3)
        if not np.isfinite(origin).all():
            origin = None
    if backend == "numba" and numba is not None:
        hit = np.empty((h, w), np.bool_)
        depth_p = np.empty((h, w), np.float32)
        normal_p = np.empty((3, h, w), np.float32)
        pos_p = np.empty((3, h, w) if pos is not None else (3, 0, 0), np.float32)
        mot_p = np.empty((2, h, w) if motion is not None else (2, 0, 0), np.float32)
        # read-only inputs (methods/kernels/arrays.py): one specialisation whoever calls
        _geometry_nb(kernel_input(depth), kernel_input(normal),
                     kernel_input(pos if pos is not None else np.zeros((0, 0, 3), np.float32)),
                     kernel_input(motion if motion is not None
                                  else np.zeros((0, 0, 2), np.float32)),
                     hit, depth_p, normal_p, pos_p, mot_p)
        return Geometry(hit=hit, depth=depth_p, normal=normal_p,
                        position=pos_p if pos is not None else None,
                        motion=mot_p if motion is not None else None, origin=origin)
    hit = np.isfinite(depth) & (depth > 0) & np.isfinite(normal).all(-1)
    pos_p = None
    if pos is not None:
        hit &= np.isfinite(pos).all(-1)
        pos_p = np.ascontiguousarray(np.where(hit[..., None], pos, 0).transpose(2, 0, 1))
    mot_p = None if motion is None else np.ascontiguousarray(motion.transpose(2, 0, 1))
    return Geometry(hit=hit, depth=np.where(hit, depth, 0).astype(np.float32),
                    normal=np.ascontiguousarray(np.where(hit[..., None], normal, 0)
                                                .transpose(2, 0, 1), dtype=np.float32),
                    position=pos_p, motion=mot_p, origin=origin)


if numba is not None:
    @njit(cache=True, parallel=True)
    def _geometry_nb(depth, normal, pos, motion, hit, depth_p, normal_p, pos_p, mot_p):
        h, w = depth.shape
        has_pos = pos.shape[0] > 0
        has_mot = motion.shape[0] > 0
        for y in prange(h):
            for x in range(w):
                d = depth[y, x]
                ok = np.isfinite(d) and d > 0
                for c in range(3):
                    ok = ok and np.isfinite(normal[y, x, c])
                if has_pos:
                    for c in range(3):
                        ok = ok and np.isfinite(pos[y, x, c])
                hit[y, x] = ok
                depth_p[y, x] = d if ok else 0.0
                for c in range(3):
                    normal_p[c, y, x] = normal[y, x, c] if ok else 0.0
                if has_pos:
                    for c in range(3):
                        pos_p[c, y, x] = pos[y, x, c] if ok else 0.0
                if has_mot:
                    mot_p[0, y, x] = motion[y, x, 0]
                    mot_p[1, y, x] = motion[y, x, 1]


def expected_distance(cur: Geometry, prev_origin: np.ndarray | None) -> np.ndarray:
    """d_exp (H, W) float32 = ‖P(p) − o←‖ (docs/methods/temporal.md §3.1); this frame's depth without the data."""
    if cur.position is None or prev_origin is None:
        return cur.depth
    o = np.asarray(prev_origin, np.float32).reshape(3, 1, 1)
    d = np.sqrt(((cur.position - o) ** 2).sum(0))
    return np.where(cur.hit, d, 0).astype(np.float32)
