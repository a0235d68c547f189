"""The state a sequence method keeps between frames: :class:`History` (the previous frame's
buffers and geometry, reprojected on demand) and :class:`HistoryDenoiser`, the base class of the
temporal methods."""
from __future__ import annotations

from typing import Any

import numpy as np

from ...data import check_buffer
from ...errors import DbenchInputError
from ...denoiser import Denoiser
from ..guards import RADIANCE_MAX
from .dispatch import reproject, resolve_backend
from .geometry import Geometry
from .numba_path import clamp_radiance, kernel_threads
from .params import EPS_F, TAU_D, TAU_N
from .taa import TAA_ALPHA, taa


class History:
    """The previous frame's geometry and history buffers of one sequence method.

    ``fetch(cur, c)`` reprojects the stored (C, H, W) buffers into the current frame (all
    reset when there is no previous frame, the size changed, or the frame has no motion);
    ``store(cur, buffers, valid)`` keeps this frame's buffers for the next call.
    The state is NumPy (float32 buffers, bool masks) for every backend; ``backend`` ("auto" is
    resolved here) selects the reprojection kernel.

    Frame to frame the compiled path reuses its arrays instead of allocating new ones (at 720p
    a fresh 10-channel history costs about 12 ms of page faults on the 2-core machine): what
    ``fetch`` returns is overwritten by the next ``fetch``, and ``staging(c, h, w)`` hands out
    a (C, H, W) array that does not hold the stored history, for the method to fill (through
    the kernels' ``out``) and ``store``.
    """

    def __init__(self, tau_d: float = TAU_D, tau_n: float = TAU_N, eps_f: float = EPS_F,
                 backend: str = "numba") -> None:
        backend = resolve_backend(backend)
        self.tau_d, self.tau_n, self.eps_f, self.backend = tau_d, tau_n, eps_f, backend
        self._arrays: dict[str, np.ndarray] = {}
        self.reset()

    def work_array(self, key: str, shape: tuple[int, ...]) -> np.ndarray:
        """The reusable float32 array ``key`` of ``shape`` (a new one when the shape changed),
        kept from frame to frame: its values are stale. A method keeps its own work arrays here
        too, under keys of its own ("fetched", "stage-a" and "stage-b" are the history's)."""
        arr = self._arrays.get(key)
        if arr is None or arr.shape != shape:
            arr = self._arrays[key] = np.empty(shape, np.float32)
        return arr

    def staging(self, channels: int, h: int, w: int) -> np.ndarray:
        """A reusable (channels, h, w) float32 array for this frame's history, not the one
        stored now (two alternate), so the kernels can write into it while the stored one is
        still to be read. Its values are stale: the caller writes every element."""
        for key in ("stage-a", "stage-b"):
            arr = self.work_array(key, (channels, h, w))
            if self.buffers is None or not np.may_share_memory(arr, self.buffers):
                return arr
        raise AssertionError("both staging arrays hold the history")  # pragma: no cover

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
                         self.eps_f, self.backend,
                         out=self.work_array("fetched", self.buffers.shape))

    def store(self, cur: Geometry, buffers: np.ndarray, valid: np.ndarray | None = None,
              finite: bool = False) -> None:
        """Keep (C, H, W) ``buffers`` of this frame; ``valid`` (H, W) marks usable pixels.
        ``finite=True`` promises the buffers hold no NaN/Inf (skips that check)."""
        buffers = np.ascontiguousarray(buffers, np.float32)
        fetched = self._arrays.get("fetched")
        if fetched is not None and np.may_share_memory(buffers, fetched):
            buffers = buffers.copy()  # the next fetch overwrites ``fetched``
        ok = cur.hit if valid is None else (cur.hit & valid)
        if not finite:
            ok = ok & np.isfinite(buffers).all(0)
            buffers = np.where(ok, buffers, 0.0).astype(np.float32)
        self.prev, self.buffers, self.valid = cur, buffers, ok
        self.frames += 1


#: The smallest demodulation floor: the spec's own threshold (docs/methods/svgf.md §2), so no sample
#: is amplified more than 1000× (a subnormal floor made 1 / a_eff overflow to Inf).
MIN_ALBEDO_FLOOR = 1e-3


def _check_unit_interval(name: str, value: Any, low: float = 0.0) -> None:
    """A plain number in (0, 1] (not a bool; in [low, 1] for low > 0), else DbenchInputError
    naming ``name``."""
    if (isinstance(value, bool) or not isinstance(value, (int, float))
            or not (low <= value <= 1.0 if low > 0 else 0.0 < value <= 1.0)):
        bounds = f"[{low:g}, 1]" if low > 0 else "(0, 1]"
        raise DbenchInputError(f"{name}: expected a number in {bounds}, got {value!r}")


class HistoryDenoiser(Denoiser):
    """Base of the reprojecting sequence methods (``accumulate``, ``svgf``/``asvgf``, ``bmfr``).

    Input range: finite colour values beyond ±:data:`~dbench.methods.guards.RADIANCE_MAX`
    (1e15) are clamped to it before anything else (NaN/±Inf stay missing samples), so that the
    float32 luminance moments l² — after albedo demodulation, (C / 1e-3)² — cannot overflow.

    A subclass validates its parameters in ``__init__`` and then calls :meth:`_start`, and
    implements ``_denoise(data, color)`` with ``color`` the checked (H, W, 3) input; ``denoise``
    runs it with the kernel thread count of the frame size. ``last`` holds the diagnostics of
    the latest frame; ``reset`` empties the history. A method with the parameters ``taa`` and
    ``taa_alpha`` passes its output through :meth:`_with_taa` (temporal antialiasing,
    :mod:`.taa`), whose own history is the previous TAA output.
    """

    def _start(self) -> None:
        p = self.params
        # reprojection's tests (docs/methods/temporal.md §3.2): a relative depth tolerance > 0
        # and a normal cosine in [-1, 1] (-1 accepts every normal)
        if not (isinstance(p["tau_d"], (int, float)) and 0.0 < p["tau_d"] < float("inf")):
            raise DbenchInputError(f"tau_d: expected a finite number > 0, got {p['tau_d']!r}")
        if not (isinstance(p["tau_n"], (int, float)) and -1.0 <= p["tau_n"] <= 1.0):
            raise DbenchInputError(f"tau_n: expected a number in [-1, 1], got {p['tau_n']!r}")
        # "auto" is decided once, here; params keep the resolved name so that result files
        # record the kernels that ran
        self.backend = p["backend"] = resolve_backend(p["backend"])
        self.history = History(p["tau_d"], p["tau_n"], EPS_F, self.backend)
        self.last: dict[str, Any] = {}
        self._taa_prev: np.ndarray | None = None
        if "taa" in p:
            if not isinstance(p["taa"], bool):
                raise DbenchInputError(f"taa: expected True or False, got {p['taa']!r}")
            _check_unit_interval("taa_alpha", p.get("taa_alpha", TAA_ALPHA))
        if "albedo_floor" in p:  # the demodulation's a_eff = clip(albedo, floor, 1)
            _check_unit_interval("albedo_floor", p["albedo_floor"], MIN_ALBEDO_FLOOR)

    def reset(self) -> None:
        self.history.reset()
        self.last = {}
        self._taa_prev = None

    @property
    def last_settings(self) -> dict[str, Any]:
        """The parameters the method runs with, its preset's values and "auto" resolved: a
        sweep records them beside the parameters it was given (bench/harness.py)."""
        return dict(self.params)

    def _with_taa(self, out: np.ndarray, motion: np.ndarray | None, status: np.ndarray
                  ) -> np.ndarray:
        """``out`` (H, W, 3) after temporal antialiasing when the ``taa`` parameter is on
        (:func:`.taa.taa` with the previous TAA output, none on the first frame or where the
        method's own history restarted: no pixel of the reprojection ``status`` (H, W) > 0);
        ``out`` itself otherwise."""
        p = self.params
        if not p.get("taa", False):
            return out
        prev = self._taa_prev
        if prev is None or prev.shape != out.shape or not (status > 0).any():
            prev = None
        out = taa(self.backend, out, prev, motion, float(p.get("taa_alpha", TAA_ALPHA)))
        self._taa_prev = out.copy()  # the caller owns the returned array
        return out

    def denoise(self, data) -> np.ndarray:
        color = check_buffer("color", getattr(data, "color", None), (None, None, 3))
        # the moments l² (and SVGF/BMFR's demodulated l² ≤ (C / 1e-3)²) are float32 history:
        # finite colours beyond RADIANCE_MAX would overflow them to Inf, then NaN (Inf − Inf)
        color = clamp_radiance(color, RADIANCE_MAX)  # guards.clamp_magnitude, compiled check
        with kernel_threads(color.shape[0] * color.shape[1]):
            return self._denoise(data, color)

    def _denoise(self, data, color: np.ndarray) -> np.ndarray:
        raise NotImplementedError
