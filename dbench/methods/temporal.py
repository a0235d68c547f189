"""Temporal accumulation, luminance moments and reprojection (spec/temporal.md).

Shared by ``accumulate``, ``svgf``/``asvgf`` and ``bmfr``. Functional core on planar float32
arrays — images are (C, H, W) here, so that every colour channel is one contiguous plane for the
compiled kernels — plus :class:`History`, the thin stateful wrapper a sequence method keeps.

Per frame (spec §5): build the frame's :class:`Geometry` (:func:`frame_geometry`), reproject the
previous frame's history buffers (:func:`reproject`: 2×2 bilinear with validity §3.3, normalised
3×3 fallback §3.4, reset on disocclusion §3.5), then :func:`accumulate` the new sample
(§2: ``C' = α C + (1 − α) C'←``, ``N = min(N← + 1, N_max)``, ``α = max(α_min, 1/N)``) and its
luminance :func:`moments` ``[l, l²]`` (Rec. 709 luminance).

Validity of a previous-frame tap q for pixel p (spec §3.2)::

    inside(q) and prev_ok(q) and hit(p)
    and |D←(q) − d_exp(p)| <= τ_d · d_exp(p)         τ_d = 0.05
    and n←(q) · n(p) >= τ_n                           τ_n = 0.9

``prev_ok`` is the previous hit mask and'ed with "history finite and not empty". ``d_exp`` is the
distance from the previous camera origin to this pixel's world position (:func:`expected_distance`);
without camera metadata it falls back to this frame's depth (exact for a static camera).

Backends (``backend=``): ``"numba"`` (compiled, parallel over rows), ``"reference"`` (readable
per-pixel NumPy, float64), ``"torch"`` (vectorised PyTorch: index-tensor gathers and masks, on
the device of the inputs or CUDA when available, :func:`reproject_torch`,
:func:`accumulate_torch`) and ``"auto"`` (torch on CUDA when ``torch.cuda.is_available()``, else
numba; :func:`resolve_backend`). The torch functions take and return tensors; the
NumPy-facing dispatchers (:func:`reproject`, :func:`accumulate_any`) convert at their boundary, and
:class:`History` keeps its state as NumPy arrays for every backend.

Non-finite policy: a pixel whose colour sample is non-finite is *missing*: it keeps its
reprojected history (the history length is not incremented), or becomes an empty history
(value 0, N = 0) that later frames and spatial filters ignore. Non-finite depth, normal or
position make a pixel "no hit" (its history is reset every frame). Non-finite motion means "no
previous position" (reset). Nothing non-finite is ever read from another pixel.

Example:
    >>> import numpy as np
    >>> h = np.arange(12, dtype=np.float32).reshape(1, 3, 4)          # (C, H, W)
    >>> geo = Geometry.flat(3, 4, motion=(1.0, 0.0))                   # everything moved 1 px
    >>> out, status = reproject(h, geo, geo, np.ones((3, 4), bool))
    >>> out[0, :, :3].tolist() == h[0, :, 1:].tolist(), status[:, 3].tolist()  # 3×3 fallback
    (True, [2, 2, 2])
"""
from __future__ import annotations

import math
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, Iterator

import numpy as np

from ..data import check_buffer
from ..errors import DbenchInputError
from ..registry import Denoiser
from .guards import RADIANCE_MAX, clamp_magnitude

try:  # Numba is a dependency; the NumPy/Python reference still works without it
    import numba
    from numba import njit, prange
except ImportError:  # pragma: no cover
    numba = None

LUMA = np.array([0.2126, 0.7152, 0.0722], np.float32)  # Rec. 709 [dbench]
N_MAX = 256          # history cap [S001]
TAU_D = 0.05         # relative depth tolerance (§3.2) [dbench]
TAU_N = 0.9          # normal cosine (§3.2) [dbench]
EPS_F = 1e-3         # minimum bilinear weight (§3.3) [dbench]
#: §3.4 fallback kernel exactly as printed in the seed (sums to 0.9997; normalised in use).
FALLBACK_KERNEL = np.array([[0.0778, 0.1233, 0.0778],
                            [0.1233, 0.1953, 0.1233],
                            [0.0778, 0.1233, 0.0778]])
#: reprojection status codes
RESET, BILINEAR, FALLBACK = 0, 1, 2
#: "auto" resolves to "torch" when CUDA is available, else "numba" (:func:`resolve_backend`).
BACKENDS = ("auto", "numba", "torch", "reference")


#: Below this many pixels the compiled kernels run on one thread: a parallel region costs
#: more than the work, and on a shared machine each one waits for a descheduled second thread.
SMALL_IMAGE = 1 << 16


@contextmanager
def kernel_threads(n_pixels: int) -> Iterator[None]:
    """Run the Numba kernels of one frame on a single thread when the image is small."""
    if numba is None or n_pixels >= SMALL_IMAGE:
        yield
        return
    old = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        yield
    finally:
        numba.set_num_threads(old)


# ---------------------------------------------------------------------------------------------
# geometry


@dataclass
class Geometry:
    """One frame's G-buffer in the planar layout of this module (spec/temporal.md §1).

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
        _geometry_nb(np.ascontiguousarray(depth), normal,
                     pos if pos is not None else np.zeros((0, 0, 3), np.float32),
                     motion if motion is not None else np.zeros((0, 0, 2), np.float32),
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
    """d_exp (H, W) float32 = ‖P(p) − o←‖ (spec §3.1); this frame's depth without the data."""
    if cur.position is None or prev_origin is None:
        return cur.depth
    o = np.asarray(prev_origin, np.float32).reshape(3, 1, 1)
    d = np.sqrt(((cur.position - o) ** 2).sum(0))
    return np.where(cur.hit, d, 0).astype(np.float32)


# ---------------------------------------------------------------------------------------------
# colour helpers


def luminance(color: np.ndarray) -> np.ndarray:
    """Rec. 709 luminance of a planar (3, H, W) image: (H, W)."""
    return LUMA[0] * color[0] + LUMA[1] * color[1] + LUMA[2] * color[2]


def moments(color: np.ndarray) -> np.ndarray:
    """Luminance moments [l, l²] (2, H, W) of a planar (3, H, W) image (spec §2)."""
    lum = luminance(color)
    return np.stack([lum, lum * lum])


def to_planar(image: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(np.transpose(image, (2, 0, 1)), dtype=np.float32)


def to_interleaved(image: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(np.transpose(image, (1, 2, 0)), dtype=np.float32)


# ---------------------------------------------------------------------------------------------
# reprojection (spec §3.3-3.5)


def _tap_valid(qx, qy, prev_ok, prev_depth, prev_normal, n_p, d_exp, tau_d, tau_n):
    h, w = prev_ok.shape
    if qx < 0 or qy < 0 or qx >= w or qy >= h or not prev_ok[qy, qx]:
        return False
    if abs(prev_depth[qy, qx] - d_exp) > tau_d * d_exp:
        return False
    dot = (prev_normal[0, qy, qx] * n_p[0] + prev_normal[1, qy, qx] * n_p[1]
           + prev_normal[2, qy, qx] * n_p[2])
    return dot >= tau_n


def reproject_reference(history: np.ndarray, motion: np.ndarray, cur_hit: np.ndarray,
                        cur_normal: np.ndarray, d_exp: np.ndarray, prev_ok: np.ndarray,
                        prev_depth: np.ndarray, prev_normal: np.ndarray, tau_d: float = TAU_D,
                        tau_n: float = TAU_N, eps_f: float = EPS_F
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Readable per-pixel transcription of spec §3.3-3.5 (float64 arithmetic).

    Shapes: history (C, H, W); motion (2, H, W); cur_hit, prev_ok, d_exp, prev_depth (H, W);
    cur_normal, prev_normal (3, H, W). Returns (reprojected (C, H, W) in history's dtype,
    status (H, W) uint8: 0 reset, 1 bilinear, 2 fallback). Reset pixels hold 0.
    """
    c, h, w = history.shape
    out = np.zeros(history.shape, np.float64)
    status = np.zeros((h, w), np.uint8)
    for y in range(h):
        for x in range(w):
            mx, my = float(motion[0, y, x]), float(motion[1, y, x])
            if not cur_hit[y, x] or not (math.isfinite(mx) and math.isfinite(my)):
                continue
            n_p = cur_normal[:, y, x].astype(np.float64)
            de = float(d_exp[y, x])
            px, py = x + mx, y + my
            x0, y0 = math.floor(px), math.floor(py)
            wx, wy = px - x0, py - y0
            taps = (((x0, y0), (1 - wx) * (1 - wy)), ((x0 + 1, y0), wx * (1 - wy)),
                    ((x0, y0 + 1), (1 - wx) * wy), ((x0 + 1, y0 + 1), wx * wy))
            f, acc = 0.0, np.zeros(c)
            for (qx, qy), b in taps:
                if b > 0 and _tap_valid(qx, qy, prev_ok, prev_depth, prev_normal, n_p, de,
                                        tau_d, tau_n):
                    f += b
                    acc += b * history[:, qy, qx]
            if f > eps_f:
                out[:, y, x] = acc / f
                status[y, x] = BILINEAR
                continue
            cx, cy = math.floor(px + 0.5), math.floor(py + 0.5)
            g, acc = 0.0, np.zeros(c)
            for dy in (-1, 0, 1):
                for dx in (-1, 0, 1):
                    if _tap_valid(cx + dx, cy + dy, prev_ok, prev_depth, prev_normal, n_p, de,
                                  tau_d, tau_n):
                        k = FALLBACK_KERNEL[dy + 1, dx + 1]
                        g += k
                        acc += k * history[:, cy + dy, cx + dx]
            if g > 0:
                out[:, y, x] = acc / g
                status[y, x] = FALLBACK
    return out.astype(history.dtype), status


if numba is not None:
    @njit(cache=True, inline="always")
    def _valid_nb(qx, qy, h, w, prev_ok, prev_depth, prev_normal, n0, n1, n2, de, tau_d, tau_n):
        if qx < 0 or qy < 0 or qx >= w or qy >= h:
            return False
        if not prev_ok[qy, qx]:
            return False
        if abs(prev_depth[qy, qx] - de) > tau_d * de:
            return False
        dot = (prev_normal[0, qy, qx] * n0 + prev_normal[1, qy, qx] * n1
               + prev_normal[2, qy, qx] * n2)
        return dot >= tau_n

    @njit(cache=True, parallel=True)
    def _reproject_nb(history, motion, cur_hit, cur_normal, d_exp, prev_ok, prev_depth,
                      prev_normal, tau_d, tau_n, eps_f, kernel, out, status):
        c, h, w = history.shape
        for y in prange(h):
            acc = np.zeros(c, np.float64)
            for x in range(w):
                for k in range(c):
                    out[k, y, x] = 0.0
                status[y, x] = 0
                mx = motion[0, y, x]
                my = motion[1, y, x]
                if not cur_hit[y, x] or not (np.isfinite(mx) and np.isfinite(my)):
                    continue
                n0 = cur_normal[0, y, x]
                n1 = cur_normal[1, y, x]
                n2 = cur_normal[2, y, x]
                de = d_exp[y, x]
                px = x + np.float64(mx)
                py = y + np.float64(my)
                x0 = int(math.floor(px))
                y0 = int(math.floor(py))
                wx = px - x0
                wy = py - y0
                f = 0.0
                acc[:] = 0.0
                for t in range(4):
                    qx = x0 + (t & 1)
                    qy = y0 + (t >> 1)
                    bx = wx if (t & 1) else 1.0 - wx
                    by = wy if (t >> 1) else 1.0 - wy
                    b = bx * by
                    if b > 0.0 and _valid_nb(qx, qy, h, w, prev_ok, prev_depth, prev_normal,
                                             n0, n1, n2, de, tau_d, tau_n):
                        f += b
                        for k in range(c):
                            acc[k] += b * history[k, qy, qx]
                if f > eps_f:
                    for k in range(c):
                        out[k, y, x] = acc[k] / f
                    status[y, x] = 1
                    continue
                cx = int(math.floor(px + 0.5))
                cy = int(math.floor(py + 0.5))
                g = 0.0
                acc[:] = 0.0
                for dy in range(-1, 2):
                    for dx in range(-1, 2):
                        if _valid_nb(cx + dx, cy + dy, h, w, prev_ok, prev_depth, prev_normal,
                                     n0, n1, n2, de, tau_d, tau_n):
                            kk = kernel[dy + 1, dx + 1]
                            g += kk
                            for k in range(c):
                                acc[k] += kk * history[k, cy + dy, cx + dx]
                if g > 0.0:
                    for k in range(c):
                        out[k, y, x] = acc[k] / g
                    status[y, x] = 2


def reproject_fast(history, motion, cur_hit, cur_normal, d_exp, prev_ok, prev_depth,
                   prev_normal, tau_d=TAU_D, tau_n=TAU_N, eps_f=EPS_F):
    """Compiled (Numba, parallel over rows) :func:`reproject_reference`; equal to it within
    float32 rounding of the output (the weights are computed in float64 in both)."""
    history = np.ascontiguousarray(history, np.float32)
    out = np.empty_like(history)
    status = np.empty(history.shape[1:], np.uint8)
    _reproject_nb(history, np.ascontiguousarray(motion, np.float32),
                  np.ascontiguousarray(cur_hit, np.bool_),
                  np.ascontiguousarray(cur_normal, np.float32),
                  np.ascontiguousarray(d_exp, np.float32), np.ascontiguousarray(prev_ok, np.bool_),
                  np.ascontiguousarray(prev_depth, np.float32),
                  np.ascontiguousarray(prev_normal, np.float32), float(tau_d), float(tau_n),
                  float(eps_f), FALLBACK_KERNEL, out, status)
    return out, status


def reproject(history: np.ndarray, cur: Geometry, prev: Geometry, prev_ok: np.ndarray,
              tau_d: float = TAU_D, tau_n: float = TAU_N, eps_f: float = EPS_F,
              backend: str = "numba") -> tuple[np.ndarray, np.ndarray]:
    """Reproject the previous frame's ``history`` (C, H, W) into the current frame.

    ``backend``: one of :data:`BACKENDS` ("torch" runs :func:`reproject_torch` on CUDA when
    available, else on CPU, and converts back to NumPy).

    Args:
        history: (C, H, W) buffers of frame i−1 (colour, moments, history length, …).
        cur, prev: geometry of frames i and i−1; ``cur.motion`` gives p← (spec §3.1).
        prev_ok: (H, W) bool, which previous pixels may be read (hit, finite, not empty).
    Returns:
        (reprojected (C, H, W) float32, status (H, W) uint8: 0 reset, 1 bilinear, 2 fallback).
    """
    if cur.motion is None:
        raise DbenchInputError("motion: missing; expected an array of shape (H, W, 2)")
    if prev.shape != cur.shape or history.shape[1:] != cur.shape:
        raise DbenchInputError(f"history: expected shape (C, {cur.shape[0]}, {cur.shape[1]}), "
                               f"got {history.shape}")
    d_exp = expected_distance(cur, prev.origin)
    args = (history, cur.motion, cur.hit, cur.normal, d_exp, prev_ok & prev.hit, prev.depth,
            prev.normal, tau_d, tau_n, eps_f)
    backend = resolve_backend(backend)
    if backend == "torch":
        out, status = reproject_torch(*args)
        return to_numpy(out), to_numpy(status)
    if backend == "reference" or numba is None:
        out, status = reproject_reference(*args)
        return out.astype(np.float32), status
    return reproject_fast(*args)


# ---------------------------------------------------------------------------------------------
# accumulation (spec §2)


def accumulate(sample: np.ndarray, history: np.ndarray, n_hist: np.ndarray, ok: np.ndarray,
               alpha_min: float = 0.0, n_max: float = N_MAX, alpha: np.ndarray | None = None,
               sample_ok: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One accumulation step: ``C' = α·C + (1 − α)·C'←`` (spec §2).

    Args:
        sample: (C, H, W) this frame's values.
        history: (C, H, W) reprojected history; n_hist (H, W) its (reprojected) length.
        ok: (H, W) bool, reprojection succeeded (else reset: C' = C, N = 1).
        alpha_min, n_max: α = max(α_min, 1/N) with N = min(N← + 1, N_max).
        alpha: (H, W) explicit α (A-SVGF) replacing the rule above where ok.
        sample_ok: (H, W) bool, the sample is usable (finite); where False the history is kept
            unchanged (N not incremented) or, without history, the pixel becomes empty (0, N = 0).
    Returns:
        (accumulated (C, H, W) float32, N (H, W) float32, α (H, W) float32).
    """
    ok = np.asarray(ok, bool)
    n = np.where(ok, np.minimum(n_hist + 1.0, n_max), 1.0).astype(np.float32)
    if alpha is None:
        a = np.maximum(np.float32(alpha_min), 1.0 / n)
    else:
        a = np.asarray(alpha, np.float32)
    a = np.where(ok, a, 1.0).astype(np.float32)
    if sample_ok is None:
        out = a * sample + (1.0 - a) * history
    else:
        s = np.where(sample_ok, sample, 0.0)
        out = np.where(sample_ok, a * s + (1.0 - a) * history, np.where(ok, history, 0.0))
        n = np.where(sample_ok, n, np.where(ok, n_hist, 0.0)).astype(np.float32)
        a = np.where(sample_ok, a, 0.0).astype(np.float32)
    return out.astype(np.float32), n, a


if numba is not None:
    @njit(cache=True, parallel=True, fastmath=True, error_model="numpy")
    def _accumulate_nb(sample, history, n_hist, ok, sample_ok, alpha, alpha_min, n_max,
                       out, n_out, a_out):
        c, h, w = sample.shape
        has_alpha = alpha.shape[0] > 0
        for y in prange(h):
            for x in range(w):
                if ok[y, x]:
                    n = min(n_hist[y, x] + np.float32(1.0), n_max)
                    a = alpha[y, x] if has_alpha else max(alpha_min, np.float32(1.0) / n)
                else:
                    n = np.float32(1.0)
                    a = np.float32(1.0)
                if sample_ok[y, x]:
                    for k in range(c):
                        out[k, y, x] = a * sample[k, y, x] + (np.float32(1.0) - a) * history[k, y, x]
                    n_out[y, x] = n
                    a_out[y, x] = a
                else:
                    for k in range(c):
                        out[k, y, x] = history[k, y, x] if ok[y, x] else np.float32(0.0)
                    n_out[y, x] = n_hist[y, x] if ok[y, x] else np.float32(0.0)
                    a_out[y, x] = np.float32(0.0)


def accumulate_fast(sample, history, n_hist, ok, alpha_min=0.0, n_max=N_MAX, alpha=None,
                    sample_ok=None):
    """Compiled :func:`accumulate` (same arguments and results, one fused pass)."""
    sample = np.ascontiguousarray(sample, np.float32)
    h, w = sample.shape[1:]
    out = np.empty_like(sample)
    n_out = np.empty((h, w), np.float32)
    a_out = np.empty((h, w), np.float32)
    _accumulate_nb(sample, np.ascontiguousarray(history, np.float32),
                   np.ascontiguousarray(n_hist, np.float32), np.ascontiguousarray(ok, np.bool_),
                   np.ones((h, w), np.bool_) if sample_ok is None
                   else np.ascontiguousarray(sample_ok, np.bool_),
                   np.zeros((0, 0), np.float32) if alpha is None
                   else np.ascontiguousarray(alpha, np.float32),
                   np.float32(alpha_min), np.float32(n_max), out, n_out, a_out)
    return out, n_out, a_out


def variance_from_moments(m: np.ndarray) -> np.ndarray:
    """Var = max(0, M'2 − M'1²) for (2, H, W) accumulated moments (spec §2)."""
    return np.maximum(0.0, m[1] - m[0] * m[0]).astype(np.float32)


def sample_mask(color: np.ndarray) -> np.ndarray:
    """(H, W) bool: every channel of the planar (3, H, W) sample is finite."""
    return np.isfinite(color).all(0)


# ---------------------------------------------------------------------------------------------
# PyTorch backend (CUDA when available, CPU tensors otherwise): same maths, vectorised


def torch_cuda_available() -> bool:
    """True when PyTorch is importable and sees a CUDA device."""
    from .kernels.bilateral.torch_path import torch_cuda_available as available
    return available()


def resolve_backend(backend: str) -> str:
    """``"auto"`` → ``"torch"`` when CUDA is available, else ``"numba"``; other names pass
    through after validation (DbenchInputError naming ``backend``)."""
    if backend not in BACKENDS:
        raise DbenchInputError(f"backend: expected one of {BACKENDS}, got {backend!r}")
    if backend == "auto":
        return "torch" if torch_cuda_available() else "numba"
    return backend


def torch_device(like: Any = None):
    """The device of tensor ``like``; else CUDA when available, else CPU."""
    import torch
    if isinstance(like, torch.Tensor):
        return like.device
    return torch.device("cuda" if torch.cuda.is_available() else "cpu")


def as_tensor(a: Any, device: Any = None, dtype: Any = None):
    """``a`` (ndarray or tensor) as a tensor on ``device`` (default: :func:`torch_device`);
    ``dtype`` None keeps float32/bool/integer types as they are (float64 arrays stay float64)."""
    import torch
    device = torch_device(a) if device is None else device
    if isinstance(a, torch.Tensor):
        return a.to(device=device, dtype=dtype or a.dtype)
    return torch.as_tensor(np.ascontiguousarray(a), device=device, dtype=dtype)


def to_numpy(t: Any) -> np.ndarray:
    """Tensor (any device) or array → NumPy array (no copy for CPU tensors)."""
    if isinstance(t, np.ndarray):
        return t
    return t.detach().cpu().numpy()


def reproject_torch(history, motion, cur_hit, cur_normal, d_exp, prev_ok, prev_depth,
                    prev_normal, tau_d=TAU_D, tau_n=TAU_N, eps_f=EPS_F, device=None):
    """Vectorised PyTorch :func:`reproject_reference` (spec §3.3-3.5): the four bilinear taps
    and the nine fallback taps of every pixel are gathers with (H, W) index tensors and masks.

    Same arguments and shapes as :func:`reproject_reference` (arrays or tensors); the device is
    ``device``, else that of ``history`` if it is a tensor, else CUDA when available, else CPU.
    Positions, weights and the validity tests are float64 — as in the reference, so that
    ``floor`` and the ``τ`` comparisons decide identically — the blend is float32.

    Returns:
        (reprojected (C, H, W) float32 tensor, status (H, W) uint8 tensor), on that device.
    """
    import torch
    dev = torch_device(history) if device is None else device
    f64 = torch.float64
    hist = as_tensor(history, dev, torch.float32)
    c, h, w = hist.shape
    mot = as_tensor(motion, dev, f64)
    hit = as_tensor(cur_hit, dev, torch.bool)
    n_p = as_tensor(cur_normal, dev, f64)
    de = as_tensor(d_exp, dev, f64)
    p_ok = as_tensor(prev_ok, dev, torch.bool).reshape(-1)
    p_dep = as_tensor(prev_depth, dev, f64).reshape(-1)
    p_nrm = as_tensor(prev_normal, dev, f64).reshape(3, -1)
    hist_f = hist.reshape(c, -1)

    active = hit & torch.isfinite(mot).all(0)
    yy = torch.arange(h, device=dev, dtype=f64)[:, None]
    xx = torch.arange(w, device=dev, dtype=f64)[None, :]
    # inactive pixels get p← = p so that no NaN reaches floor/long()
    px = xx + torch.where(active, mot[0], 0.0)
    py = yy + torch.where(active, mot[1], 0.0)

    def tap(qx, qy):
        """(valid (H, W) bool, flat index (H, W) int64) of previous-frame taps (qx, qy)."""
        inside = (qx >= 0) & (qy >= 0) & (qx < w) & (qy < h) & active
        idx = torch.where(inside, qy * w + qx, 0)
        ok = inside & p_ok[idx]
        ok &= (p_dep[idx] - de).abs() <= tau_d * de
        ok &= (p_nrm[:, idx] * n_p).sum(0) >= tau_n
        return ok, idx

    x0f, y0f = torch.floor(px), torch.floor(py)
    wx, wy = px - x0f, py - y0f
    x0, y0 = x0f.long(), y0f.long()
    f = torch.zeros((h, w), dtype=f64, device=dev)
    acc = torch.zeros((c, h, w), dtype=torch.float32, device=dev)
    for t in range(4):  # the 2×2 bilinear footprint (§3.3)
        bx = wx if t & 1 else 1.0 - wx
        by = wy if t >> 1 else 1.0 - wy
        b = bx * by
        ok, idx = tap(x0 + (t & 1), y0 + (t >> 1))
        b = torch.where(ok & (b > 0), b, 0.0)
        f += b
        acc += b.float() * hist_f[:, idx]
    bil = f > eps_f
    out = torch.where(bil, acc / torch.where(bil, f, 1.0).float(), 0.0)

    # the normalised 3×3 fallback (§3.4), evaluated where the bilinear test failed
    need = active & ~bil
    cx, cy = torch.floor(px + 0.5).long(), torch.floor(py + 0.5).long()
    g = torch.zeros((h, w), dtype=f64, device=dev)
    acc = torch.zeros_like(acc)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            ok, idx = tap(cx + dx, cy + dy)
            k = torch.where(ok & need, float(FALLBACK_KERNEL[dy + 1, dx + 1]), 0.0)
            g += k
            acc += k.float() * hist_f[:, idx]
    fb = need & (g > 0)
    out = torch.where(fb, acc / torch.where(fb, g, 1.0).float(), out)
    status = torch.where(bil, BILINEAR, torch.where(fb, FALLBACK, RESET)).to(torch.uint8)
    return out, status


def accumulate_torch(sample, history, n_hist, ok, alpha_min: float = 0.0, n_max: float = N_MAX,
                     alpha=None, sample_ok=None, device=None):
    """PyTorch :func:`accumulate` (same arguments, arrays or tensors; same float32 arithmetic).

    Returns:
        (accumulated (C, H, W), N (H, W), α (H, W)) float32 tensors on the device of
        ``sample`` (a tensor) or ``device``, else CUDA when available, else CPU.
    """
    import torch
    dev = torch_device(sample) if device is None else device
    f32 = torch.float32
    s = as_tensor(sample, dev, f32)
    hst = as_tensor(history, dev, f32)
    nh = as_tensor(n_hist, dev, f32)
    ok = as_tensor(ok, dev, torch.bool)
    n = torch.where(ok, torch.clamp(nh + 1.0, max=float(n_max)), 1.0)
    if alpha is None:
        a = torch.clamp(1.0 / n, min=float(np.float32(alpha_min)))
    else:
        a = as_tensor(alpha, dev, f32)
    a = torch.where(ok, a, 1.0)
    if sample_ok is None:
        return a * s + (1.0 - a) * hst, n, a
    sok = as_tensor(sample_ok, dev, torch.bool)
    s = torch.where(sok, s, 0.0)
    out = torch.where(sok, a * s + (1.0 - a) * hst, torch.where(ok, hst, 0.0))
    n = torch.where(sok, n, torch.where(ok, nh, 0.0))
    a = torch.where(sok, a, 0.0)
    return out, n, a


def accumulate_any(backend: str, sample, history, n_hist, ok, alpha_min=0.0, n_max=N_MAX,
                   alpha=None, sample_ok=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`accumulate` on the resolved ``backend`` ("numba": :func:`accumulate_fast`,
    "torch": :func:`accumulate_torch`, "reference": :func:`accumulate`), NumPy float32 out."""
    backend = resolve_backend(backend)
    args = (sample, history, n_hist, ok, alpha_min, n_max, alpha, sample_ok)
    if backend == "torch":
        return tuple(to_numpy(t) for t in accumulate_torch(*args))
    if backend == "numba" and numba is not None:
        return accumulate_fast(*args)
    return accumulate(*args)


# ---------------------------------------------------------------------------------------------
# the stateful wrapper


class History:
    """The previous frame's geometry and history buffers of one sequence method.

    ``fetch(cur, c)`` reprojects the stored (C, H, W) buffers into the current frame (all
    reset when there is no previous frame, the size changed, or the frame has no motion);
    ``store(cur, buffers, valid)`` keeps this frame's buffers for the next call.
    The state is NumPy (float32 buffers, bool masks) for every backend; ``backend`` ("auto" is
    resolved here) selects the reprojection kernel.
    """

    def __init__(self, tau_d: float = TAU_D, tau_n: float = TAU_N, eps_f: float = EPS_F,
                 backend: str = "numba") -> None:
        backend = resolve_backend(backend)
        self.tau_d, self.tau_n, self.eps_f, self.backend = tau_d, tau_n, eps_f, backend
        self.reset()

    def reset(self) -> None:
        self.prev: Geometry | None = None
        self.buffers: np.ndarray | None = None
        self.valid: np.ndarray | None = None
        self.frames = 0

    def fetch(self, cur: Geometry, channels: int) -> tuple[np.ndarray, np.ndarray]:
        """(reprojected (C, H, W) float32, status (H, W) uint8); zeros/RESET without history."""
        h, w = cur.shape
        if (self.prev is None or self.buffers is None or cur.motion is None
                or self.prev.shape != cur.shape or self.buffers.shape[0] != channels):
            return np.zeros((channels, h, w), np.float32), np.zeros((h, w), np.uint8)
        return reproject(self.buffers, cur, self.prev, self.valid, self.tau_d, self.tau_n,
                         self.eps_f, self.backend)

    def store(self, cur: Geometry, buffers: np.ndarray, valid: np.ndarray | None = None,
              finite: bool = False) -> None:
        """Keep (C, H, W) ``buffers`` of this frame; ``valid`` (H, W) marks usable pixels.
        ``finite=True`` promises the buffers hold no NaN/Inf (skips that check)."""
        buffers = np.ascontiguousarray(buffers, np.float32)
        ok = cur.hit if valid is None else (cur.hit & valid)
        if not finite:
            ok = ok & np.isfinite(buffers).all(0)
            buffers = np.where(ok, buffers, 0.0).astype(np.float32)
        self.prev, self.buffers, self.valid = cur, buffers, ok
        self.frames += 1


class HistoryDenoiser(Denoiser):
    """Base of the reprojecting sequence methods (``accumulate``, ``svgf``/``asvgf``, ``bmfr``).

    Input range: finite colour values beyond ±:data:`~dbench.methods.guards.RADIANCE_MAX`
    (1e15) are clamped to it before anything else (NaN/±Inf stay missing samples), so that the
    float32 luminance moments l² — after albedo demodulation, (C / 1e-3)² — cannot overflow.

    A subclass validates its parameters in ``__init__`` and then calls :meth:`_start`, and
    implements ``_denoise(data, color)`` with ``color`` the checked (H, W, 3) input; ``denoise``
    runs it with the kernel thread count of the frame size. ``last`` holds the diagnostics of
    the latest frame; ``reset`` empties the history.
    """

    def _start(self) -> None:
        p = self.params
        # "auto" is decided once, here; params keep the resolved name so that result files
        # record the kernels that ran
        self.backend = p["backend"] = resolve_backend(p["backend"])
        self.history = History(p["tau_d"], p["tau_n"], EPS_F, self.backend)
        self.last: dict[str, Any] = {}

    def reset(self) -> None:
        self.history.reset()
        self.last = {}

    def denoise(self, data) -> np.ndarray:
        color = check_buffer("color", getattr(data, "color", None), (None, None, 3))
        # the moments l² (and SVGF/BMFR's demodulated l² ≤ (C / 1e-3)²) are float32 history:
        # finite colours beyond RADIANCE_MAX would overflow them to Inf, then NaN (Inf − Inf)
        color = clamp_magnitude(color, RADIANCE_MAX)
        with kernel_threads(color.shape[0] * color.shape[1]):
            return self._denoise(data, color)

    def _denoise(self, data, color: np.ndarray) -> np.ndarray:
        raise NotImplementedError


__all__ = ["BACKENDS", "EPS_F", "FALLBACK_KERNEL", "Geometry", "History", "HistoryDenoiser", "LUMA", "N_MAX",
           "TAU_D", "TAU_N", "accumulate", "accumulate_any", "accumulate_torch", "as_tensor",
           "expected_distance", "reproject_torch", "resolve_backend", "to_numpy",
           "torch_cuda_available", "torch_device", "frame_geometry", "luminance",
           "moments", "reproject", "reproject_fast", "reproject_reference", "sample_mask",
           "accumulate_fast",
           "to_interleaved", "to_planar", "variance_from_moments"]
