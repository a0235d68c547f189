"""HDR-FLIP with exposures fixed once per reference (docs/metrics.md §5), remembered for the
``HDRFLIP_CACHE_SIZE`` most recent references."""
from __future__ import annotations

import hashlib
import math
import threading
from collections import OrderedDict
from typing import Any

import numpy as np

from .checks import _finite, _integrate, check_pair
from .ldr import _check_flip_channels, _flip_input
from .params import HDRFLIP_BLACK_EXPOSURES, HDRFLIP_BLACK_LUMINANCE
#: How many references' HDR-FLIP exposures are remembered (least recently used evicted first).
HDRFLIP_CACHE_SIZE = 64
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


def _hdrflip_value(o: np.ndarray, r: np.ndarray) -> float:
    """HDR-FLIP of checked linear arrays (transient: the sum over T)."""
    return _hdrflip_eval(_hdr_image("output", _integrate(o)),
                         _hdr_image("reference", _integrate(r)))[0]


def hdrflip(output: Any, reference: Any, *, return_params: bool = False
            ) -> float | tuple[float, dict[str, Any]]:
    """HDR-FLIP on linear values with exposures fixed per reference (docs/metrics.md §1, §5).

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
