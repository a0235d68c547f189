"""``bmfr``: blockwise multi-order feature regression (Koskela et al. 2019; spec/bmfr.md).

Per frame (spec §1): subtract the primary hits' emission (``emission`` buffer when present, as
for SVGF) and demodulate by albedo; accumulation 1 of the noisy illumination Z with
α1 = max(1/N, 0.2); a block grid (B = 32) with this frame's offset (16 offsets cycling, the
first (0, 0)); per block a least-squares fit of Z' on the features
[1, n, P, P²] (positions scaled per block, §2.1) with U(−0.01, 0.01) noise on every feature
column but the constant (stochastic regularisation, §4), solved by batched Householder QR
without Q with R shared by the three channels (§5, :func:`householder_lstsq`); reconstruction
with the noise-free features, negatives clamped to 0; accumulation 2 of the fit with
α2 = max(1/N, 0.1); remodulation.

Public: :func:`householder_lstsq` (A (K, m, n), B (K, m, c)) -> X (K, n, c).

Parameters: features ("paper" | "seed" | "normals" | "positions"), block_size (32),
noise_amount (0.01), offsets (16), alpha1 (0.2), alpha2 (0.1), clamp_negative (True),
rcond (1e-10), seed (0: noise and offsets), tau_d, tau_n, backend ("auto" | "numba" | "torch" |
"reference"; "auto", the default, is "torch" when ``torch.cuda.is_available()``, else "numba";
"torch" runs reprojection, accumulation, demodulation, feature construction, the batched
Householder fit of all blocks and the reconstruction as PyTorch kernels
(:mod:`dbench.methods.bmfr.torch_path`) on CUDA when available, else on CPU, NumPy in and out
of each kernel, history kept as NumPy; ``params["backend"]`` holds the resolved name),
preset (None | "seed": block 64, features "seed"; the seed's 36 random samples per block are not
implemented — every pixel of a block is used).

Fit set: pixels with a hit, no emission and a usable accumulated value; reconstructed: every
hit pixel without emission (a pixel whose sample was non-finite gets the block's fit).
Pixels without hit and emitters keep their accumulated value. ``last`` holds ``dropped``
(columns zeroed by the rank safeguard this frame), ``offset`` and ``n1``/``n2``.

Non-finite policy: non-finite colour is missing (accumulation keeps history, the pixel is left
out of the fit and reconstructed from its features); non-finite features make a pixel "no hit".

Input range: finite ``color`` and ``emission`` values beyond ±1e15
(:data:`dbench.methods.guards.RADIANCE_MAX`) are clamped to ±1e15 (NaN/±Inf stay missing), so
the demodulated illumination (÷ albedo ≥ 1e-3) stays ≤ 1e18 in float32 and the Householder
norms of the float64 fit stay finite (before the clamp, one pixel at 3e38 demodulated to Inf and
the block fits, then every pixel, became NaN).

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
from ...registry import register
from .. import temporal as T
from ..svgf import _accumulate_emission, _emission
from ..svgf import dispatch as SC
from .dispatch import bmfr_fit, householder_lstsq
from .numba_path import bmfr_fit_fast
from .params import FEATURE_PRESETS, N_OFFSETS, PRESETS, RCOND
from .reference import (block_origins, block_sample_mask, bmfr_fit_reference, feature_stack, grid_offsets,
                        householder_lstsq_reference, uniform_hash)
from .torch_path import bmfr_fit_torch, feature_stack_torch, householder_lstsq_torch

__all__ = ["BMFR", "householder_lstsq", "householder_lstsq_reference", "bmfr_fit",
           "bmfr_fit_fast", "bmfr_fit_reference", "feature_stack", "grid_offsets",
           "block_origins", "uniform_hash", "FEATURE_PRESETS", "bmfr_fit_torch",
           "feature_stack_torch", "householder_lstsq_torch"]


@register("bmfr")
class BMFR(T.HistoryDenoiser):
    """Blockwise multi-order feature regression with two temporal accumulations."""

    kinds = {"sequence"}
    needs = {"color", "albedo", "normal", "depth", "position", "motion"}
    defaults: dict[str, Any] = dict(features="paper", block_size=32, noise_amount=0.01,
                                    offsets=N_OFFSETS, alpha1=0.2, alpha2=0.1,
                                    clamp_negative=True, rcond=RCOND, seed=0, tau_d=T.TAU_D,
                                    tau_n=T.TAU_N, backend="auto", preset=None, samples=None)

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
        if p["samples"] is not None and (not isinstance(p["samples"], (int, np.integer))
                                         or isinstance(p["samples"], bool) or p["samples"] < 1):
            raise DbenchInputError(f"samples: expected None (every pixel of a block) or an "
                                   f"integer >= 1, got {p['samples']!r}")
        self._start()
        self.grid = grid_offsets(int(p["block_size"]), int(p["offsets"]), int(p["seed"]))
        self.scaled = np.array([c[0] == "p" for c in FEATURE_PRESETS[p["features"]]], bool)
        self.frame_index = 0

    def reset(self) -> None:
        super().reset()
        self.frame_index = 0

    def _denoise(self, data, color: np.ndarray) -> np.ndarray:
        p, be = self.params, self.backend
        fast = be == "numba"
        h, w = color.shape[:2]
        albedo = check_buffer("albedo", getattr(data, "albedo", None), (h, w, 3))
        geo = T.frame_geometry(data, backend=be)
        prep = SC.prepare(be, color, albedo, _emission(data, h, w), geo.hit)
        present = prep["present"]

        # history: Z accumulated (3), N, the fit accumulated (3), emission accumulated (3)
        hist, status = self.history.fetch(geo, 10)
        ok = status > 0
        acc = partial(T.accumulate_any, be)
        z_acc, n1, _ = acc(prep["illum"], hist[0:3], hist[3], ok, p["alpha1"], T.N_MAX, None,
                           present)
        acc_e = _accumulate_emission(be, prep, hist[7:10], hist[3], ok, p["alpha1"], T.N_MAX,
                                     None, present)
        filled = n1 > 0
        recon = geo.hit & ~prep["emitter"]
        fit = recon & filled
        k = self.frame_index
        offset = self.grid[k % len(self.grid)]
        noise_seed = (int(p["seed"]) * 1_000_003 + k) & 0x7FFFFFFFFFFFFFFF
        fit_args = (int(p["block_size"]), offset, float(p["noise_amount"]), noise_seed,
                    float(p["rcond"]), bool(p["clamp_negative"]))
        if p["samples"] is not None:  # the seed's W random pixels per block (spec §3.1)
            fit = fit & block_sample_mask(fit, int(p["block_size"]), offset, int(p["samples"]),
                                          noise_seed)
        scaled = self.scaled
        if be == "torch":
            feats = feature_stack_torch(geo.normal, geo.position, p["features"])
            y_fit, dropped = bmfr_fit("torch", z_acc, feats, scaled, fit, recon, *fit_args)
        elif fast:
            y_fit, dropped = bmfr_fit_fast(z_acc, None, scaled, fit, recon, *fit_args,
                                           source=(geo.normal, geo.position, p["features"]))
        else:
            feats, _ = feature_stack(geo.normal, geo.position, p["features"])
            y_fit, dropped = bmfr_fit_reference(z_acc, feats, scaled, fit, recon, *fit_args)
        # the second history length equals the first one (same reprojection, same resets)
        y_acc, n2, _ = acc(y_fit, hist[4:7], hist[3], ok, p["alpha2"], T.N_MAX, None,
                           filled | recon)
        self.history.store(geo, np.concatenate([z_acc, n1[None], y_acc, acc_e]),
                           valid=filled | recon, finite=True)
        self.frame_index += 1
        self.last = {"dropped": dropped, "offset": tuple(int(v) for v in offset), "n1": n1,
                     "n2": n2, "status": status}
        return SC.remodulate(y_acc, prep["a_eff"], acc_e, be)
