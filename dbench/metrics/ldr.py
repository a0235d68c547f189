"""LDR metrics on tone-mapped images: PSNR, SSIM, LDR-FLIP (docs/metrics.md §1)."""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..errors import DbenchInputError
from .checks import _finite, _integrate, check_pair
from .pixel import _err_sq
from .params import PSNR_CAP_DB, SSIM_K1, SSIM_K2, SSIM_SIGMA, SSIM_WIN
from .tonemapping import check_ev, tonemap


def psnr_ldr(a: np.ndarray, b: np.ndarray) -> float:
    """PSNR with data range 1 between two tone-mapped images in [0, 1], capped at 100 dB.

    ``min(100, 10·log10(1 / mean((a − b)²)))``; 100 when the images are equal; NaN if ``a``
    holds NaN. No shape checks (internal helper; :func:`psnr` checks).
    """
    if not _finite(a):
        return float("nan")
    m = float(np.mean(_err_sq(a, b)))
    if m <= 0.0:
        return PSNR_CAP_DB
    return min(PSNR_CAP_DB, 10.0 * math.log10(1.0 / m))


def ssim_ldr(a: np.ndarray, b: np.ndarray) -> float:
    """SSIM between two tone-mapped (H, W, C) images in [0, 1] (docs/metrics.md §1).

    Images at least 11 px on both sides: ``skimage.metrics.structural_similarity(a, b,
    gaussian_weights=True, sigma=1.5, use_sample_covariance=False, data_range=1,
    channel_axis=-1)`` (K1 = 0.01, K2 = 0.03). Smaller images, where the 11×11 Gaussian window
    does not fit: the same SSIM formula with a single window covering the whole image (global
    means, population variances and covariance per channel, then averaged over channels); for a
    1×1 image this reduces to the luminance term (2ab + C1)/(a² + b² + C1). Always finite for
    finite input; NaN if ``a`` holds NaN.
    """
    if not _finite(a):
        return float("nan")
    h, w = a.shape[:2]
    if min(h, w) >= SSIM_WIN:
        from skimage.metrics import structural_similarity

        return float(structural_similarity(a, b, gaussian_weights=True, sigma=SSIM_SIGMA,
                                           use_sample_covariance=False, data_range=1.0,
                                           channel_axis=-1, K1=SSIM_K1, K2=SSIM_K2))
    return _ssim_global(a, b)


def ssim_global_over(a: np.ndarray, b: np.ndarray, select: np.ndarray) -> float:
    """The single-window SSIM of :func:`ssim_ldr`'s small images over the pixels ``select``
    ((H, W) bool) of the tone-mapped (H, W, C) pair: the surface form of an image smaller than
    the window, where the per-pixel map is one value for the whole image; NaN when ``select``
    holds no pixel."""
    if not select.any():
        return float("nan")
    return _ssim_global(a[select][:, None, :], b[select][:, None, :])


def _ssim_global(a: np.ndarray, b: np.ndarray) -> float:
    c1 = (SSIM_K1 * 1.0) ** 2
    c2 = (SSIM_K2 * 1.0) ** 2
    mu_a = a.mean(axis=(0, 1))
    mu_b = b.mean(axis=(0, 1))
    da = a - mu_a
    db = b - mu_b
    var_a = (da * da).mean(axis=(0, 1))
    var_b = (db * db).mean(axis=(0, 1))
    cov = (da * db).mean(axis=(0, 1))
    s = ((2 * mu_a * mu_b + c1) * (2 * cov + c2)) / ((mu_a ** 2 + mu_b ** 2 + c1) * (var_a + var_b + c2))
    return float(np.mean(s))


def _psnr_from_mean(m: Any) -> Any:
    """PSNR from the mean squared LDR error ``m`` (a scalar or an array of bootstrap
    resamples), as the judge takes it: capped at 100 dB, 100 dB where ``m`` is 0, NaN where
    ``m`` is NaN (a mean over no pixel, e.g. the surface of an image that is all light: no
    value, where the cap would read as a perfect score)."""
    m = np.asarray(m, np.float64)
    out = np.where(m > 0, np.minimum(PSNR_CAP_DB, 10.0 * np.log10(1.0 / np.where(
        m > 0, m, 1.0))), PSNR_CAP_DB)
    out = np.where(np.isnan(m), np.nan, out)
    return out if out.ndim else float(out)


def _ssim_map(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(map, weight): skimage's SSIM map averaged over channels, weight 0 on the border it
    crops; images smaller than the window get the global SSIM everywhere (:func:`ssim_ldr`;
    their surface form is :func:`ssim_global_over` the surface pixels, set by the judge)."""
    h, w = a.shape[:2]
    if min(h, w) < SSIM_WIN:
        return np.full((h, w), _ssim_global(a, b)), np.ones((h, w))
    from skimage.metrics import structural_similarity

    _, s = structural_similarity(a, b, gaussian_weights=True, sigma=SSIM_SIGMA,
                                 use_sample_covariance=False, data_range=1.0, channel_axis=-1,
                                 K1=SSIM_K1, K2=SSIM_K2, full=True)
    pad = (SSIM_WIN - 1) // 2
    weight = np.zeros((h, w))
    weight[pad:h - pad, pad:w - pad] = 1.0
    return s.mean(axis=-1).astype(np.float64), weight


def _flip_map(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, None]:
    """(map, None): flip_evaluator's per-pixel LDR-FLIP error of ``a`` against ``b``."""
    import flip_evaluator

    m, _, _ = flip_evaluator.evaluate(_flip_input("reference", b), _flip_input("output", a),
                                      "LDR", inputsRGB=True, applyMagma=False,
                                      computeMeanError=True, parameters={})
    return np.asarray(m, np.float64).reshape(a.shape[:2]), None


def _flip_input(name: str, x: np.ndarray) -> np.ndarray:
    """(H, W, 1 or 3) -> C-contiguous float32 (H, W, 3), the layout flip_evaluator takes."""
    if x.shape[-1] not in (1, 3):
        raise DbenchInputError(f"{name}: FLIP needs 1 or 3 channels; expected shape (H, W, 3) or "
                               f"(H, W, 1), got {tuple(x.shape)}")
    if x.shape[-1] == 1:
        x = np.repeat(x, 3, axis=-1)
    return np.ascontiguousarray(x, dtype=np.float32)


def flip_ldr(a: np.ndarray, b: np.ndarray) -> float:
    """Mean LDR-FLIP error between a tone-mapped test image ``a`` and reference ``b``.

    Both (H, W, 1 or 3), sRGB-encoded in [0, 1]; one channel is replicated to three.
    ``flip_evaluator.evaluate(b, a, "LDR", inputsRGB=True, applyMagma=False,
    computeMeanError=True, parameters={})`` with the default ppd (67.02). NaN if ``a`` holds NaN.
    """
    if not _finite(a):
        return float("nan")
    import flip_evaluator

    test = _flip_input("output", a)
    ref = _flip_input("reference", b)
    _, mean, _ = flip_evaluator.evaluate(ref, test, "LDR", inputsRGB=True, applyMagma=False,
                                         computeMeanError=True, parameters={})
    return float(mean)


def psnr(output: Any, reference: Any, ev: float = 0.0) -> float:
    """PSNR in dB on tone-mapped images (docs/metrics.md §1), capped at 100 dB.

    Args:
        output, reference: (H, W, C) or (H, W, T, C), same shape; transient: the sum over T.
        ev: exposure of the tone map in stops.
    """
    o, r = check_pair(output, reference)
    ev = check_ev(ev)
    if not _finite(o):
        return float("nan")
    return psnr_ldr(tonemap(_integrate(o), ev), tonemap(_integrate(r), ev))


def ssim(output: Any, reference: Any, ev: float = 0.0) -> float:
    """SSIM on tone-mapped images (docs/metrics.md §1); see :func:`ssim_ldr` for the small-image rule.

    Args:
        output, reference: (H, W, C) or (H, W, T, C), same shape; transient: the sum over T.
        ev: exposure of the tone map in stops.
    """
    o, r = check_pair(output, reference)
    ev = check_ev(ev)
    if not _finite(o):
        return float("nan")
    return ssim_ldr(tonemap(_integrate(o), ev), tonemap(_integrate(r), ev))


def flip(output: Any, reference: Any, ev: float = 0.0) -> float:
    """LDR-FLIP on tone-mapped sRGB images (docs/metrics.md §1, §5).

    Args:
        output, reference: (H, W, C) or (H, W, T, C) with C = 1 or 3, same shape; transient:
            the sum over T.
        ev: exposure of the tone map in stops.
    """
    o, r = check_pair(output, reference)
    ev = check_ev(ev)
    _check_flip_channels(r)
    if not _finite(o):
        return float("nan")
    return flip_ldr(tonemap(_integrate(o), ev), tonemap(_integrate(r), ev))


def _check_flip_channels(r: np.ndarray) -> None:
    if r.shape[-1] not in (1, 3):
        layout = "(H, W, C)" if r.ndim == 3 else "(H, W, T, C)"
        raise DbenchInputError(f"output, reference: FLIP needs C = 1 or 3 channels; expected "
                               f"shape {layout} with C in (1, 3), got {tuple(r.shape)}")
