"""``jbf``: joint (cross) bilateral filter on noise-free G-buffers (docs/methods/jbf.md).

Two modes of one method:

* ``mode="jbf"`` (default): ρ_ij = exp(−½ Σ_k (p_j,k − p_i,k)² Σ⁻¹_kk) over pixel position,
  albedo and normal (optionally position/depth), hit mask, no colour term, normalised per pixel
  (docs/methods/jbf.md §1). It is also the base filter of ``statistical``.
* ``mode="illumination"``: the seed-002 "effective illumination" filter as a post-process
  (docs/methods/jbf.md §2.2, simplified): demodulate by albedo, filter with C·exp(−α|o|²)·exp(−β(1−n·n'))
  ·H(n·n') so that the self-weight stays ≥ ``self_weight_min``, remodulate. There is no
  direct/indirect split (the whole colour is filtered); the BDF-lobe factor and ``lobe_key``
  are not implemented.

Every buffer of ``needs`` (color, albedo, normal) must be present: a missing one raises
DbenchInputError naming it (the filter does not silently drop a feature). Optional buffers:
``depth`` (the hit mask; without it, pixels with an all-zero normal count as background,
:func:`~dbench.methods.guards.depth_or_hit`; a ``features`` entry "depth" still requires it),
``position`` (required when ``features`` or ``use_position`` asks for it) and ``emitter``
(lights seen directly or in smooth mirrors form their own label and never mix with the
surfaces around them, so a light's albedo, black in the catalogue and anything in other
renderers' files, does not matter).

Huge finite colour (up to the float32 maximum, or its demodulated value in illumination mode)
stays finite: a plane above 1e30 is divided by an exact power of two before the float32 window
sums and multiplied back in float64
(:func:`~dbench.methods.kernels.bilateral.numba2d.accumulate`); ordinary inputs are untouched.

Non-finite colour pixels are missing (no weight as neighbours; their own output is the filtered
value of valid neighbours, or 0); pixels with non-finite G-buffers are isolated
(:mod:`dbench.methods.kernels.bilateral`).

Parameters (``get("jbf", **params)``; every value is checked, a bad one raises
DbenchInputError naming it):
    radius (20), sigma ((10, 10, 0.02 ×3, 0.1 ×3)), sigma_convention ("variance" | "sd"),
    window ("square" | "disk"), features (("xy", "albedo", "normal"), optional "position",
    "depth"), sigma_position (0.01), sigma_depth (0.01), hit_mask (True),
    preset (None | "seed" | "statmc": fills sigma_convention/window/radius unless given),
    mode ("jbf" | "illumination"), alpha (0.005 px⁻²), beta (10), self_weight_min (0.5),
    eps_albedo (1e-3), use_position (False), sigma_P (0.05), backend ("numba" | "torch" |
    "auto" | "reference").

Example:
    >>> import numpy as np
    >>> from dbench.data import Frame
    >>> from dbench.registry import get
    >>> f = Frame(color=np.ones((8, 8, 3), np.float32), albedo=np.ones((8, 8, 3), np.float32),
    ...           normal=np.ones((8, 8, 3), np.float32), depth=np.ones((8, 8, 1), np.float32))
    >>> out = get("jbf", radius=2).denoise(f)
    >>> bool(np.allclose(out, 1.0))
    True
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ...errors import DbenchInputError
from ...denoiser import Denoiser, register
from ..checks import check_choice, check_features, check_positive, check_radius
from ..guards import depth_or_hit, require_buffers
from ..kernels.bilateral.guide import Guide, check_sigma, make_guide, window_offsets
from ..kernels.bilateral.numba2d import accumulate
from ..kernels.bilateral.reference import reference_weights
from ..kernels.bilateral.torch_path import accumulate_torch
from .fast import jbf_fast, joint_bilateral_filter, resolve_backend
from .illumination import (IlluminationSetup, illumination_fast, illumination_filter,
                           illumination_reference, make_illumination_setup)
from .params import (BACKENDS, FEATURES, GUIDE_OPTIONS, MODES, PRESETS, SEED_SIGMA,
                     SIGMA_CONVENTIONS, WINDOWS)
from .reference import jbf_reference

__all__ = ["JBF", "Guide", "IlluminationSetup", "SEED_SIGMA", "PRESETS", "accumulate",
           "accumulate_torch", "illumination_fast", "illumination_filter",
           "illumination_reference", "jbf_fast", "jbf_reference", "joint_bilateral_filter",
           "make_guide", "make_illumination_setup", "reference_weights", "window_offsets"]


@register("jbf")
class JBF(Denoiser):
    """Joint bilateral filter (docs/methods/jbf.md §1) and the seed-002 illumination filter (§2.2)."""

    kinds = {"steady"}
    needs = {"color", "albedo", "normal"}
    optional_needs = {"depth", "position", "emitter"}
    defaults: dict[str, Any] = dict(
        radius=20, sigma=SEED_SIGMA, sigma_convention="variance", window="square",
        features=("xy", "albedo", "normal"), sigma_position=0.01, sigma_depth=0.01,
        hit_mask=True, preset=None, mode="jbf", alpha=0.005, beta=10.0, self_weight_min=0.5,
        eps_albedo=1e-3, use_position=False, sigma_P=0.05, backend="numba")
    #: ``denoise_device``: the window as one Triton kernel (:mod:`.device`), ``jbf`` mode.
    device_backend = "triton"

    def __init__(self, **params: Any) -> None:
        super().__init__(**params)
        preset = self.params["preset"]
        if preset is not None:
            check_choice("preset", preset, tuple(PRESETS))
            for key, value in PRESETS[preset].items():
                if key not in params:
                    self.params[key] = value
        p = self.params
        check_choice("mode", p["mode"], MODES)
        check_choice("backend", p["backend"], BACKENDS)
        check_radius(p["radius"])
        check_sigma(p["sigma"])
        check_choice("sigma_convention", p["sigma_convention"], SIGMA_CONVENTIONS)
        check_choice("window", p["window"], WINDOWS)
        check_features(p["features"], FEATURES)
        for name in ("sigma_position", "sigma_depth", "sigma_P"):
            check_positive(name, p[name], allow_inf=True)
        for name in ("alpha", "beta", "eps_albedo"):
            check_positive(name, p[name], allow_zero=True)
        swm = check_positive("self_weight_min", p["self_weight_min"], allow_zero=True)
        if swm > 1:
            raise DbenchInputError(f"self_weight_min: expected a number in [0, 1], got {swm!r}")
        #: Resolved settings of the last call (e.g. the illumination constant C), for reports.
        self.last_settings: dict[str, Any] = {}

    def runs_on_device(self) -> bool:
        # the illumination mode and the readable reference stay on the host
        return self.params["mode"] == "jbf" and self.params["backend"] != "reference"

    def denoise_device(self, data: Any):
        """The ``jbf`` mode on a :class:`~dbench.device.DeviceFrame` (:func:`.device.jbf_device`);
        equal to :meth:`denoise` within float32 rounding (tests/methods/test_gpu_bilateral.py)."""
        if not self.runs_on_device():
            raise DbenchInputError("jbf: the device path covers mode='jbf' with a compiled "
                                   f"backend; got mode={self.params['mode']!r}, "
                                   f"backend={self.params['backend']!r}")
        require_buffers(self, data)
        from .device import jbf_device
        if "depth" in self.params["features"] and data.depth is None:
            require_buffers(self, data, ["depth"])
        out, settings = jbf_device(data, self.params)
        self.last_settings = dict(settings, backend="triton")
        return out

    def denoise(self, data: Any) -> np.ndarray:
        if getattr(data, "kind", None) != "steady":
            raise DbenchInputError(f"jbf: expected a steady Frame, got "
                                   f"{getattr(data, 'kind', type(data).__name__)} data")
        require_buffers(self, data)  # every buffer of ``needs``
        p = self.params
        depth = depth_or_hit(data)
        if p["mode"] == "illumination":
            opts = {k: p[k] for k in ("radius", "window", "alpha", "beta", "self_weight_min",
                                      "eps_albedo", "use_position", "sigma_P", "hit_mask")}
            setup = make_illumination_setup(data.albedo, data.normal, depth, data.position,
                                            shape=data.shape, **opts)
            self.last_settings = dict(mode="illumination", **setup.settings)
            if p["backend"] == "reference":
                return illumination_reference(data.color, setup).astype(np.float32)
            return illumination_fast(data.color, setup)
        opts = {k: p[k] for k in GUIDE_OPTIONS}
        if "depth" in opts["features"] and data.depth is None:
            require_buffers(self, data, ["depth"])
        guide = make_guide(data.albedo, data.normal, depth, data.position,
                           shape=data.shape, emitter=getattr(data, "emitter", None), **opts)
        self.last_settings = dict(mode="jbf", **guide.settings)
        backend = p["backend"]
        if backend == "auto":
            backend = resolve_backend("auto")
        self.last_settings["backend"] = backend
        if backend == "reference":
            return jbf_reference(data.color, guide).astype(np.float32)
        return jbf_fast(data.color, guide, backend=backend)
