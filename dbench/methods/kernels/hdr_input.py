"""Inputs the learned denoisers share so that one network serves every exposure and noise level
(OIDN's approach for HDR input, plus the sample count dbench always knows).

* :func:`autoexposure` — OIDN's auto-exposure: the image is averaged over 16×16-pixel blocks, and
  the exposure is key / (geometric mean of the block luminances above 1e-8), key = 0.18; 1 when
  every block is black. The networks read ``log1p(exposure · colour)`` and their output is
  divided by the exposure again, so scaling an input image by s scales the output by s.
* :func:`noise_level` — ``log2(spp) / 10``: 0 at 1 spp, 1 at 1024 spp. The networks receive it
  (the NCA through its step size, the autoencoder as an input channel) so that they can leave a
  converged image alone; without it a network trained at 1-8 spp blurs a 1024-spp image.
* :func:`frame_spp` — the sample count of a frame: the method's ``spp`` parameter when given,
  else ``data.meta["spp"]`` (every dbench loader records it), else None.

Example:
    >>> import numpy as np
    >>> round(autoexposure(np.full((32, 32, 3), 0.36, np.float32)), 6)
    0.5
    >>> noise_level(1024)
    1.0
"""
from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit, prange

from ...errors import DbenchInputError
from .arrays import kernel_input

EXPOSURE_KEY = 0.18
EXPOSURE_BLOCK = 16
#: Rec. 709 luminance weights (what OIDN uses for its auto-exposure).
LUMINANCE = np.array([0.2126, 0.7152, 0.0722], np.float64)


def autoexposure(color: np.ndarray, block: int = EXPOSURE_BLOCK) -> float:
    """Exposure of an (H, W, 3) linear image (or a batch (..., H, W, 3): one value for all):
    key / exp(mean log L) over the block-averaged luminances L > 1e-8; 1.0 for a black image.
    Non-finite and negative values count as 0. A single image goes through one compiled pass
    (:func:`_block_means_nb`, 1 ms instead of 17-22 ms at 720p), equal to
    :func:`autoexposure_reference` within 1e-12 relative (tests)."""
    c = np.asarray(color)
    if c.ndim != 3 or c.shape[-1] != 3 or c.size == 0:
        return autoexposure_reference(color, block)
    means = _block_means_nb(kernel_input(c, np.float32 if c.dtype == np.float32 else np.float64),
                            int(block), LUMINANCE)
    return _exposure_from_means(means)


def _exposure_from_means(means: np.ndarray) -> float:
    """key / exp(mean log L) over the block means L > 1e-8; 1.0 when there is none."""
    means = means[means > 1e-8]
    if means.size == 0:
        return 1.0
    return float(EXPOSURE_KEY / np.exp(np.mean(np.log(means))))


@njit(parallel=True, cache=True)
def _block_means_nb(color, block, luma):  # pragma: no cover - compiled
    """Mean Rec. 709 luminance (float64) of each block × block tile of an (H, W, 3) image
    (edge tiles over their pixels only), non-finite and negative values as 0."""
    h, w = color.shape[0], color.shape[1]
    bh, bw = -(-h // block), -(-w // block)
    means = np.empty(bh * bw, np.float64)
    for t in prange(bh * bw):
        by, bx = t // bw, t % bw
        y0, x0 = by * block, bx * block
        y1, x1 = min(y0 + block, h), min(x0 + block, w)
        acc = 0.0
        for y in range(y0, y1):
            for x in range(x0, x1):
                lum = 0.0
                for k in range(3):
                    v = np.float64(color[y, x, k])
                    if np.isfinite(v) and v > 0:
                        lum += luma[k] * v
                acc += lum
        means[t] = acc / ((y1 - y0) * (x1 - x0))
    return means


def autoexposure_reference(color: np.ndarray, block: int = EXPOSURE_BLOCK) -> float:
    """The readable NumPy form of :func:`autoexposure` (any leading batch dimensions)."""
    c = np.asarray(color, np.float64)
    c = np.where(np.isfinite(c) & (c > 0), c, 0.0)
    lum = c @ LUMINANCE
    lum = lum.reshape(-1, *lum.shape[-2:])
    h, w = lum.shape[-2:]
    bh, bw = -(-h // block), -(-w // block)
    pad = np.zeros((lum.shape[0], bh * block, bw * block))
    pad[:, :h, :w] = lum
    counts = np.zeros((bh * block, bw * block))
    counts[:h, :w] = 1.0
    sums = pad.reshape(-1, bh, block, bw, block).sum(axis=(2, 4))
    return _exposure_from_means(sums / counts.reshape(bh, block, bw, block).sum(axis=(1, 3)))


def noise_level(spp: Any) -> float:
    """log2(spp) / 10 for a sample count ≥ 1 (0 at 1 spp, 1 at 1024 spp)."""
    s = float(spp)
    if not np.isfinite(s) or s < 1:
        raise DbenchInputError(f"spp: expected a sample count >= 1, got {spp!r}")
    return float(np.log2(s) / 10.0)


def check_run_options(params: dict[str, Any]) -> None:
    """The learned methods' ``threads`` (None, or an integer >= 1) and ``spp`` (None, or a
    sample count >= 1, :func:`noise_level`) in ``params``, checked when the method is built,
    before anything renders, rather than on its first frame; DbenchInputError naming the
    parameter."""
    threads = params.get("threads")
    if threads is not None and (isinstance(threads, (bool, np.bool_))
                                or not isinstance(threads, (int, np.integer)) or threads < 1):
        raise DbenchInputError(f"threads: expected an integer >= 1 (None: the runtime's "
                               f"default), got {threads!r}")
    spp = params.get("spp")
    if spp is not None:
        if isinstance(spp, (bool, np.bool_)) or not isinstance(spp, (int, float, np.number)):
            raise DbenchInputError(f"spp: expected a sample count >= 1, got {spp!r}")
        noise_level(spp)


def frame_spp(data: Any, given: Any = None) -> float | None:
    """The sample count behind ``data.color``: ``given`` (a method parameter) when not None,
    else ``data.meta["spp"]``, else None."""
    if given is not None:
        noise_level(given)  # validates
        return float(given)
    meta = getattr(data, "meta", None) or {}
    spp = meta.get("spp")
    return None if spp is None else float(spp)


__all__ = ["EXPOSURE_KEY", "autoexposure", "check_run_options", "frame_spp", "noise_level"]
