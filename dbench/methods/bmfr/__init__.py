"""``bmfr``: blockwise multi-order feature regression (Koskela et al. 2019; docs/methods/bmfr.md).

Per frame (docs/methods/bmfr.md §1; the demodulation and emission steps are SVGF's,
:func:`dbench.methods.svgf.dispatch.prepare` and :mod:`dbench.methods.svgf.steps`): subtract the
primary hits' emission (``emission`` buffer when present, as for SVGF) and demodulate by albedo (a_eff = clip(albedo, ``albedo_floor``, 1), the rule of
:data:`dbench.methods.svgf.params.ALBEDO_FLOOR`; by default ``albedo_floor`` = 1, no
demodulation, :data:`~dbench.methods.bmfr.params.ALBEDO_FLOOR_BMFR`); accumulation 1 of the
noisy illumination Z with α1 = max(1/N, 0.2); a block grid (B = 32) with this frame's offset
(16 offsets cycling, the first (0, 0)); per block a least-squares fit of Z' on the features
[1, n, P, P²] (positions scaled per block, §2.1) with U(−0.01, 0.01) noise on every feature
column but the constant (stochastic regularisation, §4), solved by batched Householder QR
without Q with R shared by the three channels (§5, :func:`householder_lstsq`); reconstruction
with the noise-free features, negatives clamped to 0; accumulation 2 of the fit with
α2 = max(1/N, 0.1); remodulation, with the emission accumulated like Z.

Residual hand-back (``handback="signed"``, default; [dbench], docs/temporal.md §9, §17,
:mod:`dbench.methods.bmfr.handback`): before accumulation 2 the fit y gets back the part of Z' −
y that is not noise — its 7×7 local mean, and the rest in proportion to its window energy beyond
the variance of Z' (accumulated per channel from Z² and the blend weights, spatial below 4
effective samples), clamped at 0 like the fit (``clamp_negative``); below the fit also in
proportion to each pixel's residual beyond its own variance (``"wiener"``: without that). A
block fit cannot follow a contact shadow or a highlight inside a block: fed the reference
itself, the paper's BMFR had twice plain accumulation's error on ``orbit``, and that bias does
not fall as frames accumulate.
With the hand-back the output converges to the accumulated input as its variance vanishes.
``"none"`` is the paper's method (4 history planes fewer: 7 instead of 11, 3 more each with an
``emission`` buffer).

Temporal gradient (``temporal_gradient=True``, default; docs/temporal.md §5): when the frame has
a ``gradient`` buffer (the re-shaded samples A-SVGF uses), both accumulations take A-SVGF's
adaptive history (:func:`dbench.methods.svgf.steps.gradient_history`):
N' = min(N(1 − G)^10 + 1, 256), α_k = max(mix(1/N', 1, G), α_k). The BMFR code's fixed α lags
~10 frames behind a light change (it was 1.05× plain accumulation on ``flicker``); A-SVGF's
authors present the gradient as usable by any temporal filter. ``False`` (or a frame without the buffer) gives the fixed rule.

Public: :func:`householder_lstsq` (A (K, m, n), B (K, m, c)) -> X (K, n, c).

Parameters: features ("paper" | "seed" | "normals" | "positions" | "reflected" | "paper+geo" |
"reflected+geo": the last three read the frame's ``reflected_normal`` (instead of ``normal``)
and ``geo_normal`` (beside it) buffers, seed 001 §1.2.1, params.FEATURE_PRESETS), block_size (32),
samples (None: every pixel of a block; an integer W: W pixels drawn per block and frame, the
seed's 36, :func:`block_sample_mask`), noise_amount (0.01), offsets (16), alpha1 (0.2),
alpha2 (0.1), clamp_negative (True), rcond (1e-10), seed (0: noise, offsets and samples),
temporal_gradient (True), tau_d, tau_n, backend ("auto" | "numba" | "torch" | "reference";
"auto", the default, is "numba"; on a GPU the harness runs ``denoise_device``, the Triton kernels
of :mod:`.device`, which cover every setting but ``samples`` (preset "seed"), the features
reading ``reflected_normal``/``geo_normal`` and blocks above 64 px: those stay on the host,
docs/gpu.md §2; "torch" runs
reprojection, accumulation, demodulation, feature construction, the batched Householder fit of
all blocks and the reconstruction as PyTorch kernels (:mod:`dbench.methods.bmfr.torch_path`) on
CUDA when available, else on CPU, NumPy in and out of each kernel, history kept as NumPy;
``params["backend"]`` holds the resolved name), preset (None | "seed": block 64, 36 samples,
features "seed", no hand-back — the seed's implementation, docs/methods/bmfr.md §3.1 | "paper": no hand-back),
handback ("signed" | "wiener" | "none"), taa (False: docs/methods/bmfr.md §1 step 6, the BMFR code's temporal
antialiasing of the output, :mod:`dbench.methods.temporal.taa`), taa_alpha (0.2) and
albedo_floor (1 [dbench]: no demodulation; 0.2 in the ``seed`` and ``paper`` presets, SVGF's;
docs/temporal.md §12).

Fit set: pixels with a hit, no emission and a usable accumulated value; reconstructed: every
hit pixel without emission (a pixel whose sample was non-finite gets the block's fit).
Pixels without hit and emitters keep their accumulated value. ``last`` holds ``dropped``
(columns zeroed by the rank safeguard this frame), ``offset``, ``n1``/``n2`` and ``gradient``
(G, or None without the gradient step).

Non-finite policy: non-finite colour is missing (accumulation keeps history, the pixel is left
out of the fit and reconstructed from its features); non-finite features make a pixel "no hit".

Input range: finite ``color`` and ``emission`` values beyond ±1e15
(:data:`dbench.methods.guards.RADIANCE_MAX`) are clamped to ±1e15 (NaN/±Inf stay missing), so
the demodulated illumination (÷ a_eff ≥ albedo_floor) stays ≤ 1e15 / albedo_floor in float32 and
the Householder norms of the float64 fit stay finite (before the clamp, one pixel at 3e38
demodulated to Inf and the block fits, then every pixel, became NaN).

Example:
    >>> import numpy as np
    >>> from dbench.data import Frame
    >>> from dbench.registry import get
    >>> g = dict(albedo=np.ones((8, 8, 3)), depth=np.ones((8, 8, 1)),
    ...          normal=np.tile([0, 0, 1.0], (8, 8, 1)), position=np.zeros((8, 8, 3)),
    ...          motion=np.zeros((8, 8, 2)))
    >>> m = get("bmfr"); m.reset()
    >>> out = m.denoise(Frame(color=np.full((8, 8, 3), 0.25), **g))
    >>> bool(np.allclose(out, 0.25))
    True
"""
from __future__ import annotations

from functools import partial
from typing import Any

import numpy as np

from ...data import check_buffer
from ...errors import DbenchInputError
from ...denoiser import register
from ..checks import check_positive
from .. import temporal as T
from ..svgf.dispatch import prepare, remodulate
from ..svgf.steps import accumulate_emission, emission_buffer, gradient_history
from . import handback as HB
from .dispatch import bmfr_fit, householder_lstsq
from .numba_path import bmfr_fit_fast
from .params import (ALBEDO_FLOOR_BMFR, FEATURE_PRESETS, N_OFFSETS, NORMAL_SOURCES, PRESETS,
                     RCOND, normal_sources)
from .reference import (block_origins, block_sample_mask, bmfr_fit_reference, feature_stack, grid_offsets,
                        householder_lstsq_reference, uniform_hash)
from .torch_path import bmfr_fit_torch, feature_stack_torch, householder_lstsq_torch

__all__ = ["BMFR", "householder_lstsq", "householder_lstsq_reference", "bmfr_fit",
           "bmfr_fit_fast", "bmfr_fit_reference", "block_sample_mask", "feature_stack", "grid_offsets",
           "block_origins", "uniform_hash", "FEATURE_PRESETS", "bmfr_fit_torch",
           "feature_stack_torch", "householder_lstsq_torch"]


@register("bmfr")
class BMFR(T.HistoryDenoiser):
    """Blockwise multi-order feature regression with two temporal accumulations."""

    kinds = {"sequence"}
    #: ``denoise_device``: Triton kernels, the history kept on the device (:mod:`.device`).
    device_backend = "triton"
    needs = {"color", "albedo", "normal", "depth", "position", "motion"}
    optional_needs = {"emission", "gradient", "geo_normal", "reflected_normal"}
    defaults: dict[str, Any] = dict(features="paper", block_size=32, noise_amount=0.01,
                                    offsets=N_OFFSETS, alpha1=0.2, alpha2=0.1,
                                    clamp_negative=True, rcond=RCOND, seed=0, tau_d=T.TAU_D,
                                    tau_n=T.TAU_N, backend="auto", preset=None, samples=None,
                                    temporal_gradient=True, handback="signed", taa=False,
                                    taa_alpha=T.TAA_ALPHA, albedo_floor=ALBEDO_FLOOR_BMFR)

    def __init__(self, **params: Any) -> None:
        super().__init__(**params)
        preset = self.params["preset"]
        if preset is not None:
            if preset not in PRESETS:
                raise DbenchInputError(f"preset: expected None or one of {tuple(PRESETS)}, "
                                       f"got {preset!r}")
            for key, value in PRESETS[preset].items():
                if key not in params:
                    self.params[key] = value
        p = self.params
        if not 0 <= p["seed"] < 2**32:  # (an integer: Denoiser checks its kind) NumPy's seeds
            raise DbenchInputError(f"seed: expected an integer in [0, {2**32 - 1}], "
                                   f"got {p['seed']!r}")
        if p["features"] not in FEATURE_PRESETS:
            raise DbenchInputError(f"features: expected one of {tuple(FEATURE_PRESETS)}, "
                                   f"got {p['features']!r}")
        if not isinstance(p["block_size"], (int, np.integer)) or p["block_size"] < 2:
            raise DbenchInputError(f"block_size: expected an integer >= 2, got {p['block_size']!r}")
        if not isinstance(p["offsets"], (int, np.integer)) or p["offsets"] < 1:
            raise DbenchInputError(f"offsets: expected an integer >= 1, got {p['offsets']!r}")
        for key in ("alpha1", "alpha2"):
            if not 0.0 <= float(p[key]) <= 1.0:
                raise DbenchInputError(f"{key}: expected a number in [0, 1], got {p[key]!r}")
        if not 0.0 <= float(p["noise_amount"]) < 1.0:
            raise DbenchInputError(f"noise_amount: expected a number in [0, 1), "
                                   f"got {p['noise_amount']!r}")
        check_positive("rcond", p["rcond"], allow_zero=True)  # a relative threshold, < inf
        if p["samples"] is not None and (not isinstance(p["samples"], (int, np.integer))
                                         or isinstance(p["samples"], bool) or p["samples"] < 1):
            raise DbenchInputError(f"samples: expected None (every pixel of a block) or an "
                                   f"integer >= 1, got {p['samples']!r}")
        if not isinstance(p["temporal_gradient"], bool):
            raise DbenchInputError(f"temporal_gradient: expected True or False, "
                                   f"got {p['temporal_gradient']!r}")
        if p["handback"] not in HB.HANDBACKS:
            raise DbenchInputError(f"handback: expected one of {HB.HANDBACKS}, "
                                   f"got {p['handback']!r}")
        # a feature preset with the reflected or geometric normal needs that buffer: the
        # harness then skips scenes that cannot provide it, before rendering
        self.needs = set(self.needs) | {NORMAL_SOURCES[k] for k in normal_sources(p["features"])
                                        if k != "n"}
        self._start()
        self.grid = grid_offsets(int(p["block_size"]), int(p["offsets"]), int(p["seed"]))
        self.scaled = np.array([c[0] == "p" for c in FEATURE_PRESETS[p["features"]]], bool)
        self.frame_index = 0
        self._prev_lum: np.ndarray | None = None

    def reset(self) -> None:
        super().reset()
        self.frame_index = 0
        self._prev_lum = None
        if getattr(self, "_device_history", None) is not None:
            self._device_history.reset()

    def runs_on_device(self) -> bool:
        from .device import device_refusal
        return self.params["backend"] != "reference" and not device_refusal(self.params)

    def denoise_device(self, data):
        """One frame on a :class:`~dbench.device.DeviceFrame` (:func:`.device.bmfr_device`): an
        (H, W, 3) tensor on its device, equal to :meth:`denoise` on the numba backend within
        the tolerance of tests/methods/test_bmfr_device.py. Settings without a device path
        (:func:`.device.device_refusal`) raise DbenchInputError naming them."""
        from .device import bmfr_device, device_refusal
        why = device_refusal(self.params)
        if self.params["backend"] == "reference":
            why = "backend='reference'"
        if why:
            raise DbenchInputError(f"bmfr: {why} has no device path (runs_on_device() is "
                                   f"False); run it on the host with denoise()")
        return bmfr_device(self, data)

    def _normals(self, data, geo) -> np.ndarray:
        """The planar (3·k, H, W) normals the feature preset reads (params.normal_sources):
        the shading normal alone for the spec's presets."""
        sources = normal_sources(self.params["features"])
        if sources in ((), ("n",)):
            return geo.normal
        why = f"features={self.params['features']!r}"
        return np.concatenate([T.feature_normal(data, geo, NORMAL_SOURCES[k], why)
                               for k in sources])

    def _buffer(self, key: str, shape) -> np.ndarray:
        """A float32 work array kept from frame to frame in the history's pool (a fresh one
        costs its page faults at 720p); its values are stale."""
        return self.history.work_array(f"bmfr-{key}", tuple(shape))

    def _alphas(self, data, geo, n_hist, prep):
        """(history length to accumulate on, α1, α2, G): the fixed rule of the BMFR code, or,
        with ``temporal_gradient`` and a ``gradient`` buffer on the frame, A-SVGF's adaptive
        history (docs/methods/svgf.md §6; Schied et al. 2018 present the gradient as usable by any
        temporal filter): N' = min(N(1 − G)^10 + 1, 256), α_k = max(mix(1/N', 1, G), α_k)."""
        p = self.params
        if not p["temporal_gradient"] or getattr(data, "gradient", None) is None:
            return n_hist, None, None, None
        g, n_new, a = gradient_history(data, geo, self.history.prev, self._prev_lum, n_hist,
                                       T.N_MAX, backend=self.backend)
        # in place where it can be: three fresh (H, W) arrays a frame cost their page faults
        a1 = np.maximum(a, np.float32(p["alpha1"]))
        a2 = np.maximum(a, np.float32(p["alpha2"]), out=a)
        return np.subtract(n_new, np.float32(1.0), out=n_new), a1, a2, g

    def _denoise(self, data, color: np.ndarray) -> np.ndarray:
        p, be = self.params, self.backend
        fast = be == "numba"
        h, w = color.shape[:2]
        albedo = check_buffer("albedo", getattr(data, "albedo", None), (h, w, 3))
        geo = T.frame_geometry(data, backend=be)
        emission = emission_buffer(data, h, w)
        prep = prepare(be, color, albedo, emission, geo.hit, p["albedo_floor"])
        present = prep["present"]

        # history: Z accumulated (3), N, the fit accumulated (3); with the hand-back Z²
        # accumulated (3) and Σ w² of the first accumulation; with an emission buffer the
        # emission accumulated (3) (without one it is 0 everywhere: nothing to reproject or
        # accumulate; a change of the buffer's presence resets the history)
        handing_back = p["handback"] != "none"  # "wiener" or "signed"
        emissive = emission is not None
        base = 7 + (HB.EXTRA_PLANES if handing_back else 0)  # the emission planes' start
        planes = base + (3 if emissive else 0)
        hist, status = self.history.fetch(geo, planes)
        ok = status > 0
        acc = partial(T.accumulate_any, be)
        n_hist, a1, a2, g = self._alphas(data, geo, hist[3], prep)
        # this frame's history is written in place into a reused array (History.staging)
        stage = self.history.staging(planes, h, w)
        z_acc, n1, a_used = acc(prep["illum"], hist[0:3], n_hist, ok, p["alpha1"], T.N_MAX, a1,
                                present, out=(stage[0:3], stage[3]))
        acc_e = (accumulate_emission(be, prep, hist[base:], n_hist, ok, p["alpha1"], T.N_MAX,
                                     a1, present, out=stage[base:])
                 if emissive else prep["emission"])
        filled = n1 > 0
        recon = geo.hit & ~prep["emitter"]
        fit = handed = recon & filled  # handed: where the residual may go back
        k = self.frame_index
        offset = self.grid[k % len(self.grid)]
        noise_seed = (int(p["seed"]) * 1_000_003 + k) & 0x7FFFFFFFFFFFFFFF
        fit_args = (int(p["block_size"]), offset, float(p["noise_amount"]), noise_seed,
                    float(p["rcond"]), bool(p["clamp_negative"]))
        if p["samples"] is not None:  # the seed's W random pixels per block (docs/methods/bmfr.md §3.1)
            fit = fit & block_sample_mask(fit, int(p["block_size"]), offset, int(p["samples"]),
                                          noise_seed)
        scaled = self.scaled
        normals = self._normals(data, geo)
        if be == "torch":
            feats = feature_stack_torch(normals, geo.position, p["features"])
            y_fit, dropped = bmfr_fit("torch", z_acc, feats, scaled, fit, recon, *fit_args)
        elif fast:
            y_fit, dropped = bmfr_fit_fast(z_acc, None, scaled, fit, recon, *fit_args,
                                           source=(normals, geo.position, p["features"]),
                                           out=self._buffer("fit", z_acc.shape))
        else:
            feats, _ = feature_stack(normals, geo.position, p["features"])
            y_fit, dropped = bmfr_fit_reference(z_acc, feats, scaled, fit, recon, *fit_args)
        if handing_back:  # the residual's hand-back before the second accumulation (handback.py)
            # the torch backend runs the hand-back's compiled CPU kernels (NumPy in and out)
            compiled = be != "reference"
            if compiled:
                zz_acc, s, var = HB.moments_fast(
                    prep["illum"], z_acc, a_used, hist[7:11], ok, present, handed,
                    stage[7:11] if fast else np.empty((4, h, w), np.float32),
                    self._buffer("var", z_acc.shape))
            else:
                zz_acc, s, var = HB.moments_reference(be, prep["illum"], z_acc, a_used,
                                                      hist[7:11], n_hist, ok, present, handed,
                                                      p["alpha1"], T.N_MAX, a1)
            # clamp_negative: the residual's local mean can take the fit below 0
            y_fit = HB.handback(z_acc, y_fit, var, handed, compiled,
                                out=self._buffer("handback", y_fit.shape) if compiled else None,
                                clamp=bool(p["clamp_negative"]),
                                signed=p["handback"] == "signed")
        # the second history length equals the first one (same reprojection, same resets)
        y_acc, n2, _ = acc(y_fit, hist[4:7], n_hist, ok, p["alpha2"], T.N_MAX, a2,
                           filled | recon, out=(stage[4:7], None))
        if not fast:  # the other backends return new arrays: gather them
            parts = ([z_acc, n1[None], y_acc] + ([zz_acc, s[None]] if handing_back else [])
                     + ([acc_e] if emissive else []))
            stage = np.concatenate(parts)
        self.history.store(geo, stage, valid=filled | recon, finite=True)
        self.frame_index += 1
        self._prev_lum = prep["lum_raw"]
        self.last = {"gradient": g, "dropped": dropped, "offset": tuple(int(v) for v in offset), "n1": n1,
                     "n2": n2, "status": status}
        out = remodulate(y_acc, prep["a_eff"], acc_e, be)
        return self._with_taa(out, geo.motion, status)
