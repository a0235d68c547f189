"""The learned models' input and output passes as PyTorch operations, for their device paths
(``Denoiser.denoise_device``, :mod:`dbench.device`): every step runs on the tensors' device, with
no conversion to NumPy and no read-back of a value to the host.

Each function is the torch form of a NumPy/Numba pass the host path runs, with the same
arithmetic (float64 where the host computes in float64, the same clamps and the same order):

* :func:`autoexposure` — :func:`dbench.methods.kernels.hdr_input.autoexposure` (OIDN's
  auto-exposure over 16×16 blocks), returned as a 0-dim float64 tensor instead of a float, so
  that no ``.item()`` waits for the device; 1 for a black image, chosen with ``torch.where``.
* :func:`encode_planar` — :func:`dbench.methods.kernels.learned_input.encode_planar` (the
  sanitised, exposed, demodulated ``log1p`` colour and the feature planes, replicate-padded).
* :func:`decode_planar` — :func:`dbench.methods.kernels.learned_input.decode_planar`
  (``max(expm1(min(x, 80)), 0) · a_eff / exposure``, non-finite x as 0).
* :func:`keep_emitters` — :func:`dbench.methods.kernels.emitters.keep_emitters` over the whole
  image with ``torch.where`` (the host version gathers the covered pixels with ``np.nonzero``,
  which on a device would wait for the count).
* :func:`float32_precision` — the convolutions and products in IEEE float32 for the duration of
  a call: cuDNN's default TF32 convolutions changed the autoencoder's output by 6.5e-2 on an
  H200, far from the host's numbers.

Shapes: images (H, W, C) float32 as in :mod:`dbench.device`; planar network inputs (C, H', W').
The repository's architecture notes (docs/architecture.md) list this module with the other
kernels. A kernel imports no method and nothing of the harness.

Example:
    >>> import torch
    >>> round(float(autoexposure(torch.full((32, 32, 3), 0.36))), 6)
    0.5
"""
from __future__ import annotations

from contextlib import contextmanager
from typing import Iterator, Sequence

import numpy as np
import torch
import torch.nn.functional as F

from ...errors import DbenchInputError
from .hdr_input import EXPOSURE_BLOCK, EXPOSURE_KEY, LUMINANCE
from .learned_input import ALBEDO_EPS

_F32_MAX = float(np.finfo(np.float32).max)
#: the decoder's cap on the log-space output (expm1(80) ≈ 5.5e34), as in the host decoders
LOG_CAP = 80.0


def check_tensor(name: str, t, channels: int, hw: tuple[int, int] | None = None
                 ) -> torch.Tensor:
    """``t`` as an (H, W, channels) float32 tensor (a 2-D depth gains its channel axis), or a
    DbenchInputError naming the buffer; ``hw`` fixes H and W (those of the colour). Shapes only:
    nothing is read from the device."""
    shape = f"(H, W, {channels})" if hw is None else f"({hw[0]}, {hw[1]}, {channels})"
    if t is None:
        raise DbenchInputError(f"{name}: missing; expected a tensor of shape {shape}")
    if not isinstance(t, torch.Tensor):
        raise DbenchInputError(f"{name}: expected a torch tensor of shape {shape} (a "
                               f"DeviceFrame from dbench.device.upload), got {type(t).__name__}")
    if t.ndim == 2 and channels == 1:
        t = t[..., None]
    if t.ndim != 3 or t.shape[2] != channels or (hw is not None and tuple(t.shape[:2]) != hw):
        raise DbenchInputError(f"{name}: expected shape {shape}, got {tuple(t.shape)}")
    if t.numel() == 0:
        raise DbenchInputError(f"{name}: empty tensor of shape {tuple(t.shape)}; expected "
                               f"{shape} with every dimension > 0")
    if t.is_complex():
        raise DbenchInputError(f"{name}: expected a real tensor, got dtype {t.dtype}")
    return t.to(torch.float32)


def _clean(x: torch.Tensor, lo: float, hi: float) -> torch.Tensor:
    """Non-finite → 0, then clipped to [lo, hi] (the codecs' ``sanitize``)."""
    return torch.where(torch.isfinite(x), x, torch.zeros((), dtype=x.dtype, device=x.device)
                       ).clamp(lo, hi)


def autoexposure(color: torch.Tensor, block: int = EXPOSURE_BLOCK) -> torch.Tensor:
    """Exposure of an (H, W, 3) linear image as a 0-dim float64 tensor on its device:
    key / exp(mean log L) over the block-averaged Rec. 709 luminances L > 1e-8 (edge blocks
    averaged over their pixels), 1 for a black image; non-finite and negative values count as
    0. Float64 throughout, as the compiled host pass."""
    c = color.to(torch.float64)
    c = torch.where(torch.isfinite(c) & (c > 0), c, torch.zeros((), dtype=c.dtype,
                                                                 device=c.device))
    # the host adds the channels in this order, each term a float64 product
    lum = c[..., 0] * LUMINANCE[0] + c[..., 1] * LUMINANCE[1] + c[..., 2] * LUMINANCE[2]
    h, w = lum.shape
    bh, bw = -(-h // block), -(-w // block)
    sums = F.pad(lum, (0, bw * block - w, 0, bh * block - h)).reshape(bh, block, bw, block)
    sums = sums.sum(dim=(1, 3))
    # pixels per block from the shape alone (on the device: no host-to-device copy)
    ry = (h - torch.arange(bh, device=c.device, dtype=torch.float64) * block).clamp(max=block)
    rx = (w - torch.arange(bw, device=c.device, dtype=torch.float64) * block).clamp(max=block)
    means = (sums / (ry[:, None] * rx[None, :])).reshape(-1)
    lit = means > 1e-8
    n = lit.sum()
    logs = torch.where(lit, torch.log(torch.where(lit, means, torch.ones_like(means))),
                       torch.zeros_like(means))
    mean_log = logs.sum() / n.clamp(min=1)
    one = torch.ones((), dtype=torch.float64, device=c.device)
    return torch.where(n > 0, EXPOSURE_KEY / torch.exp(mean_log), one)


def effective_albedo(albedo: torch.Tensor, demodulate: bool = True) -> torch.Tensor:
    """(H, W, 3) a_eff: the sanitised albedo where it exceeds 1e-3, else 1 (all 1 without
    ``demodulate``)."""
    a = _clean(albedo, 0.0, 1.0)
    if not demodulate:
        return torch.ones_like(a)
    return torch.where(a > ALBEDO_EPS, a, torch.ones((), dtype=a.dtype, device=a.device))


def encode_planar(color: torch.Tensor, buffers: dict, features: Sequence[str],
                  exposure: torch.Tensor, multiple: int = 1, demodulate: bool = True
                  ) -> tuple[torch.Tensor, torch.Tensor]:
    """(x (C, H', W') float32, H' and W' the next multiples of ``multiple``, padding repeating
    the last row and column; a_eff (H, W, 3)). ``color`` (H, W, 3); ``buffers`` holds (H, W, 3)
    ``albedo`` and, as ``features`` ask, (H, W, 3) ``normal``, (H, W, 1) ``depth`` and a number
    ``level`` (a host value from the frame's metadata); ``exposure`` a 0-dim tensor."""
    c = _clean(color, 0.0, float("inf"))
    # the host multiplies in float64 and clips to the float32 maximum before rounding; with an
    # exposure of exactly 1 this returns c unchanged, so no branch on its value is needed
    c = _clean(c.to(torch.float64) * exposure.to(torch.float64), 0.0, _F32_MAX).to(torch.float32)
    a_eff = effective_albedo(buffers["albedo"], demodulate)
    q = c / a_eff
    # where the float32 quotient overflows (colour near 3.4e38 over a dark albedo), log1p of
    # the float64 quotient, at most ≈ 95 (guards.log_demodulated)
    big = torch.log1p(c.to(torch.float64) / a_eff.to(torch.float64)).to(torch.float32)
    chans = [torch.where(torch.isinf(q), big, torch.log1p(q))]
    for f in features:
        if f == "normal":
            chans.append(_clean(buffers["normal"], -1.0, 1.0))
        elif f == "albedo":
            chans.append(_clean(buffers["albedo"], 0.0, 1.0))
        elif f == "depth":
            d = _clean(buffers["depth"], 0.0, float("inf"))
            scale = d.amax()  # ≥ 0: the largest finite depth, 0 when there is none
            safe = torch.where(scale > 0, scale, torch.ones_like(scale))
            chans.append(torch.where(scale > 0, d / safe, d))
        elif f == "level":
            chans.append(torch.full((*c.shape[:2], 1), float(np.float32(buffers["level"])),
                                    dtype=torch.float32, device=c.device))
        else:
            raise ValueError(f"unknown feature {f!r}; valid: normal, albedo, depth, level")
    x = torch.cat(chans, dim=-1).permute(2, 0, 1)
    h, w = c.shape[:2]
    ph, pw = (-h) % multiple, (-w) % multiple
    if ph or pw:
        x = F.pad(x[None], (0, pw, 0, ph), mode="replicate")[0]
    return x.contiguous(), a_eff


def decode_planar(state_rgb: torch.Tensor, a_eff: torch.Tensor | None,
                  exposure: torch.Tensor) -> torch.Tensor:
    """(3, H', W') log-space RGB → (H, W, 3) float32 linear radiance, H and W those of
    ``a_eff`` (or of the state when it is None: no remodulation):
    max(expm1(min(x, 80)), 0) · a_eff / float32(exposure), non-finite x as 0."""
    h, w = (state_rgb.shape[1:] if a_eff is None else a_eff.shape[:2])
    x = state_rgb[:, :h, :w].permute(1, 2, 0).clamp(max=LOG_CAP)
    x = torch.where(torch.isfinite(x), x, torch.zeros((), dtype=x.dtype, device=x.device))
    out = torch.expm1(x).clamp(min=0.0)
    if a_eff is not None:
        out = out * a_eff
    # the host divides by the exposure rounded to float32 (by nothing when it is 1: x / 1 = x)
    return (out / exposure.to(torch.float32)).contiguous()


def keep_emitters(color: torch.Tensor, out: torch.Tensor, emitter: torch.Tensor | None
                  ) -> torch.Tensor:
    """out + e (color − out) with e the (H, W, 1) emitter coverage clipped to 1 (non-finite or
    ≤ 0: the output stays), exactly the input where e ≥ 1, the output where the input colour is
    not finite; ``out`` itself when there is no emitter buffer."""
    if emitter is None:
        return out
    h, w = out.shape[:2]
    if tuple(emitter.shape) != (h, w, 1):
        raise DbenchInputError(f"emitter: expected shape ({h}, {w}, 1), got "
                               f"{tuple(emitter.shape)}")
    e = emitter.to(torch.float32)
    on = torch.isfinite(e) & (e > 0)
    cov = torch.where(on, e.clamp(max=1.0), torch.zeros((), device=e.device))
    target = torch.where(torch.isfinite(color), color, out)
    mixed = torch.where(cov >= 1, target, out + cov * (target - out))
    return torch.where(on, mixed, out)


@contextmanager
def float32_precision() -> Iterator[None]:
    """Convolutions and matrix products in IEEE float32 inside the block (no TF32), the
    previous settings restored afterwards. PyTorch ≥ 2.9 has the ``fp32_precision`` settings
    and refuses to read the legacy ``allow_tf32`` flags once they were mixed with them, so
    those are used where they exist, the legacy flags elsewhere."""
    conv = getattr(torch.backends.cudnn, "conv", None)
    new_api = conv is not None and hasattr(conv, "fp32_precision") and hasattr(
        torch.backends.cuda.matmul, "fp32_precision")
    if new_api:
        saved = (conv.fp32_precision, torch.backends.cuda.matmul.fp32_precision)
        conv.fp32_precision = "ieee"
        torch.backends.cuda.matmul.fp32_precision = "ieee"
    else:
        saved = (torch.backends.cudnn.allow_tf32, torch.backends.cuda.matmul.allow_tf32)
        torch.backends.cudnn.allow_tf32 = False
        torch.backends.cuda.matmul.allow_tf32 = False
    try:
        yield
    finally:
        if new_api:
            conv.fp32_precision, torch.backends.cuda.matmul.fp32_precision = saved
        else:
            torch.backends.cudnn.allow_tf32, torch.backends.cuda.matmul.allow_tf32 = saved


__all__ = ["LOG_CAP", "autoexposure", "check_tensor", "decode_planar", "effective_albedo",
           "encode_planar", "float32_precision", "keep_emitters"]
