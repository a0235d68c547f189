"""Training losses (docs/methods/autoencoder.md §3, docs/methods/nca.md §5), on (N, 3, H, W) tensors.

All losses are means over pixels and channels and are computed by the callers on log1p-encoded
RGB (spec: "losses are computed on the log1p-encoded, remodulated RGB").

* ``l1`` L_s = mean |P - T|;  ``mse`` mean (P - T)².
* ``gradient_loss`` (seed form, "sobel_of_gaussian"): L_g = mean |Sx(g*T) - Sx(g*P)| +
  mean |Sy(g*T) - Sy(g*P)|, g the 3x3 Gaussian (1,2,1)ᵀ(1,2,1)/16 and Sx, Sy the Sobel kernels /8
  of docs/methods/nca.md §2, replicate padding.
* ``hfen`` (the RAE's HFEN form, "log"): mean |LoG * P - LoG * T| with a 9x9
  Laplacian-of-Gaussian, σ = 1.5, shifted to sum 0 (an L1 form of the high-frequency error norm).
* ``temporal_loss`` L_t = mean |(T_i - T_{i-1}) - (P_i - P_{i-1})| over a sequence (N, F, 3, H, W).
* ``FRAME_WEIGHTS``: the RAE's per-frame weights inside a 7-frame sequence.
* ``clamped_linear_mse``: an optional [dbench] term on linear radiance clamped at 64, for the
  configurations that add one (``linear_weight`` in :mod:`dbench.learn.configs`).
* ``relative_linear_mse``: an optional [dbench] term, the output's linear MSE relative to the
  noisy input's, per crop (``relative_weight``).

Example:
    >>> import torch
    >>> p = torch.rand(2, 3, 16, 16)
    >>> float(l1(p, p)), float(gradient_loss(p, p)), float(hfen(p, p))
    (0.0, 0.0, 0.0)
"""
from __future__ import annotations

import numpy as np
import torch
from kornia.filters import filter2d

FRAME_WEIGHTS = (0.011, 0.044, 0.135, 0.325, 0.607, 0.882, 1.0)
AE_WEIGHTS = {"l1": 0.8, "hfen": 0.1, "temporal": 0.1}  # docs/methods/autoencoder.md §3 [RAE]
NCA_WEIGHTS = {"mse": 1.0, "grad": 0.5}  # docs/methods/nca.md §5 [dbench]

_GAUSS = np.outer([1, 2, 1], [1, 2, 1]).astype(np.float32) / 16.0
_SOBEL_X = np.array([[-1, 0, 1], [-2, 0, 2], [-1, 0, 1]], np.float32) / 8.0


def log_kernel(size: int = 9, sigma: float = 1.5) -> np.ndarray:
    """Laplacian-of-Gaussian kernel (size x size), shifted so its entries sum to 0."""
    r = np.arange(size, dtype=np.float64) - (size - 1) / 2
    y, x = np.meshgrid(r, r, indexing="ij")
    q = (x * x + y * y) / (2 * sigma * sigma)
    k = (q - 1.0) / (np.pi * sigma ** 4) * np.exp(-q)
    k -= k.mean()
    return k.astype(np.float32)


_LOG = log_kernel()


def _check(name: str, x: torch.Tensor) -> None:
    if x.ndim != 4:
        raise ValueError(f"{name}: expected (N, C, H, W), got {tuple(x.shape)}")


def _filt(x: torch.Tensor, k: np.ndarray) -> torch.Tensor:
    return filter2d(x, torch.as_tensor(k, dtype=x.dtype, device=x.device)[None],
                    border_type="replicate")


def l1(p: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    return (p - t).abs().mean()


def mse(p: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    return ((p - t) ** 2).mean()


def gradient_loss(p: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """Sobel gradients of the 3x3-Gaussian-blurred images, L1, x and y terms summed."""
    _check("prediction", p)
    _check("target", t)
    gp, gt = _filt(p, _GAUSS), _filt(t, _GAUSS)
    return ((_filt(gp, _SOBEL_X) - _filt(gt, _SOBEL_X)).abs().mean()
            + (_filt(gp, _SOBEL_X.T.copy()) - _filt(gt, _SOBEL_X.T.copy())).abs().mean())


def hfen(p: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """L1 of the Laplacian-of-Gaussian-filtered difference (9x9, σ = 1.5)."""
    _check("prediction", p)
    _check("target", t)
    return _filt(p - t, _LOG).abs().mean()


def temporal_loss(p: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """(N, F, C, H, W) sequences; 0 when F < 2."""
    if p.ndim != 5 or p.shape != t.shape:
        raise ValueError(f"sequences: expected equal (N, F, C, H, W), got {tuple(p.shape)} "
                         f"and {tuple(t.shape)}")
    if p.shape[1] < 2:
        return p.new_zeros(())
    return ((t[:, 1:] - t[:, :-1]) - (p[:, 1:] - p[:, :-1])).abs().mean()


def clamped_linear_mse(p_log: torch.Tensor, t_log: torch.Tensor, clamp: float = 64.0
                       ) -> torch.Tensor:
    """mean (min(expm1(P), c) - min(expm1(T), c))² on log1p-encoded inputs: a linear-radiance
    term (what RMSE measures) with values above ``clamp`` cut so fireflies cannot dominate."""
    pl = torch.expm1(p_log.clamp(max=20.0)).clamp(max=clamp)
    tl = torch.expm1(t_log.clamp(max=20.0)).clamp(max=clamp)
    return ((pl - tl) ** 2).mean()


def relative_linear_mse(p_log: torch.Tensor, t_log: torch.Tensor, noisy: torch.Tensor,
                        clamp: float = 64.0, eps: float = 1e-3, metric: str = "mse"
                        ) -> torch.Tensor:
    """Mean over the batch of (error of the output) / (error of the noisy input + eps), per
    (N, 3, H, W) crop, on linear radiance clamped at ``clamp``: the training form of "beat the
    input on every image". A crop whose input is already nearly right (flat texture, converged
    pixels) weighs as much as one full of fireflies, and blurring a visible light, which costs
    far more than the light edge's own sample noise, is punished in proportion.

    ``metric`` "mse": the error is the linear MSE. "relmse": the relative MSE
    mean((x − r)² / (r² + 1e-2)) that dbench's verdicts rank HDR images by
    (dbench.metrics.pixel.relmse); its per-crop value is bounded below by the sample noise of
    the pixels' relative values, not by the crop's brightness, so ``eps`` can be small enough
    (1e-6) that a converged crop's ratio is its ratio, where with "mse" a dark crop's input
    error of 1e-9 turns the ratio's gradient into spikes."""
    if metric not in ("mse", "relmse"):
        raise ValueError(f"metric: expected 'mse' or 'relmse', got {metric!r}")
    pl = torch.expm1(p_log.clamp(max=20.0)).clamp(max=clamp)
    tl = torch.expm1(t_log.clamp(max=20.0)).clamp(max=clamp)
    nl = noisy.clamp(min=0.0, max=clamp)
    scale = 1.0 / (tl * tl + 1e-2) if metric == "relmse" else 1.0
    out = ((pl - tl) ** 2 * scale).mean(dim=(1, 2, 3))
    base = ((nl - tl) ** 2 * scale).mean(dim=(1, 2, 3))
    return (out / (base + eps)).mean()


def frame_weights(n_frames: int) -> torch.Tensor:
    """The last ``n_frames`` of FRAME_WEIGHTS (1.0 for a single frame)."""
    if not 1 <= n_frames <= len(FRAME_WEIGHTS):
        raise ValueError(f"n_frames: expected 1..{len(FRAME_WEIGHTS)}, got {n_frames}")
    return torch.tensor(FRAME_WEIGHTS[-n_frames:], dtype=torch.float32)


def autoencoder_loss(p: torch.Tensor, t: torch.Tensor, weights: dict | None = None
                     ) -> tuple[torch.Tensor, dict[str, float]]:
    """0.8 L1 + 0.1 HFEN + 0.1 L_t on (N, F, 3, H, W) sequences (F = 1: single frames, L_t = 0);
    spatial terms weighted per frame by :func:`frame_weights` (normalised to sum 1)."""
    w = {**AE_WEIGHTS, **(weights or {})}
    n_frames = p.shape[1]
    fw = frame_weights(n_frames)
    fw = fw / fw.sum()
    ls = sum(fw[i] * l1(p[:, i], t[:, i]) for i in range(n_frames))
    lg = sum(fw[i] * hfen(p[:, i], t[:, i]) for i in range(n_frames))
    lt = temporal_loss(p, t)
    total = w["l1"] * ls + w["hfen"] * lg + w["temporal"] * lt
    return total, {"l1": float(ls.detach()), "hfen": float(lg.detach()),
                   "temporal": float(lt.detach())}


def nca_loss(p: torch.Tensor, t: torch.Tensor, weights: dict | None = None
             ) -> tuple[torch.Tensor, dict[str, float]]:
    """MSE + 0.5 L_g (docs/methods/nca.md §5) on (N, 3, H, W)."""
    w = {**NCA_WEIGHTS, **(weights or {})}
    lm, lg = mse(p, t), gradient_loss(p, t)
    return w["mse"] * lm + w["grad"] * lg, {"mse": lm.item(), "grad": lg.item()}
