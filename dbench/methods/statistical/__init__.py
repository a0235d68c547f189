"""``statistical``: the Welch-test statistical denoiser (docs/methods/statistical.md, Sakai et
al. 2024).

The joint bilateral filter of ``jbf`` (shared code) gives the base weights ρ; a neighbour is a
member only if every colour channel passes Welch's test on the skew-corrected means θ̂ of the
transformed samples (Frame.stats); the normalised weights are applied to the linear noisy
colour (Frame.color). See :mod:`dbench.methods.statistical.reference` for the maths and the
policies (non-finite pixels, zero variance, out-of-image neighbours).

Files: ``params.py`` (defaults, constants and the test's threshold γ_t), ``reference.py`` (the
Welch test and the readable NumPy filter), ``fast.py`` (the filter on the JBF's shared Numba and
PyTorch kernels), ``dispatch.py`` (:func:`statistical_filter`: one image on the chosen backend),
``device.py`` (the device path of images); for videos ``transient.py`` (the spatio-temporal
filter), ``transient_inputs.py`` (its per-voxel statistics), ``shrink.py`` (the
centre-versus-neighbourhood shrinkage and the pixel-total rule) and ``transient_device.py``
(the device path of videos).
Transient videos (docs/methods/statistical.md §11.3): given a :class:`~dbench.data.TransientFrame`,
the same method runs the spatio-temporal denoiser of :mod:`dbench.methods.statistical.transient`: a
(2r_s+1)² × (2r_t+1) voxel window, the JBF replicated along time (or a plain 3D Gaussian for
participating media) as base filter, the Welch test per voxel pair on the per-bin statistics, and
empty bins skipped (they cost nothing and return 0).

Parameters (``get("statistical", **params)``; every value is checked, a bad one raises
DbenchInputError naming it; the resolved values land in ``last_settings`` after each call):
    radius (None: 20 for images [docs/methods/statistical.md §7], 5 for videos [docs/methods/statistical.md §7, §11.3]; an integer applies to
    both), alpha / gamma (both None: α = 0.005 for images [docs/methods/statistical.md §5.1 steady default], γ = 0.1
    for videos [the upper end of docs/methods/statistical.md §5.1's transient range 0.05-0.1, measured best on every
    rendered scene: results/transient_statistical.md §6]; γ_t = t_{1−α/2, n_i+n_j−2} from alpha,
    γ_t² = 1/(2γ) − 1 from gamma, which wins when both are given), sigma ((10, 10, 0.02 ×3,
    0.1 ×3)), sigma_convention ("variance" | "sd"), window ("square" | "disk"), backend ("auto":
    Numba; on a GPU the harness runs ``denoise_device``, docs/gpu.md | "numba" | "torch"
    (images only) | "reference"), hit_mask (True), membership (True; False = plain base filter, the ablation).
    The ProDen gate of docs/methods/statistical.md §12 is ``statistical+gate`` (:mod:`dbench.methods.gate`, which
    wraps any steady method; ``statistical-gate`` is the old name of the same method).
    Videos only (docs/methods/statistical.md §11.3, docs/methods/jbf.md §1.4): radius_t ("auto": follows the bin width,
    min(3, ⌊20 mm / bin width⌋) from the frame's ``meta["bin_width_opl"]`` in metres, 1 when
    the frame has no window in metres;
    :func:`~dbench.methods.statistical.transient.auto_radius_t` | an integer), base ("auto":
    "jbf" when the frame has albedo and normal, media included (measured better than the
    seed's 3D Gaussian on dbench's media scenes), else "gauss3d" | "jbf" | "gauss3d"),
    temporal_profile (None: "box" for the jbf base, "gaussian" for gauss3d | "box" |
    "gaussian"), sigma_t (1.0 bin), skip_empty (True), shrink (True: the
    centre-versus-neighbourhood shrinkage of :mod:`dbench.methods.statistical.shrink`; False:
    the seed's normalised sum), mass (True: each pixel's time integral shrunk towards the noisy
    total by its own variance, ``TransientFrame.total_var``; skipped, and recorded in
    ``last_settings``, when the frame has none). The seed's rule is ``shrink=False,
    mass=False, gamma=0.05, radius_t=1``.
On images every buffer of ``needs`` (color, albedo, normal, stats) must be present: a
missing one raises DbenchInputError naming it. ``depth`` is optional: it feeds the JBF's hit
mask, and without it pixels with an all-zero normal count as background
(:func:`~dbench.methods.guards.depth_or_hit`). Videos keep their documented G-buffer-free
fallback (media have no albedo/normal/depth).
The sample transform (identity / Box-Cox / Yeo-Johnson and λ) is a property of the statistics
(SampleStats.transform, .lam) and is recorded, not chosen here; transient datasets default to
identity (docs/methods/statistical.md §3, §11.3: identity or Yeo-Johnson; Box-Cox distorts near-zero bins).

Example:
    >>> import numpy as np
    >>> from dbench.data import Frame, SampleStats
    >>> from dbench.registry import get
    >>> h = w = 8; ones = np.ones((h, w, 3), np.float32)
    >>> st = SampleStats(n=np.full((h, w, 3), 16.0), mean=np.ones((h, w, 3)),
    ...                  var_mean=np.zeros((h, w, 3)), m3=np.zeros((h, w, 3)), transform="identity")
    >>> f = Frame(color=ones, albedo=ones, normal=ones, depth=ones[..., :1], stats=st)
    >>> m = get("statistical", radius=2, backend="numba")
    >>> bool(np.allclose(m.denoise(f), 1.0)), m.last_settings["nu"]
    (True, 30)
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ...errors import DbenchInputError
from ...denoiser import Denoiser, register
from ..guards import depth_or_hit, require_buffers
from ..checks import check_choice, check_positive, check_radius
from ..kernels.bilateral.guide import check_sigma, make_guide
from ..kernels.bilateral.params import SEED_SIGMA, SIGMA_CONVENTIONS, TEMPORAL_PROFILES, WINDOWS
from ..kernels.gate_reference import proden_gate, proden_gate_factor
from ..kernels.variance_floor import linear_variance
from .dispatch import statistical_filter
from .fast import statistical_fast
from .params import (BACKENDS, DEFAULT_ALPHA, STEADY_RADIUS, Threshold, check_alpha,
                     g2_from_gamma, gamma_from_gamma_t, gamma_t_from_gamma, resolve_threshold,
                     student_gamma_t)
from .reference import (StatPlanes, membership, stat_planes, statistical_reference, welch_pass,
                        welch_t, welch_t_from_weight, welch_weight)
from .shrink import mass_shrink
from .transient import (BASES, VIDEO_RADIUS, auto_radius_t, statistical_filter_video,
                        statistical_video_fast,
                        statistical_video_reference)

__all__ = ["Statistical", "StatPlanes", "Threshold", "gamma_from_gamma_t", "gamma_t_from_gamma",
           "linear_variance", "membership", "proden_gate", "proden_gate_factor",
           "resolve_threshold", "stat_planes", "statistical_fast", "statistical_filter",
           "statistical_filter_video", "statistical_video_fast", "statistical_video_reference",
           "statistical_reference", "student_gamma_t", "welch_pass", "welch_t",
           "welch_t_from_weight", "welch_weight"]


@register("statistical")
class Statistical(Denoiser):
    """Welch-test statistical denoiser with the JBF as base filter (docs/methods/statistical.md), on
    images (§1-§8) and on transient videos (§11.3)."""

    kinds = {"steady", "transient"}
    needs = {"color", "albedo", "normal", "stats"}
    #: ``emitter``: lights seen directly get their own label in the base filter's guide, as in
    #: ``jbf`` (docs/methods/jbf.md §1.3), so ``membership=False`` is ``jbf`` (§7)
    optional_needs = {"depth", "emitter"}
    defaults: dict[str, Any] = dict(
        radius=None, alpha=None, gamma=None, sigma=SEED_SIGMA,
        sigma_convention="variance", window="square", backend="auto", hit_mask=True,
        membership=True, radius_t="auto", base="auto",
        temporal_profile=None, sigma_t=1.0, skip_empty=True, shrink=True, mass=True)
    #: ``denoise_device``: the Welch-tested window as one Triton kernel, over space for steady
    #: images (:mod:`.device`), over space and time bins for transient videos
    #: (:mod:`.transient_device`).
    device_backend = "triton"

    def __init__(self, **params: Any) -> None:
        super().__init__(**params)
        p = self.params
        if p["radius"] is not None:
            check_radius(p["radius"])
        if p["radius_t"] != "auto":
            try:
                check_radius(p["radius_t"], "radius_t")
            except DbenchInputError:  # the same check, with "auto" among the choices
                raise DbenchInputError(f"radius_t: expected 'auto' or an integer ≥ 0, got "
                                       f"{p['radius_t']!r}") from None
        if p["alpha"] is not None:
            check_alpha(p["alpha"])
        if p["gamma"] is not None:
            g2_from_gamma(p["gamma"])
        check_sigma(p["sigma"])
        check_choice("sigma_convention", p["sigma_convention"], SIGMA_CONVENTIONS)
        check_choice("window", p["window"], WINDOWS)
        check_choice("backend", p["backend"], BACKENDS)
        check_choice("base", p["base"], ("auto",) + BASES)
        if p["temporal_profile"] is not None:
            check_choice("temporal_profile", p["temporal_profile"], TEMPORAL_PROFILES)
        check_positive("sigma_t", p["sigma_t"], allow_inf=True)
        for name in ("hit_mask", "membership", "skip_empty", "shrink", "mass"):
            if not isinstance(p[name], (bool, np.bool_)):
                raise DbenchInputError(f"{name}: expected True or False, got {p[name]!r}")
        #: Resolved settings of the last call: γ_t, ν, transform, λ, backend, base filter.
        self.last_settings: dict[str, Any] = {}

    def runs_on_device(self) -> bool:
        # images and videos on a compiled backend; the readable reference stays on the host
        return self.params["backend"] != "reference"

    def denoise_device(self, data: Any):
        """A steady :class:`~dbench.device.DeviceFrame` (:func:`.device.statistical_device`) or
        a transient one (:func:`.transient_device.statistical_video_device`, then the
        pixel-total rule on the device), equal to :meth:`denoise` within float32 rounding of
        the weights (tests/methods/test_gpu_bilateral.py,
        tests/methods/test_statistical_transient_device.py)."""
        kind = getattr(data, "kind", None)
        if kind not in ("steady", "transient"):
            raise DbenchInputError("statistical: the device path takes steady or transient "
                                   f"frames; got {kind or type(data).__name__} data")
        if not self.runs_on_device():
            raise DbenchInputError("statistical: backend='reference' runs on the host only")
        if kind == "transient":
            return self._denoise_video_device(data)
        require_buffers(self, data)
        from .device import statistical_device
        p = self.params
        alpha = p["alpha"] if (p["alpha"] is not None or p["gamma"] is not None) else DEFAULT_ALPHA
        opts = {k: p[k] for k in ("sigma", "sigma_convention", "window", "hit_mask")}
        out, info = statistical_device(
            data, radius=STEADY_RADIUS if p["radius"] is None else p["radius"], alpha=alpha,
            gamma=p["gamma"], guide_options=opts, membership_on=p["membership"])
        self.last_settings = info
        return out

    def denoise(self, data: Any) -> np.ndarray:
        kind = getattr(data, "kind", None)
        if kind == "transient":
            return self._denoise_video(data)
        if kind != "steady":
            raise DbenchInputError(f"statistical: expected a steady Frame or a TransientFrame, "
                                   f"got {getattr(data, 'kind', type(data).__name__)} data")
        require_buffers(self, data)  # images: every buffer of ``needs``
        p = self.params
        alpha = p["alpha"] if (p["alpha"] is not None or p["gamma"] is not None) else DEFAULT_ALPHA
        radius = STEADY_RADIUS if p["radius"] is None else p["radius"]
        out, info = statistical_filter(
            data.color, data.stats, data.albedo, data.normal, depth_or_hit(data),
            radius=radius, alpha=alpha, gamma=p["gamma"], sigma=p["sigma"],
            sigma_convention=p["sigma_convention"], window=p["window"], hit_mask=p["hit_mask"],
            membership_on=p["membership"], backend=p["backend"], return_info=True,
            emitter=getattr(data, "emitter", None))
        self.last_settings = info
        return out

    def _video_radii(self, data: Any) -> tuple[int, int, float | None]:
        """(r_s, r_t, bin width in metres or None) of a video (docs/methods/statistical.md §7, §11.3)."""
        p = self.params
        if p["backend"] == "torch":
            raise DbenchInputError("backend: 'torch' is not available for transient videos; "
                                   "use 'auto', 'numba' or 'reference'")
        radius = VIDEO_RADIUS if p["radius"] is None else p["radius"]
        meta = getattr(data, "meta", None) or {}
        # a bin width in metres of path (rendered or declared); a frame without a window has
        # the placeholder width 1 in units of "bins", which says nothing about the signal
        width_m = (meta.get("bin_width_opl") if str(meta.get("units", "")).startswith("m")
                   else None)
        radius_t = auto_radius_t(width_m) if p["radius_t"] == "auto" else p["radius_t"]
        return radius, radius_t, width_m

    def _denoise_video_device(self, data: Any):
        """:meth:`_denoise_video` on a transient DeviceFrame: the filter and the pixel-total
        rule as tensor operations and one Triton launch; ``mass_beta_mean`` is then a 0-d
        tensor on the device (reading it inside the call would wait for the device)."""
        from .transient_device import mass_shrink_device, statistical_video_device
        p = self.params
        radius, radius_t, width_m = self._video_radii(data)
        opts = {k: p[k] for k in ("sigma", "sigma_convention", "window", "hit_mask")}
        out, info = statistical_video_device(
            data, radius=radius, radius_t=radius_t, alpha=p["alpha"], gamma=p["gamma"],
            base=p["base"], temporal_profile=p["temporal_profile"], sigma_t=p["sigma_t"],
            guide_options=opts, membership_on=p["membership"], skip_empty=p["skip_empty"],
            shrink=p["shrink"])
        info.update(kind="transient", mass="off",
                    radius_t_source=("auto" if p["radius_t"] == "auto" else "given"),
                    bin_width_m=width_m)
        if p["mass"] and p["membership"]:
            if data.total_var is None:
                info["mass"] = "skipped: the frame has no total_var"
            else:
                h, w = data.shape
                out, beta = mass_shrink_device(out, data.color, data.total_var, h, w)
                info.update(mass="on", mass_beta_mean=beta.mean())
        self.last_settings = info
        return out

    def _denoise_video(self, data: Any) -> np.ndarray:
        """Spatio-temporal denoiser on a TransientFrame (docs/methods/statistical.md §11.3)."""
        p = self.params
        radius, radius_t, width_m = self._video_radii(data)
        backend = "reference" if p["backend"] == "reference" else "numba"
        out, info = statistical_filter_video(
            data.color, data.stats, data.albedo, data.normal, getattr(data, "depth", None),
            radius=radius, radius_t=radius_t, alpha=p["alpha"], gamma=p["gamma"],
            base=p["base"], temporal_profile=p["temporal_profile"], sigma_t=p["sigma_t"],
            sigma=p["sigma"], sigma_convention=p["sigma_convention"], window=p["window"],
            hit_mask=p["hit_mask"], membership_on=p["membership"], skip_empty=p["skip_empty"],
            shrink=p["shrink"], backend=backend, return_info=True)
        total_var = getattr(data, "total_var", None)
        info.update(kind="transient", mass="off",
                    radius_t_source=("auto" if p["radius_t"] == "auto" else "given"),
                    bin_width_m=width_m)
        if p["mass"] and p["membership"]:
            if total_var is None:
                info["mass"] = "skipped: the frame has no total_var"
            else:
                out, beta = mass_shrink(out, data.color, total_var)
                info.update(mass="on", mass_beta_mean=float(np.mean(beta)))
        self.last_settings = info
        return out
