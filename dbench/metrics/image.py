"""Image metrics: MSE, RMSE, relMSE, SMAPE, rMAE, PSNR, SSIM, LDR-FLIP and HDR-FLIP.

Definitions and constants follow docs/metrics.md §1 (metrics), §5 (FLIP usage) and are checked by
the tests of §6. Each metric is a plain function ``metric(output, reference, **options) -> float``
on NumPy arrays (scikit-image style); :func:`compute` picks one by name and :func:`compute_all`
computes several, tone-mapping each image once. The metrics live in ``pixel.py`` (linear),
``ldr.py`` (PSNR, SSIM, LDR-FLIP) and ``hdr.py``, with ``tonemapping.py``, ``params.py``
(constants), ``records.py`` (one record per metric: its formula, direction and definition)
and ``checks.py`` (inputs); this module calls them by name through the records.

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

from collections.abc import Iterable
from typing import Any

import numpy as np

from ..errors import DbenchInputError, UnknownNameError
from .checks import _check_eps, _finite, _integrate, check_pair
from .ldr import _check_flip_channels
from .records import METRICS, Metric, image_metrics
from .tonemapping import check_ev, tonemap


def _pixel_wise(m: Metric) -> bool:
    """The mean of a per-value error map over linear values (per_bin can split it by bin)."""
    return m.domain == "hdr" and m.error_map is not None


def _options(m: Metric) -> tuple[str, ...]:
    """The keyword options ``compute`` accepts for ``m``."""
    if m.domain == "ldr":
        return ("ev",)
    return ("eps",) if m.eps is not None and _pixel_wise(m) else ()


#: Metrics :func:`per_bin` can compute (the pixel-wise ones).
PER_BIN_METRICS = tuple(n for n in image_metrics() if _pixel_wise(METRICS[n]))


def available() -> list[str]:
    """Names of every metric, in report order."""
    return list(image_metrics())


def _lookup(name: Any) -> Metric:
    key = str(name).lower() if isinstance(name, str) else name
    names = image_metrics()
    if key not in names:
        raise UnknownNameError(f"unknown metric {name!r}; valid names: {', '.join(names)}")
    return METRICS[key]


def _check_options(name: str, metric: Metric, options: dict[str, Any]) -> None:
    valid = _options(metric)
    bad = [k for k in options if k not in valid]
    if bad:
        valid_text = ", ".join(valid) if valid else "none"
        raise UnknownNameError(f"metric {name!r}: unknown option(s) {', '.join(map(repr, bad))}; "
                               f"valid options: {valid_text}")


def _check_channels(m: Metric, r: np.ndarray) -> None:
    if m.channels:
        _check_flip_channels(r)


def _from_checked(name: str, o: np.ndarray, r: np.ndarray, options: dict[str, Any],
                  ldr: tuple[np.ndarray, np.ndarray] | None = None) -> float:
    """Metric ``name`` on validated arrays; ``ldr`` optionally holds the tone-mapped pair."""
    metric = METRICS[name]
    if _pixel_wise(metric):
        eps = _check_eps(options["eps"]) if "eps" in options else None
        if not _finite(o):
            return float("nan")
        value = float(np.mean(metric.errors(o, r, eps)))
        return value if metric.from_mean is None else float(metric.from_mean(value))
    _check_channels(metric, r)
    if not _finite(o):
        return float("nan")
    if metric.domain == "hdr":
        return metric.image_fn(o, r)
    if ldr is None:
        ev = check_ev(options.get("ev", 0.0))
        ldr = (tonemap(_integrate(o), ev), tonemap(_integrate(r), ev))
    return metric.image_fn(*ldr)


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
    for n in names:
        _check_channels(METRICS[n], r)
    ldr = None
    if _finite(o) and any(METRICS[n].domain == "ldr" for n in names):
        ldr = (tonemap(_integrate(o), ev), tonemap(_integrate(r), ev))
    return {n: _from_checked(n, o, r, {"ev": ev} if METRICS[n].domain == "ldr" else {}, ldr)
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
    if not _pixel_wise(metric):
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
        values = metric.errors(o, r, eps).mean(axis=(0, 1, 3))
    if metric.from_mean is not None:
        values = metric.from_mean(values)
    values[bad] = np.nan
    return values
