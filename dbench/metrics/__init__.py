"""Image metrics for denoiser outputs (docs/metrics.md §1, §5, §6).

Plain functions on NumPy arrays. ``output`` and ``reference`` are (H, W, C) images or
(H, W, T, C) transient videos of the same shape, any real dtype, computed in float64.

* ``mse``, ``rmse``, ``relmse`` (ε = 1e-2), ``smape`` (ε = 1e-2), ``rmae``: linear HDR values,
  over every pixel, bin and channel; :func:`per_bin` gives the (T,) curve of transient data.
* ``psnr`` (capped at 100 dB), ``ssim``, ``flip`` (LDR-FLIP): on the tone-mapped sRGB image
  :func:`tonemap` (``clip(x·2^EV, 0, 1)`` then the sRGB transfer function).
* ``hdrflip``: HDR-FLIP on linear values clipped to >= 0, exposures fixed once per reference.
* Transient inputs: psnr, ssim, flip and hdrflip run on the time-integrated image (sum over T).
* Sequences: :func:`dbench.metrics.video_quality.cvvdp_jod`, ColorVideoVDP in JOD on
  (T, H, W, 3) videos (imported on use; it loads PyTorch and the ``cvvdp`` package).
* Non-finite policy: a NaN/Inf anywhere in ``output`` makes the metric NaN (never an exception,
  never silently dropped); ``reference`` must be finite (DbenchInputError otherwise).

:data:`DEFINITIONS` states each metric with its constants in one line, for reports; every
metric's record (formula, direction, definition, variants) is in
:data:`dbench.metrics.records.METRICS`, which every module that names metrics reads.

Example:
    >>> import numpy as np
    >>> from dbench import metrics
    >>> r = np.ones((8, 8, 3)); x = np.full((8, 8, 3), 1.1)
    >>> round(metrics.compute("relmse", x, r), 8)
    0.00990099
    >>> sorted(metrics.compute_all(x, r, names=["rmse", "psnr"]))
    ['psnr', 'rmse']
"""
from __future__ import annotations

from .checks import check_pair
from .hdr import clear_exposure_cache, hdrflip, hdrflip_exposures
from .image import PER_BIN_METRICS, available, compute, compute_all, per_bin
from .ldr import flip, flip_ldr, psnr, psnr_ldr, ssim, ssim_ldr
from .pixel import mse, relmse, rmae, rmse, smape
from .records import DEFINITIONS, HIGHER_IS_BETTER, higher_is_better
from .tonemapping import TONEMAP_DEFINITION, srgb_decode, srgb_encode, tonemap

__all__ = [
    "DEFINITIONS", "HIGHER_IS_BETTER", "higher_is_better",
    "PER_BIN_METRICS", "TONEMAP_DEFINITION",
    "available", "compute", "compute_all", "per_bin",
    "tonemap", "srgb_encode", "srgb_decode",
    "mse", "rmse", "relmse", "smape", "rmae", "psnr", "ssim", "flip", "hdrflip",
    "psnr_ldr", "ssim_ldr", "flip_ldr", "hdrflip_exposures", "clear_exposure_cache", "check_pair",
]
