"""Constants of the metrics (docs/metrics.md §1); their definitions and directions are in
the metric records (records.py)."""
from __future__ import annotations

#: ε of relMSE = mean((x − r)² / (r² + ε)).
RELMSE_EPS = 1e-2
#: ε of SMAPE = mean(|x − r| / (|x| + |r| + ε)), no factor 2.
SMAPE_EPS = 1e-2
#: Constant of rMAE = mean(|x − r| / (|r| + 0.01)) (noisebase's extra /3 omitted).
RMAE_EPS = 1e-2
#: PSNR value for MSE_LDR = 0, and the upper bound of every PSNR.
PSNR_CAP_DB = 100.0
#: SSIM parameters (Wang et al. 2004, as skimage with gaussian_weights=True).
SSIM_SIGMA = 1.5
SSIM_K1 = 0.01
SSIM_K2 = 0.03
#: Width of the Gaussian window skimage uses for σ = 1.5 (truncate 3.5): 2·int(3.5σ + 0.5) + 1.
SSIM_WIN = 11
#: HDR-FLIP: references whose largest luminance is below this are "black" (see :func:`hdrflip`).
HDRFLIP_BLACK_LUMINANCE = 1e-6
#: Exposures used for a black reference, where flip_evaluator's own choice is undefined.
HDRFLIP_BLACK_EXPOSURES = {"startExposure": 0.0, "stopExposure": 0.0, "numExposures": 2}
