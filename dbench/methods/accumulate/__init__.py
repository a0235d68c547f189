"""``accumulate``: temporal accumulation alone (docs/methods/temporal.md §2-§3), the baseline every
sequence denoiser must beat.

Per frame: reproject the previous accumulated colour, luminance moments and history length
(2×2 bilinear with validity, normalised 3×3 fallback, reset on disocclusion), then
``C' = α C + (1 − α) C'←`` with ``α = max(alpha_min, 1/N)``, ``N = min(N← + 1, n_max)``.
With the defaults (``alpha_min = 0``, ``n_max = 256``) this is the running mean of every frame
that saw the same surface point, capped at 256 frames. ``last`` holds the diagnostics of the
latest frame: ``variance`` (H, W) of luminance (docs/methods/temporal.md §2), ``n`` (H, W) and ``status`` (H, W)
(0 reset, 1 bilinear, 2 fallback).

Non-finite policy: a non-finite colour pixel keeps its reprojected history; without history its
output stays non-finite (it is missing) and its history is empty, so nothing spreads.
Without motion vectors (a single image) every frame is treated as the first.

Input range: finite colour values beyond ±1e15 (:data:`dbench.methods.guards.RADIANCE_MAX`)
are clamped to ±1e15 (NaN/±Inf stay missing), so the float32 luminance moment l² stays finite
(before, a pixel above ~1.8e19 made l² Inf: the pixel lost its history and ``last["variance"]``
was Inf).

Parameters: alpha_min (0), n_max (256), tau_d (0.05), tau_n (0.9), taa (False) and taa_alpha (0.2)
(the temporal antialiasing the filters offer, :mod:`dbench.methods.temporal.taa`), backend ("auto"
(default): Numba; "numba": compiled
reprojection and the accumulation fused into one pass (:func:`.fast.accumulate_frame`); "torch":
vectorised PyTorch reprojection and accumulation (:func:`~dbench.methods.temporal.reproject_torch`,
:func:`~dbench.methods.temporal.accumulate_torch`) on CUDA when available, else on CPU;
"reference": readable NumPy). Every backend takes and returns NumPy at the method boundary and
keeps its history as NumPy (:class:`~dbench.methods.temporal.History`). ``params["backend"]`` holds
the resolved name after construction ("auto" becomes "numba"). On a GPU the harness runs
``denoise_device`` instead: two Triton kernels a frame with the history on the device
(:mod:`.device`, docs/gpu.md).

Example:
    >>> import numpy as np
    >>> from dbench.data import Frame
    >>> from dbench.registry import get
    >>> m = get("accumulate")
    >>> rng = np.random.default_rng(0)
    >>> g = dict(depth=np.ones((4, 4, 1)), normal=np.tile([0, 0, 1.0], (4, 4, 1)),
    ...          position=np.zeros((4, 4, 3)), motion=np.zeros((4, 4, 2)))
    >>> frames = [Frame(color=rng.random((4, 4, 3)), **g) for _ in range(5)]
    >>> m.reset(); out = [m.denoise(f) for f in frames][-1]
    >>> bool(np.allclose(out, np.mean([f.color for f in frames], 0), atol=1e-6))
    True
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ...errors import DbenchInputError
from ...denoiser import register
from .. import temporal as T
from . import fast as _fast


def _check_params(p: dict[str, Any]) -> None:
    if not 0.0 <= float(p["alpha_min"]) <= 1.0:
        raise DbenchInputError(f"alpha_min: expected a number in [0, 1], got {p['alpha_min']!r}")
    if not float(p["n_max"]) >= 1:
        raise DbenchInputError(f"n_max: expected a number >= 1, got {p['n_max']!r}")
    T.resolve_backend(p["backend"])  # validates: DbenchInputError naming ``backend``


@register("accumulate")
class Accumulate(T.HistoryDenoiser):
    """Reprojected temporal accumulation with luminance moments (docs/methods/temporal.md)."""

    kinds = {"sequence"}
    needs = {"color", "normal", "depth", "position", "motion"}
    defaults: dict[str, Any] = dict(alpha_min=0.0, n_max=T.N_MAX, tau_d=T.TAU_D, tau_n=T.TAU_N,
                                    taa=False, taa_alpha=T.TAA_ALPHA, backend="auto")
    #: ``denoise_device``: Triton kernels, the history kept on the device (:mod:`.device`).
    device_backend = "triton"

    def __init__(self, **params: Any) -> None:
        super().__init__(**params)
        _check_params(self.params)
        self._start()

    def reset(self) -> None:
        super().reset()
        if getattr(self, "_device_history", None) is not None:
            self._device_history.reset()

    def runs_on_device(self) -> bool:
        return self.params["backend"] != "reference"  # the readable form stays on the host

    def denoise_device(self, data):
        """One frame on a :class:`~dbench.device.DeviceFrame` (:func:`.device.accumulate_device`):
        an (H, W, 3) tensor on its device, equal to :meth:`denoise` within the tolerance of
        tests/methods/test_accumulate_device.py."""
        if not self.runs_on_device():
            raise DbenchInputError("backend: the device path runs Triton kernels; "
                                   "backend='reference' stays on the host")
        from .device import accumulate_device
        return accumulate_device(self, data)

    def _denoise(self, data, color: np.ndarray) -> np.ndarray:
        geo = T.frame_geometry(data)
        if self.backend == "numba" and _fast.numba is not None:
            hist, status = self.history.fetch(geo, 6)
            h, w = color.shape[:2]
            stored, out, variance = _fast.accumulate_frame(
                color, hist, status > 0, self.params["alpha_min"], self.params["n_max"],
                out_hist=self.history.staging(6, h, w))
            # finite by construction: colours are clamped to ±1e15, so l² ≤ 1e30 in float32
            self.history.store(geo, stored, valid=stored[5] > 0, finite=True)
            self.last = {"variance": variance, "n": stored[5], "status": status}
            return self._with_taa(out, geo.motion, status)
        c = T.to_planar(color)
        ok_s = T.sample_mask(c)
        c = np.where(ok_s, c, 0.0).astype(np.float32)
        hist, status = self.history.fetch(geo, 6)
        ok = status > 0
        sample = np.concatenate([c, T.moments(c)])
        # numba and reference share the NumPy accumulation here (one cheap fused expression)
        acc_backend = "torch" if self.backend == "torch" else "reference"
        acc, n, _ = T.accumulate_any(acc_backend, sample, hist[:5], hist[5], ok,
                                     self.params["alpha_min"], self.params["n_max"],
                                     sample_ok=ok_s)
        self.history.store(geo, np.concatenate([acc, n[None]]), valid=n > 0)
        self.last = {"variance": T.variance_from_moments(acc[3:5]), "n": n, "status": status}
        out = T.to_interleaved(acc[:3])
        empty = n <= 0
        if empty.any():
            out[empty] = color[empty]
        return self._with_taa(out, geo.motion, status)
