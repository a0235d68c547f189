"""Image metrics: MSE, RMSE, relMSE, SMAPE, rMAE, PSNR, SSIM, LDR-FLIP and HDR-FLIP.

Definitions and constants follow spec anchors.md §1 (metrics), §5 (FLIP usage) and are checked by
the tests of §6. Each metric is a plain function ``metric(output, reference, **options) -> float``
on NumPy arrays (scikit-image style); :func:`compute` picks one by name and :func:`compute_all`
computes several, tone-mapping each image once.

Shapes:
    ``output`` and ``reference`` are (H, W, C) images or (H, W, T, C) transient videos of the
    same shape, any real dtype; everything is computed in float64 (FLIP in float32, which is what
    flip_evaluator takes).

Linear (pixel-wise) metrics — ``mse``, ``rmse``, ``relmse``, ``smape``, ``rmae`` — run on linear
HDR values over every pixel, bin and channel. For transient inputs they cover the whole
(H, W, T, C) tensor; :func:`per_bin` gives the curve over T.

Image metrics — ``psnr``, ``ssim``, ``flip``, ``hdrflip`` — need an image: for transient inputs
they run on the time-integrated image (the sum over T, shape (H, W, C)). ``psnr``, ``ssim`` and
``flip`` use the tone mapping :func:`tonemap`, ``T(x) = srgb_encode(clip(x·2^EV, 0, 1))`` with the
sRGB transfer function ``12.92 y`` for ``y <= 0.0031308``, else ``1.055 y^(1/2.4) − 0.055``
(EV = 0 unless a scene sets it); ``hdrflip`` uses linear values.

Non-finite policy:
    * ``reference`` must be finite, else :class:`~dbench.errors.DbenchInputError`.
    * If ``output`` holds any NaN or ±Inf, every metric returns ``float('nan')``: it never raises
      and never drops the bad pixels silently (a clipped or masked mean would hide a broken
      denoiser). :func:`per_bin` returns NaN for the bins that hold a non-finite value.

Example:
    >>> import numpy as np
    >>> r = np.ones((4, 4, 3)); x = np.full((4, 4, 3), 1.1)
    >>> round(compute("rmse", x, r), 6), round(compute("smape", x, r), 8)
    (0.1, 0.04739336)
"""
from __future__ import annotations

import hashlib
import math
import threading
from collections import OrderedDict
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..data import check_buffer
from ..errors import DbenchInputError, UnknownNameError

# ---------------------------------------------------------------------------------------------
# Tone mapping for LDR metrics (spec anchors.md §1): T(x) = srgb_encode(clip(x·2^EV, 0, 1))
# ---------------------------------------------------------------------------------------------

#: Linear-segment threshold of the sRGB transfer function (IEC 61966-2-1).
SRGB_THRESHOLD = 0.0031308
#: The same threshold in encoded values (12.92 · SRGB_THRESHOLD, rounded as in the standard).
SRGB_THRESHOLD_ENCODED = 0.04045

#: One-line statement of the tone mapping, printed by reports next to the LDR metrics.
TONEMAP_DEFINITION = ("tone map T(x) = sRGB(clip(x·2^EV, 0, 1)), EV = 0 unless the scene sets it; "
                      "sRGB(y) = 12.92·y for y <= 0.0031308, else 1.055·y^(1/2.4) − 0.055")


def _as_float64(name: str, x: Any) -> np.ndarray:
    arr = np.asarray(x)
    if arr.dtype == object or np.iscomplexobj(arr) or not (
            np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
        raise DbenchInputError(f"{name}: expected a real numeric array, got dtype {arr.dtype}")
    return arr.astype(np.float64, copy=False)


def check_ev(ev: Any) -> float:
    """Return ``ev`` as a float; DbenchInputError unless it is a finite real number."""
    try:
        value = float(ev)
    except (TypeError, ValueError):
        raise DbenchInputError(f"ev: expected a finite number (exposure in stops), got {ev!r}") from None
    if not math.isfinite(value):
        raise DbenchInputError(f"ev: expected a finite number (exposure in stops), got {ev!r}")
    return value


def srgb_encode(y: Any) -> np.ndarray:
    """sRGB transfer function (linear -> display-encoded), element-wise, float64.

    Args:
        y: array of any shape, linear values, normally in [0, 1] (values outside are not clipped:
            negative values follow the linear segment, values above 1 the power segment).

    Returns:
        float64 array of the same shape.
    """
    y = _as_float64("y", y)
    with np.errstate(invalid="ignore"):
        # 1.055 p − 0.055 written as 1 + 1.055 (p − 1), so that 1 maps to exactly 1.
        power = 1.0 + 1.055 * (np.power(np.maximum(y, SRGB_THRESHOLD), 1.0 / 2.4) - 1.0)
    return np.where(y <= SRGB_THRESHOLD, 12.92 * y, power)


def srgb_decode(s: Any) -> np.ndarray:
    """Inverse of :func:`srgb_encode` (display-encoded -> linear), element-wise, float64."""
    s = _as_float64("s", s)
    with np.errstate(invalid="ignore"):
        power = np.power((np.maximum(s, SRGB_THRESHOLD_ENCODED) + 0.055) / 1.055, 2.4)
    return np.where(s <= SRGB_THRESHOLD_ENCODED, s / 12.92, power)


def tonemap(x: Any, ev: float = 0.0) -> np.ndarray:
    """Tone-map linear HDR values to sRGB-encoded values in [0, 1] (spec anchors.md §1).

    ``y = clip(x · 2^ev, 0, 1)``, then :func:`srgb_encode`.

    Args:
        x: array of any shape (typically (H, W, C)), linear radiance.
        ev: exposure in stops (finite).

    Returns:
        float64 array of the shape of ``x``, values in [0, 1] (NaN where ``x`` is NaN).
    """
    ev = check_ev(ev)
    x = _as_float64("x", x)
    scaled = x * (2.0 ** ev) if ev != 0.0 else x
    return srgb_encode(np.clip(scaled, 0.0, 1.0))


# ---------------------------------------------------------------------------------------------
# Constants (spec anchors.md §1)
# ---------------------------------------------------------------------------------------------

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
#: How many references' HDR-FLIP exposures are remembered (least recently used evicted first).
HDRFLIP_CACHE_SIZE = 64

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


# ---------------------------------------------------------------------------------------------
# Input checks
# ---------------------------------------------------------------------------------------------

def check_pair(output: Any, reference: Any) -> tuple[np.ndarray, np.ndarray]:
    """Validate an (output, reference) pair and return both as float64 arrays.

    ``reference`` must be (H, W, C) or (H, W, T, C), non-empty and finite; ``output`` must have
    exactly its shape (it may hold NaN/Inf; the metrics turn that into NaN).

    Raises:
        DbenchInputError: naming ``output`` or ``reference`` and the expected shape.
    """
    ref = _as_real_array("reference", reference)
    if ref.ndim not in (3, 4):
        raise DbenchInputError("reference: expected shape (H, W, C) or (H, W, T, C), "
                               f"got {tuple(ref.shape)}")
    layout = "(H, W, C)" if ref.ndim == 3 else "(H, W, T, C)"
    ref = check_buffer("reference", ref, tuple(ref.shape), dtype=np.float64)
    if not np.all(np.isfinite(ref)):
        raise DbenchInputError(f"reference: contains NaN or Inf; expected finite values of shape "
                               f"{layout} = {tuple(ref.shape)}")
    out = _as_real_array("output", output)
    if tuple(out.shape) != tuple(ref.shape):
        raise DbenchInputError(f"output: expected shape {layout} = {tuple(ref.shape)} (the shape "
                               f"of reference), got {tuple(out.shape)}")
    out = check_buffer("output", out, tuple(ref.shape), dtype=np.float64)
    return out, ref


def _as_real_array(name: str, value: Any) -> np.ndarray:
    if value is None:
        raise DbenchInputError(f"{name}: missing; expected an array of shape (H, W, C) "
                               "or (H, W, T, C)")
    arr = np.asarray(value)
    if np.iscomplexobj(arr):
        raise DbenchInputError(f"{name}: expected a real array of shape (H, W, C) or "
                               f"(H, W, T, C), got dtype {arr.dtype}")
    return arr


def _finite(x: np.ndarray) -> bool:
    return bool(np.isfinite(x).all())


def _integrate(x: np.ndarray) -> np.ndarray:
    """(H, W, T, C) -> (H, W, C) by summing over T; (H, W, C) unchanged."""
    return x.sum(axis=2) if x.ndim == 4 else x


def _check_eps(eps: Any, name: str = "eps") -> float:
    try:
        value = float(eps)
    except (TypeError, ValueError):
        raise DbenchInputError(f"{name}: expected a finite number > 0, got {eps!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise DbenchInputError(f"{name}: expected a finite number > 0, got {eps!r}")
    return value


# ---------------------------------------------------------------------------------------------
# Pixel-wise (linear HDR) metrics
# ---------------------------------------------------------------------------------------------

def _err_sq(o: np.ndarray, r: np.ndarray) -> np.ndarray:
    d = o - r
    return d * d


def _err_rel_sq(o: np.ndarray, r: np.ndarray, eps: float) -> np.ndarray:
    d = o - r
    return d * d / (r * r + eps)


def _err_smape(o: np.ndarray, r: np.ndarray, eps: float) -> np.ndarray:
    return np.abs(o - r) / (np.abs(o) + np.abs(r) + eps)


def _err_rmae(o: np.ndarray, r: np.ndarray, eps: float) -> np.ndarray:
    return np.abs(o - r) / (np.abs(r) + eps)


def _pixel_map(name: str, o: np.ndarray, r: np.ndarray, eps: float | None) -> np.ndarray:
    if name in ("mse", "rmse"):
        return _err_sq(o, r)
    if name == "relmse":
        return _err_rel_sq(o, r, RELMSE_EPS if eps is None else eps)
    if name == "smape":
        return _err_smape(o, r, SMAPE_EPS if eps is None else eps)
    if name == "rmae":
        return _err_rmae(o, r, RMAE_EPS if eps is None else eps)
    raise AssertionError(name)


def _pixel_value(name: str, o: np.ndarray, r: np.ndarray, eps: float | None = None) -> float:
    if not _finite(o):
        return float("nan")
    value = float(np.mean(_pixel_map(name, o, r, eps)))
    return math.sqrt(value) if name == "rmse" else value


def mse(output: Any, reference: Any) -> float:
    """Mean squared error, mean((x − r)²), on linear values (spec anchors.md §1).

    Args:
        output, reference: (H, W, C) or (H, W, T, C), same shape; transient: the whole tensor.

    Returns:
        float (NaN if ``output`` holds NaN/Inf).
    """
    o, r = check_pair(output, reference)
    return _pixel_value("mse", o, r)


def rmse(output: Any, reference: Any) -> float:
    """Root mean squared error, sqrt(mean((x − r)²)), on linear values (anchors.md §1).

    Shapes as :func:`mse`. The only metric of seed 000 (per inset, linear).
    """
    o, r = check_pair(output, reference)
    return _pixel_value("rmse", o, r)


def relmse(output: Any, reference: Any, eps: float = RELMSE_EPS) -> float:
    """Relative MSE, mean((x − r)² / (r² + ε)), ε = 1e-2 by default (anchors.md §1).

    Shapes as :func:`mse`.
    """
    o, r = check_pair(output, reference)
    return _pixel_value("relmse", o, r, _check_eps(eps))


def smape(output: Any, reference: Any, eps: float = SMAPE_EPS) -> float:
    """SMAPE, mean(|x − r| / (|x| + |r| + ε)), ε = 1e-2, no factor 2 (anchors.md §1, as ProDen).

    Shapes as :func:`mse`.
    """
    o, r = check_pair(output, reference)
    return _pixel_value("smape", o, r, _check_eps(eps))


def rmae(output: Any, reference: Any, eps: float = RMAE_EPS) -> float:
    """Relative mean absolute error, mean(|x − r| / (|r| + 0.01)) (anchors.md §1).

    noisebase divides this by 3 for no stated reason; dbench does not. Shapes as :func:`mse`.
    """
    o, r = check_pair(output, reference)
    return _pixel_value("rmae", o, r, _check_eps(eps))


# ---------------------------------------------------------------------------------------------
# LDR metrics on tone-mapped images
# ---------------------------------------------------------------------------------------------

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
    """SSIM between two tone-mapped (H, W, C) images in [0, 1] (anchors.md §1).

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
    """PSNR in dB on tone-mapped images (anchors.md §1), capped at 100 dB.

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
    """SSIM on tone-mapped images (anchors.md §1); see :func:`ssim_ldr` for the small-image rule.

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
    """LDR-FLIP on tone-mapped sRGB images (anchors.md §1, §5).

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


# ---------------------------------------------------------------------------------------------
# HDR-FLIP with exposures fixed per reference (anchors.md §5)
# ---------------------------------------------------------------------------------------------

_EXPOSURES: OrderedDict[str, dict[str, Any]] = OrderedDict()
_EXPOSURES_LOCK = threading.Lock()


def _reference_key(ref32: np.ndarray) -> str:
    h = hashlib.blake2b(digest_size=16)
    h.update(repr(ref32.shape).encode())
    h.update(memoryview(ref32).cast("B"))
    return h.hexdigest()


def _cache_get(key: str) -> dict[str, Any] | None:
    with _EXPOSURES_LOCK:
        params = _EXPOSURES.get(key)
        if params is not None:
            _EXPOSURES.move_to_end(key)
            return dict(params)
    return None


def _cache_put(key: str, params: dict[str, Any]) -> None:
    with _EXPOSURES_LOCK:
        _EXPOSURES[key] = dict(params)
        _EXPOSURES.move_to_end(key)
        while len(_EXPOSURES) > HDRFLIP_CACHE_SIZE:
            _EXPOSURES.popitem(last=False)


def clear_exposure_cache() -> None:
    """Forget every reference's HDR-FLIP exposures (the next call computes them again)."""
    with _EXPOSURES_LOCK:
        _EXPOSURES.clear()


def _hdr_image(name: str, x: np.ndarray) -> np.ndarray:
    """Linear (H, W, C) -> float32 (H, W, 3), negative values clipped to 0 (HDR-FLIP needs >= 0)."""
    f32max = float(np.finfo(np.float32).max)
    return _flip_input(name, np.clip(x, 0.0, f32max))


def _max_luminance(ref32: np.ndarray) -> float:
    lum = (0.2126 * ref32[..., 0].astype(np.float64) + 0.7152 * ref32[..., 1]
           + 0.0722 * ref32[..., 2])
    return float(lum.max())


def _valid_exposures(p: dict[str, Any]) -> bool:
    try:
        start, stop, num = float(p["startExposure"]), float(p["stopExposure"]), int(p["numExposures"])
    except (KeyError, TypeError, ValueError):
        return False
    return math.isfinite(start) and math.isfinite(stop) and start <= stop and num >= 2


def _hdrflip_eval(test32: np.ndarray, ref32: np.ndarray) -> tuple[float, dict[str, Any]]:
    import flip_evaluator

    key = _reference_key(ref32)
    params = _cache_get(key)
    if params is None:
        if _max_luminance(ref32) < HDRFLIP_BLACK_LUMINANCE:
            # flip_evaluator would derive start = log2(c / 0) = inf > stop and terminate the
            # whole process (std::exit) instead of raising; use fixed exposures instead.
            params = dict(HDRFLIP_BLACK_EXPOSURES)
        else:
            _, mean, used = flip_evaluator.evaluate(ref32, test32, "HDR", inputsRGB=True,
                                                    applyMagma=False, computeMeanError=True,
                                                    parameters={})
            params = {"startExposure": float(used["startExposure"]),
                      "stopExposure": float(used["stopExposure"]),
                      "numExposures": int(used["numExposures"])}
            if _valid_exposures(params):
                _cache_put(key, params)
                return float(mean), dict(used)
            params = dict(HDRFLIP_BLACK_EXPOSURES)  # not expected; keep the run alive
        _cache_put(key, params)
    _, mean, used = flip_evaluator.evaluate(ref32, test32, "HDR", inputsRGB=True,
                                            applyMagma=False, computeMeanError=True,
                                            parameters=dict(params))
    return float(mean), dict(used)


def hdrflip(output: Any, reference: Any, *, return_params: bool = False
            ) -> float | tuple[float, dict[str, Any]]:
    """HDR-FLIP on linear values with exposures fixed per reference (anchors.md §1, §5).

    Negative values of both images are clipped to 0 (HDR-FLIP is defined on non-negative
    radiance); one channel is replicated to three. The start/stop exposures (and their count)
    are chosen by flip_evaluator from the reference on the first call for that reference, read
    back from the ``params`` it returns, remembered (keyed by a hash of the reference's float32
    bytes, last :data:`HDRFLIP_CACHE_SIZE` references) and passed explicitly to every later call,
    so all test images compared with one reference share the same exposures. A black reference
    (largest luminance < 1e-6), for which flip_evaluator would terminate the process, uses
    start = stop = 0.

    Args:
        output, reference: (H, W, C) or (H, W, T, C) with C = 1 or 3, same shape; transient:
            the sum over T.
        return_params: also return the parameter dict flip_evaluator used.

    Returns:
        the mean HDR-FLIP error (NaN if ``output`` holds NaN/Inf), or (error, params).
    """
    o, r = check_pair(output, reference)
    _check_flip_channels(r)
    if not _finite(o):
        return (float("nan"), {}) if return_params else float("nan")
    value, params = _hdrflip_eval(_hdr_image("output", _integrate(o)),
                                  _hdr_image("reference", _integrate(r)))
    return (value, params) if return_params else value


def hdrflip_exposures(reference: Any) -> dict[str, Any]:
    """The HDR-FLIP exposures used for ``reference``: startExposure, stopExposure, numExposures.

    Computes (and caches) them if no call has yet; the same values every :func:`hdrflip` call
    with this reference uses. ``reference``: (H, W, C) or (H, W, T, C), C = 1 or 3, finite.
    """
    _, r = check_pair(reference, reference)
    _check_flip_channels(r)
    ref32 = _hdr_image("reference", _integrate(r))
    params = _cache_get(_reference_key(ref32))
    if params is None:
        _hdrflip_eval(ref32, ref32)
        params = _cache_get(_reference_key(ref32))
    return dict(params)


# ---------------------------------------------------------------------------------------------
# By name
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class _Metric:
    kind: str                     # "pixel", "ldr" or "hdr"
    options: tuple[str, ...]      # accepted keyword options


_METRICS: dict[str, _Metric] = {
    "mse": _Metric("pixel", ()),
    "rmse": _Metric("pixel", ()),
    "relmse": _Metric("pixel", ("eps",)),
    "smape": _Metric("pixel", ("eps",)),
    "rmae": _Metric("pixel", ("eps",)),
    "psnr": _Metric("ldr", ("ev",)),
    "ssim": _Metric("ldr", ("ev",)),
    "flip": _Metric("ldr", ("ev",)),
    "hdrflip": _Metric("hdr", ()),
}
_LDR_FUNCS: dict[str, Callable[[np.ndarray, np.ndarray], float]] = {
    "psnr": psnr_ldr, "ssim": ssim_ldr, "flip": flip_ldr,
}
#: Metrics :func:`per_bin` can compute (the pixel-wise ones).
PER_BIN_METRICS = tuple(n for n, m in _METRICS.items() if m.kind == "pixel")


def available() -> list[str]:
    """Names of every metric, in report order."""
    return list(_METRICS)


def _lookup(name: Any) -> _Metric:
    key = str(name).lower() if isinstance(name, str) else name
    if key not in _METRICS:
        raise UnknownNameError(f"unknown metric {name!r}; valid names: {', '.join(_METRICS)}")
    return _METRICS[key]


def _check_options(name: str, metric: _Metric, options: dict[str, Any]) -> None:
    bad = [k for k in options if k not in metric.options]
    if bad:
        valid = ", ".join(metric.options) if metric.options else "none"
        raise UnknownNameError(f"metric {name!r}: unknown option(s) {', '.join(map(repr, bad))}; "
                               f"valid options: {valid}")


def _from_checked(name: str, o: np.ndarray, r: np.ndarray, options: dict[str, Any],
                  ldr: tuple[np.ndarray, np.ndarray] | None = None) -> float:
    """Metric ``name`` on validated arrays; ``ldr`` optionally holds the tone-mapped pair."""
    metric = _METRICS[name]
    if metric.kind == "pixel":
        eps = _check_eps(options["eps"]) if "eps" in options else None
        return _pixel_value(name, o, r, eps)
    if name in ("flip", "hdrflip"):
        _check_flip_channels(r)
    if not _finite(o):
        return float("nan")
    if metric.kind == "hdr":
        return _hdrflip_eval(_hdr_image("output", _integrate(o)),
                             _hdr_image("reference", _integrate(r)))[0]
    if ldr is None:
        ev = check_ev(options.get("ev", 0.0))
        ldr = (tonemap(_integrate(o), ev), tonemap(_integrate(r), ev))
    return _LDR_FUNCS[name](*ldr)


def compute(name: str, output: Any, reference: Any, **options: Any) -> float:
    """Compute one metric by name (see :data:`DEFINITIONS` and :func:`available`).

    Args:
        name: metric name, e.g. ``"rmse"`` (case-insensitive).
        output, reference: (H, W, C) or (H, W, T, C) arrays of the same shape, any real dtype.
        options: ``eps`` for relmse/smape/rmae, ``ev`` (tone-map exposure, stops) for
            psnr/ssim/flip.

    Returns:
        float; NaN if ``output`` holds NaN or Inf.

    Raises:
        UnknownNameError: unknown metric or option (the message lists the valid ones).
        DbenchInputError: bad shapes (naming ``output``/``reference``) or non-finite reference.
    """
    metric = _lookup(name)
    name = str(name).lower()
    _check_options(name, metric, options)
    o, r = check_pair(output, reference)
    return _from_checked(name, o, r, options)


def compute_all(output: Any, reference: Any, names: Iterable[str] | None = None, *,
                ev: float = 0.0) -> dict[str, float]:
    """Compute several metrics at once, tone-mapping each image once (default: all of them).

    Args:
        output, reference: (H, W, C) or (H, W, T, C), same shape.
        names: metric names (default :func:`available`), in the order of the returned dict.
        ev: tone-map exposure in stops for psnr/ssim/flip.

    Returns:
        {name: value}; every value NaN if ``output`` holds NaN or Inf.
    """
    names = available() if names is None else [str(n) for n in names]
    for n in names:
        _lookup(n)
    names = [n.lower() for n in names]
    ev = check_ev(ev)
    o, r = check_pair(output, reference)
    if any(n in ("flip", "hdrflip") for n in names):
        _check_flip_channels(r)
    ldr = None
    if _finite(o) and any(_METRICS[n].kind == "ldr" for n in names):
        ldr = (tonemap(_integrate(o), ev), tonemap(_integrate(r), ev))
    return {n: _from_checked(n, o, r, {"ev": ev} if _METRICS[n].kind == "ldr" else {}, ldr)
            for n in names}


def per_bin(name: str, output: Any, reference: Any, **options: Any) -> np.ndarray:
    """A pixel-wise metric per time bin of transient data.

    Args:
        name: one of :data:`PER_BIN_METRICS` (mse, rmse, relmse, smape, rmae).
        output, reference: (H, W, T, C), same shape.
        options: ``eps`` for relmse/smape/rmae.

    Returns:
        float64 array of shape (T,): the metric over the (H, W, C) slice of each bin; NaN for the
        bins where ``output`` holds NaN or Inf.
    """
    metric = _lookup(name)
    name = str(name).lower()
    if metric.kind != "pixel":
        raise UnknownNameError(f"per_bin: metric {name!r} is not pixel-wise; valid names: "
                               f"{', '.join(PER_BIN_METRICS)}")
    _check_options(name, metric, options)
    o, r = check_pair(output, reference)
    if r.ndim != 4:
        raise DbenchInputError(f"reference: per_bin needs transient data of shape (H, W, T, C), "
                               f"got {tuple(r.shape)}")
    eps = _check_eps(options["eps"]) if "eps" in options else None
    bad = ~np.isfinite(o).all(axis=(0, 1, 3))
    with np.errstate(invalid="ignore", over="ignore"):
        values = _pixel_map(name, o, r, eps).mean(axis=(0, 1, 3))
    if name == "rmse":
        values = np.sqrt(values)
    values[bad] = np.nan
    return values
