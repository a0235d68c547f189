"""``svgf`` and ``asvgf``: spatiotemporal variance-guided filtering (docs/methods/svgf.md).

Per frame (docs/methods/svgf.md §1): subtract the emission of the primary hits (``emission`` buffer, as Falcor's
SVGFPass does; 0 when absent), demodulate by albedo (§2; a_eff = clip(albedo, ``albedo_floor``, 1),
:data:`~dbench.methods.svgf.params.ALBEDO_FLOOR`, docs/temporal.md §12), reproject and accumulate
the illumination and its luminance moments (docs/methods/temporal.md), estimate the variance
(temporal where the history has ≥ 4 frames, else a 7×7 spatial estimate, §4), run K à-trous
iterations with normal, depth and luminance edge-stopping weights and variance propagation (§3, §5),
store the colour history (unfiltered, or the output of iteration ``feedback_tap``), remodulate and
add the accumulated emission back.

``svgf`` blends with α = max(α_min, 1/N) (α_min = 0.2 for colour and moments, the paper's).
``asvgf`` replaces α by the temporal-gradient rule of the seed (§6.1): per 3×3 stratum of the
previous frame, the brightest pixel is re-shaded with the previous frame's random numbers from
the current camera under the current lights (the frame's ``gradient`` buffer,
docs/temporal.md §2), ``G = (|L_new − L_prev| / max(L_new, L_prev))²``; G is filtered by 3
à-trous iterations without the luminance weight (``gradient_mode="seed"``;
``"filtered"`` instead filters δ = L_new − L_prev and Δ = max(L_new, L_prev) apart, as the
A-SVGF paper does, and takes G = (|δ̂| / Δ̂)²: less noise from re-shaded samples that diverge
from their first path under a moving camera, a later response to a light change;
``"filtered_abs"`` filters |δ| instead, which keeps the seed's response to a light change,
docs/temporal.md §14); G is fetched at full resolution through the motion vectors (the gather
form of the spec's forward projection — identical for a static camera), and
``N' = min(N(1 − G)^10 + 1, 256)``,
``α = mix(1/N', 1, G)``, floored at α_min with the dbench preset (``alpha_floor``; the A-SVGF
paper's α = (1 − λ)α₀ + λ and Q2RTX's max(α_min, 1/N) never go below a base α either).
``gradient_mode="paper"`` uses the original paper's λ = min(1, |δ̂|/Δ̂) and α = mix(0.2, 1, λ)
floored at 1/N'. :func:`.steps.gradient_history` is that step on its own (BMFR uses it, in
the seed's mode).

Presets (``get("svgf", **params)``; a preset fills in the values not given; docs/temporal.md §3
and results/temporal.md give the reasons and the study):

======================  =========================  =============  ==============
parameter               ``dbench`` (default)       ``paper``      ``falcor``
======================  =========================  =============  ==============
sigma_z, sigma_n        1, 128                     1, 128         1, 128
sigma_l                 4                          4              10
iterations              "auto" (1-5, by size)      5              4
feedback_tap            None (unfiltered history)  0              1
alpha_min (moments)     0.2 (0.2)                  0.2 (0.2)      0.05 (0.2)
variance_of             "mean"                     "sample"       "sample"
luminance_kernel        see below                  "laplacian"    "laplacian"
variance_boost          see below                  False          "svgf"
======================  =========================  =============  ==============

``luminance_kernel``: w_l = exp(−d²) ("gaussian", as Schied's A-SVGF code writes it) or exp(−d)
("laplacian", the SVGF paper's and Falcor's), d = |l_p − l_q| / (σ_l √(g(Var)) + ε); chosen on
sequences outside the catalogue by relMSE (docs/temporal.md §13, §15): the Gaussian for both.

``variance_boost``: a short history is filtered harder than its variance estimate says
(docs/temporal.md §15, :mod:`.boost`): "svgf" (``svgf``'s default) multiplies the 7×7 spatial
estimate of a history of N < 4 frames by 4/N, as Falcor's SVGF pass does; "asvgf" multiplies
the standard deviation by max(1, 8/N) for every pixel, as Schied's A-SVGF code does, N being
the history N' after the temporal gradient; "gradient" (``asvgf``'s default, §18) takes
Schied's boost where A-SVGF's gradient shortened the history and Falcor's on new surfaces
(without a gradient, for ``svgf``, it is "svgf"); False (the paper preset) none.

``variance_of="mean"``: the luminance weights use the variance of the accumulated colour — the
per-sample variance from the moments times Σw² of the blend weights (1/N for a running mean,
α/(2 − α) for the EMA) — the quantity that is filtered, as the variance propagation of §5
already assumes; ``"sample"`` is the paper's per-sample variance. Other parameters: eps_var
(1e-4), tau_d (0.05), tau_n (0.9), normal_buffer ("normal" |
"reflected_normal" | "geo_normal": the normal of the edge-stopping weight w_n in the spatial
variance and the à-trous passes — the shading normal, seed 001 §1.2.1's reflected normal of
glossy surfaces with roughness < 0.4, or the geometric normal; reprojection keeps the shading
normal; the last two read the frame's buffers of those names, which the sequence scenes' PSR
G-buffers provide), taa (False) and taa_alpha (0.2) [dbench] (the temporal antialiasing of
the output that BMFR's code runs, :mod:`dbench.methods.temporal.taa`), albedo_floor (0.2
[dbench]: a_eff = clip(albedo, floor, 1); 1 = no demodulation), backend ("auto" |
"numba" | "torch" | "reference"); asvgf adds gradient_iterations (3), gradient_mode
("seed" | "filtered" | "filtered_abs" | "paper"), n_max (256), alpha_floor (None: on with the
dbench preset).

Backends: "auto" (default) is "numba" (on a GPU the harness runs ``denoise_device``, the
Triton kernels of :mod:`.device`; docs/gpu.md);
"numba" compiled kernels; "torch" the vectorised PyTorch kernels of
:mod:`dbench.methods.svgf.torch_path` and :mod:`dbench.methods.temporal` (reprojection,
accumulation, demodulation, variance, à-trous, A-SVGF strata/gradient filter/adaptive history) on
CUDA when available, else on CPU — each kernel takes and returns NumPy, the history stays NumPy;
"reference" readable NumPy (float64). All agree within the tolerances of
tests/methods/test_svgf.py and test_asvgf.py. ``params["backend"]`` holds the resolved name.

``emission`` is optional (``optional_needs``: loaded whenever the scene has it; synthetic
sequences have none). Pixels on emitters (emission > 0) are neither taps nor filtered: their
output is their own accumulated value plus their accumulated emission. Without that, a visible
light is blurred into the surface around it, which no edge-stopping weight prevents under 1-spp
variance; and the emission is accumulated (like the colour) because a 1-spp primary sample sees
a lamp's edge in one frame and not in the next.

Non-finite policy: non-finite colour pixels are missing (history kept or empty; empty pixels are
no tap for their neighbours and are filled from them); non-finite albedo demodulates by 1;
non-finite G-buffers make a pixel "no hit" (it is only its own tap). The output is finite
wherever the input colour is finite.

Input range: finite ``color``, ``emission`` and ``gradient`` values beyond ±1e15
(:data:`dbench.methods.guards.RADIANCE_MAX`) are clamped to ±1e15 (NaN/±Inf stay missing).
The demodulated illumination is then ≤ 1e18 and its luminance moment l² ≤ 1e36 stays finite in
the float32 history, the spatial variance m₂ − m₁² and the à-trous variance propagation (before
the clamp, one pixel at 5e18 made l² Inf and every pixel of the first frame NaN).

``last`` holds diagnostics of the latest frame: ``n``, ``alpha``, ``variance``, ``status``
(reprojection), and for asvgf ``gradient`` (H, W).

Example:
    >>> import numpy as np
    >>> from dbench.data import Frame
    >>> from dbench.registry import get
    >>> g = dict(albedo=np.ones((8, 8, 3)), depth=np.ones((8, 8, 1)),
    ...          normal=np.tile([0, 0, 1.0], (8, 8, 1)), position=np.zeros((8, 8, 3)),
    ...          motion=np.zeros((8, 8, 2)))
    >>> m = get("svgf"); m.reset()
    >>> out = m.denoise(Frame(color=np.full((8, 8, 3), 0.5), **g))
    >>> bool(np.allclose(out, 0.5))
    True
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ...data import check_buffer
from ...errors import DbenchInputError
from ...denoiser import register
from .. import temporal as T
from . import boost as B
from . import dispatch as C
from .dispatch import (adaptive_history, atrous, depth_gradient, filter_gradients, prepare,
                       remodulate, spatial_variance, stratum_gradients)
from .numba_path import atrous_fast, fast_exp_neg, prepare_fast, spatial_variance_fast
from .params import (ALBEDO_FLOOR, EPS_VAR, GRADIENT_MODES, H1, MAX_ITERATIONS, LUM_KERNELS,
                     N_SPATIAL, PRESETS, VARIANCE_BOOSTS, VARIANCE_OF, auto_iterations)
from .reference import (asvgf_history, atrous_reference, gradient_at_pixels, gradient_value,
                        normal_weight, prepare_reference, spatial_variance_reference,
                        stratum_samples)
from .steps import accumulate_emission, emission_buffer, gradient_history


def _positive(name: str, value: Any, allow_zero: bool = False) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise DbenchInputError(f"{name}: expected a positive number, got {value!r}") from None
    if not np.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        raise DbenchInputError(f"{name}: expected a positive number, got {value!r}")
    return v


def _integer_in(value: Any, low: int, high: int) -> bool:
    return (isinstance(value, (int, np.integer)) and not isinstance(value, bool)
            and low <= value <= high)


class _SVGFBase(T.HistoryDenoiser):
    kinds = {"sequence"}
    needs = {"color", "albedo", "normal", "depth", "position", "motion"}
    # loaded whenever the scene has it: without it in the list the harness loaded emission only
    # when another method of the run needed it, so a result depended on its neighbours
    optional_needs = {"emission", "geo_normal", "reflected_normal"}
    defaults: dict[str, Any] = dict(preset="dbench", **PRESETS["dbench"], eps_var=EPS_VAR,
                                    tau_d=T.TAU_D, tau_n=T.TAU_N,
                                    normal_buffer="normal", taa=False, taa_alpha=T.TAA_ALPHA,
                                    albedo_floor=ALBEDO_FLOOR, backend="auto")
    #: per-method departures from :data:`~.params.PRESETS`, {preset: {key: value}}
    preset_overrides: dict[str, dict[str, Any]] = {}
    #: keep a history plane of the frames since each surface appeared (A-SVGF's "gradient"
    #: variance boost compares its N' with it); SVGF's N is that count already
    counts_frames = False
    #: ``denoise_device``: Triton kernels, the history kept on the device (:mod:`.device`).
    device_backend = "triton"

    def __init__(self, **params: Any) -> None:
        super().__init__(**params)
        preset = self.params["preset"]
        if preset not in PRESETS:
            raise DbenchInputError(f"preset: expected one of {tuple(PRESETS)}, got {preset!r}")
        for key, value in {**PRESETS[preset], **self.preset_overrides.get(preset, {})}.items():
            if key not in params:
                self.params[key] = value
        p = self.params
        for key in ("sigma_z", "sigma_n", "sigma_l", "eps_var"):
            _positive(key, p[key])
        for key in ("alpha_min", "alpha_min_moments"):
            if not 0.0 <= float(p[key]) <= 1.0:
                raise DbenchInputError(f"{key}: expected a number in [0, 1], got {p[key]!r}")
        if p["iterations"] != "auto" and not _integer_in(p["iterations"], 0, MAX_ITERATIONS):
            raise DbenchInputError(f"iterations: expected \"auto\" or an integer in "
                                   f"[0, {MAX_ITERATIONS}], got {p['iterations']!r}")
        if p["feedback_tap"] is not None and not _integer_in(p["feedback_tap"], 0, MAX_ITERATIONS):
            raise DbenchInputError(f"feedback_tap: expected None (no feedback) or an integer in "
                                   f"[0, {MAX_ITERATIONS}], got {p['feedback_tap']!r}")
        if p["luminance_kernel"] not in LUM_KERNELS:
            raise DbenchInputError(f"luminance_kernel: expected one of {LUM_KERNELS}, "
                                   f"got {p['luminance_kernel']!r}")
        if p["variance_boost"] is True:
            p["variance_boost"] = "svgf"
        boost = p["variance_boost"]  # 0 == False: compare by identity for the booleans
        if boost is not False and not (isinstance(boost, str) and boost in VARIANCE_BOOSTS):
            raise DbenchInputError(f"variance_boost: expected one of {VARIANCE_BOOSTS} (True is "
                                   f"\"svgf\"), got {p['variance_boost']!r}")
        if p["variance_of"] not in VARIANCE_OF:
            raise DbenchInputError(f"variance_of: expected one of {VARIANCE_OF}, "
                                   f"got {p['variance_of']!r}")
        if p["normal_buffer"] not in T.NORMAL_BUFFERS:
            raise DbenchInputError(f"normal_buffer: expected one of {T.NORMAL_BUFFERS}, "
                                   f"got {p['normal_buffer']!r}")
        # another normal buffer is needed, not optional: scenes without it are skipped
        self.needs = set(self.needs) | {p["normal_buffer"]}
        self._start()

    def reset(self) -> None:
        super().reset()
        if getattr(self, "_device_history", None) is not None:
            self._device_history.reset()

    def runs_on_device(self) -> bool:
        return self.params["backend"] != "reference"  # the readable form stays on the host

    def denoise_device(self, data):
        """One frame on a :class:`~dbench.device.DeviceFrame` (:func:`.device.svgf_device`): an
        (H, W, 3) tensor on its device, equal to :meth:`denoise` within the tolerances of
        tests/methods/test_svgf_device.py and test_asvgf_device.py."""
        if not self.runs_on_device():
            raise DbenchInputError("backend: the device path runs Triton kernels; "
                                   "backend='reference' stays on the host")
        from .device import svgf_device
        return svgf_device(self, data)

    # hook for A-SVGF: (n_hist_for_accumulate, alpha or None, extras)
    def _adaptive(self, data, geo, hist_n, ok, prep):
        return hist_n, None, {}

    def _after(self, geo, prep) -> None:
        pass

    def _denoise(self, data, color: np.ndarray) -> np.ndarray:
        p, be = self.params, self.backend
        h, w = color.shape[:2]
        albedo = check_buffer("albedo", getattr(data, "albedo", None), (h, w, 3))
        geo = T.frame_geometry(data, backend=be)
        emission = emission_buffer(data, h, w)
        prep = C.prepare(be, color, albedo, emission, geo.hit, p["albedo_floor"])
        present, emitter = prep["present"], prep["emitter"]

        # history: feedback colour (3), moments (2), N, Σ of squared blend weights, and the
        # emission (3) when the frame has an emission buffer (without one it is 0 everywhere:
        # nothing to reproject or accumulate; a change of the buffer's presence resets history)
        emissive = emission is not None
        counting = self.counts_frames  # A-SVGF's frame count (boost.py): one plane, the last
        planes = 7 + (3 if emissive else 0) + (1 if counting else 0)
        hist, status = self.history.fetch(geo, planes)
        ok = status > 0
        hist_n, alpha, extras = self._adaptive(data, geo, hist[5], ok, prep)
        n_max = getattr(self, "n_max", T.N_MAX)
        alpha_m = alpha
        if alpha is not None and p.get("alpha_floor", False):
            # A-SVGF's α never falls below SVGF's (the paper's α = (1 − λ)α₀ + λ, Q2RTX's
            # max(α_min, 1/N)); without the floor the seed's 1/N' grows a window of up to 256
            # frames that lags behind view-dependent shading (results/temporal.md)
            alpha, alpha_m = (np.maximum(alpha, np.float32(p["alpha_min"])),
                              np.maximum(alpha, np.float32(p["alpha_min_moments"])))
        # the compiled kernels write this frame's history planes in place into a reused array
        # (History.staging); the other backends' new arrays are gathered at the end
        fast = be == "numba"
        stage = self.history.staging(planes, h, w) if fast else None
        acc_c, n, a_used = T.accumulate_any(be, prep["illum"], hist[:3], hist_n, ok,
                                            p["alpha_min"], n_max, alpha, present,
                                            out=(None, stage[5]) if fast else None)
        acc_m, _, _ = T.accumulate_any(be, prep["moments"], hist[3:5], hist_n, ok,
                                       p["alpha_min_moments"], n_max, alpha_m, present,
                                       out=(stage[3:5], None) if fast else None)
        # the emission of 1-spp primary hits is exact but aliased (a jittered sample sees the
        # lamp or not): accumulated with the colour's α it converges to the pixel's coverage,
        # as TAA would; adding the raw sample back made every lamp edge flicker
        acc_e = (accumulate_emission(be, prep, hist[7:10], hist_n, ok, p["alpha_min"], n_max,
                                     alpha, present, out=stage[7:10] if fast else None)
                 if emissive else prep["emission"])
        filled = n > 0
        frames = B.frame_count(hist[-1], ok, present, n_max) if counting else None
        shortened = B.shortened_by_gradient(n, frames)

        gx, gy = C.depth_gradient(geo.depth, geo.hit, backend=be)
        w_normal = T.feature_normal(data, geo, p["normal_buffer"],
                                    f"normal_buffer={p['normal_buffer']!r}")
        gather = geo.hit & ~emitter
        tap = gather & filled
        var = T.variance_from_moments(acc_m)
        # Σ w² of the accumulation weights: the variance of the accumulated mean is the
        # per-sample variance times this (1/N for a running mean, α/(2 − α) in the EMA limit)
        weight_sq = np.where(ok, a_used * a_used + (1.0 - a_used) ** 2 * hist[6],
                             1.0).astype(np.float32)
        of_mean = p["variance_of"] == "mean"
        if of_mean:
            var = (var * weight_sq).astype(np.float32)
        spatial = filled & (n < N_SPATIAL)
        if spatial.any():
            sv = C.spatial_variance(be, acc_m, geo.depth, gx, gy, w_normal, tap,
                                    gather, spatial, sigma_z=p["sigma_z"], sigma_n=p["sigma_n"])
            sv = B.boost_spatial(p["variance_boost"], sv, n, shortened)
            if of_mean:
                sv = sv * weight_sq
            var = np.where(spatial, sv, var).astype(np.float32)
        var = B.boost_all(p["variance_boost"], var, n, filled, shortened)

        cur, feedback = acc_c, acc_c
        iterations = (auto_iterations(h, w) if p["iterations"] == "auto"
                      else int(p["iterations"]))
        for i in range(iterations):
            cur, var = C.atrous(be, cur, var, geo.depth, gx, gy, w_normal, tap,
                                filled, gather, 2 ** i, sigma_z=p["sigma_z"],
                                sigma_n=p["sigma_n"], sigma_l=p["sigma_l"], eps_var=p["eps_var"],
                                lum_kernel=p["luminance_kernel"])
            if i == p["feedback_tap"]:
                feedback = cur
        if fast:
            stage[0:3] = feedback
            stage[6] = weight_sq
            if counting:
                stage[-1] = frames
        else:
            stage = np.concatenate([feedback, acc_m, n[None], weight_sq[None]]
                                   + ([acc_e] if emissive else [])
                                   + ([frames[None]] if counting else []))
        self.history.store(geo, stage, valid=filled, finite=True)
        self._after(geo, prep)
        self.last = {"n": n, "alpha": a_used, "variance": var, "status": status,
                     "frames": frames, "shortened": shortened,
                     "iterations": iterations, "weight_sq": weight_sq, **extras}
        out = C.remodulate(cur, prep["a_eff"], acc_e, be)
        return self._with_taa(out, geo.motion, status)


@register("svgf")
class SVGF(_SVGFBase):
    """Spatiotemporal variance-guided filtering (Schied et al. 2017; docs/methods/svgf.md)."""


@register("asvgf")
class ASVGF(_SVGFBase):
    """A-SVGF: SVGF with temporal-gradient-driven history (docs/methods/svgf.md §6)."""

    needs = _SVGFBase.needs | {"gradient"}
    defaults: dict[str, Any] = dict(_SVGFBase.defaults, gradient_iterations=3,
                                    gradient_mode="seed", n_max=T.N_MAX, alpha_floor=None)
    # Schied's A-SVGF code: its variance boost (std × max(1, 8/N)) and, with it, its Gaussian
    # luminance weight; on the training sequences outside the catalogue (4 seeds) A-SVGF's
    # geometric-mean relMSE ÷ accumulation 0.565 (Laplacian, no boost) → 0.473 (docs/temporal.md
    # §15); with Falcor's boost the Laplacian was still better (0.525 against 0.543). Schied's
    # boost only where the gradient shortened the history, Falcor's on new surfaces
    # ("gradient", §18): the same there (0.472), t_rmse on orbit tied with SVGF's.
    # The seed's gradient stays: "filtered" was better there (§14) but follows flicker's light
    # switch later (RMSE at 128², 4 spp, 0.0432 → 0.0480); "filtered_abs" does not, but misses
    # mirror-pan's moving reflections (RMSE over surfaces 0.152 → 0.161 at 128², 1 spp)
    preset_overrides = {"dbench": {"variance_boost": "gradient"}}

    def __init__(self, **params: Any) -> None:
        super().__init__(**params)
        if self.params["gradient_mode"] not in GRADIENT_MODES:
            raise DbenchInputError(f"gradient_mode: expected one of {GRADIENT_MODES}, "
                                   f"got {self.params['gradient_mode']!r}")
        self.n_max = _positive("n_max", self.params["n_max"])
        # as many à-trous passes as the colour's at most: a step of 2^12 px already passes
        # any image, and a larger count overflowed the step's integer inside the kernel
        if not _integer_in(self.params["gradient_iterations"], 0, MAX_ITERATIONS):
            raise DbenchInputError(f"gradient_iterations: expected an integer in "
                                   f"[0, {MAX_ITERATIONS}], got "
                                   f"{self.params['gradient_iterations']!r}")
        if self.params["alpha_floor"] is None:  # on with the dbench preset, off with the others
            self.params["alpha_floor"] = self.params["preset"] == "dbench"
        if not isinstance(self.params["alpha_floor"], bool):
            raise DbenchInputError(f"alpha_floor: expected True or False, "
                                   f"got {self.params['alpha_floor']!r}")
        self._prev_lum: np.ndarray | None = None

    @property
    def counts_frames(self) -> bool:  # the "gradient" boost compares N' with the frame count
        return self.params["variance_boost"] == "gradient"

    def reset(self) -> None:
        super().reset()
        self._prev_lum = None

    def _adaptive(self, data, geo, hist_n, ok, prep):
        p = self.params
        g_img, n_new, alpha = gradient_history(
            data, geo, self.history.prev, self._prev_lum, hist_n, self.n_max,
            int(p["gradient_iterations"]), p["gradient_mode"], p["sigma_z"], p["sigma_n"],
            self.backend)
        # accumulate() computes N = min(N_hist + 1, n_max): hand it N' − 1.
        return n_new - np.float32(1.0), alpha, {"gradient": g_img}

    def _after(self, geo, prep) -> None:
        self._prev_lum = prep["lum_raw"]


__all__ = ["SVGF", "ASVGF", "H1", "gradient_history", "PRESETS", "adaptive_history",
           "asvgf_history", "atrous", "atrous_fast", "atrous_reference", "depth_gradient",
           "fast_exp_neg", "filter_gradients", "gradient_at_pixels", "gradient_value",
           "normal_weight", "prepare", "prepare_fast", "prepare_reference", "remodulate",
           "spatial_variance", "spatial_variance_fast", "spatial_variance_reference",
           "stratum_gradients", "stratum_samples"]
