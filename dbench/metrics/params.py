"""Constants of the metrics (spec anchors.md §1) and their one-line definitions for reports."""
from __future__ import annotations

from .tonemapping import TONEMAP_DEFINITION

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
#: One-line definition of every metric with its constants; reports print these verbatim.
DEFINITIONS: dict[str, str] = {
    "mse": "MSE = mean((x − r)²) over all pixels, bins and channels; linear HDR values",
    "rmse": "RMSE = sqrt(mean((x − r)²)) over all pixels, bins and channels; linear HDR values",
    "relmse": "relMSE = mean((x − r)² / (r² + ε)), ε = 1e-2; linear HDR values",
    "smape": "SMAPE = mean(|x − r| / (|x| + |r| + ε)), ε = 1e-2, no factor 2; linear HDR values",
    "rmae": "rMAE = mean(|x − r| / (|r| + 0.01)); linear HDR values (noisebase's extra /3 omitted)",
    "psnr": ("PSNR = min(100, 10·log10(1 / mean((T(x) − T(r))²))) dB, data range 1, 100 dB when "
             "the MSE is 0; " + TONEMAP_DEFINITION + "; transient: on the sum over T"),
    "ssim": ("SSIM (Wang et al. 2004) on T(x), T(r): Gaussian window σ = 1.5 (11×11), K1 = 0.01, "
             "K2 = 0.03, data range 1, population covariance, per channel then averaged "
             "(skimage structural_similarity); images under 11 px on a side: the same formula "
             "with one window covering the whole image; " + TONEMAP_DEFINITION
             + "; transient: on the sum over T"),
    "flip": ("LDR-FLIP: mean NVIDIA FLIP error (flip_evaluator 1.7, default ppd 67 (67.02)) "
             "between the sRGB images T(x) and T(r); " + TONEMAP_DEFINITION
             + "; transient: on the sum over T"),
    "hdrflip": ("HDR-FLIP: mean NVIDIA FLIP error (flip_evaluator 1.7, default ppd 67 (67.02), "
                "ACES tone mapper) on linear values clipped to >= 0; start/stop exposures chosen "
                "by FLIP from the reference once and reused for every image compared with it "
                "(0/0 for a black reference); transient: on the sum over T"),
}
#: Metrics where a larger value is better (all others: smaller is better, 0 is perfect).
HIGHER_IS_BETTER = frozenset({"psnr", "ssim"})
