"""TNND, the tiny neural cellular automaton denoiser, in PyTorch: the readable reference
(docs/methods/nca.md).

State (docs/methods/nca.md §1): per pixel s = [R, G, B, N_x, N_y, N_z, A_x, A_y, A_z], shape (N, 9, H, W), with
RGB as ``log1p`` of linear radiance, normals in [-1, 1], albedo in [0, 1] (docs/methods/nca.md §3, colour
scaling).

Perception (docs/methods/nca.md §2): 39 channels, in this order: identity (9), Gaussian K_g on RGB (3),
Laplacian K_l (9), Sobel-x K_sx (9), Sobel-y K_sy (9); fixed 3x3 kernels applied with kornia's
``filter2d`` (cross-correlation) and replicate padding.

Update (docs/methods/nca.md §3): s <- s + sigmoid(p · W) + b, W (39, 9), b (9,): 351 + 9 = 360 trainable
parameters. [dbench] ``noise_gate=True`` scales every update by a step size that depends on the
input's noise level ℓ = log2(spp)/10 (:func:`dbench.methods.hdr_input.noise_level`):
s <- s + γ(ℓ) (sigmoid(p · W) + b), γ(ℓ) = γ_max sigmoid(v + u ℓ), two more trained numbers
(362 in all; γ_max a fixed setting, 1 or 2). The automaton can then smooth a 1-spp image and leave a 1024-spp one nearly alone; γ = 1
without the gate. ``update_channels="rgb"`` masks the update to RGB (normal and albedo stay the input
bit for bit); ``activation="tanh"`` replaces the sigmoid.

The fast path (:func:`folded_kernel`): perception followed by the 1x1 product with W is one
linear map, a 3x3 convolution 9 -> 9 whose weights are the filters scaled by the rows of W. The
ONNX model (``export.py``) runs that convolution; tests prove it equal to this module.
:class:`FoldedNCA` runs it in PyTorch (the device path, ``device.py``).

Example:
    >>> import torch
    >>> nca = NCA()
    >>> count_parameters(nca)
    360
    >>> s = torch.rand(1, 9, 8, 8)
    >>> with torch.no_grad():  # W = 0, b = -0.5 (the initial values): the identity
    ...     bool(torch.equal(nca(s, 16), s))
    True
"""
from __future__ import annotations

import numpy as np
import torch
from torch import nn

from .codec import decode, encode, sanitize  # noqa: F401  (re-exported)

STATE_CHANNELS = 9
RGB = 3
PERCEPTION_CHANNELS = 39
UPDATE_CHANNELS = ("all", "rgb")
ACTIVATIONS = ("sigmoid", "tanh")

#: The fixed filters of docs/methods/nca.md §2 (cross-correlation kernels; +x right, +y down).
K_GAUSS = np.outer([1, 2, 1], [1, 2, 1]).astype(np.float32) / 16.0
K_SOBEL_X = np.array([[-1, 0, 1], [-2, 0, 2], [-1, 0, 1]], np.float32) / 8.0
K_SOBEL_Y = K_SOBEL_X.T.copy()
K_LAPLACE = np.array([[1, 2, 1], [2, -12, 2], [1, 2, 1]], np.float32) / 16.0
K_IDENTITY = np.zeros((3, 3), np.float32)
K_IDENTITY[1, 1] = 1.0

#: Perception blocks in order: (name, kernel, channels it applies to).
BLOCKS = (
    ("identity", K_IDENTITY, tuple(range(9))),
    ("gaussian", K_GAUSS, (0, 1, 2)),
    ("laplacian", K_LAPLACE, tuple(range(9))),
    ("sobel_x", K_SOBEL_X, tuple(range(9))),
    ("sobel_y", K_SOBEL_Y, tuple(range(9))),
)


def perception_map() -> list[tuple[np.ndarray, int]]:
    """For each of the 39 perception channels: (3x3 kernel, state channel it reads)."""
    return [(k, c) for _, k, chans in BLOCKS for c in chans]


def perceive(s: torch.Tensor) -> torch.Tensor:
    """(N, 9, H, W) state -> (N, 39, H, W) perception vector (docs/methods/nca.md §2), kornia filters,
    replicate padding."""
    if s.ndim != 4 or s.shape[1] != STATE_CHANNELS:
        raise ValueError(f"state: expected (N, 9, H, W), got {tuple(s.shape)}")

    def filt(x: torch.Tensor, k: np.ndarray) -> torch.Tensor:
        kern = torch.as_tensor(k, dtype=x.dtype, device=x.device)[None]
        from kornia.filters import filter2d  # here: the device path (FoldedNCA) needs no kornia
        return filter2d(x, kern, border_type="replicate")

    return torch.cat([s, filt(s[:, :RGB], K_GAUSS), filt(s, K_LAPLACE), filt(s, K_SOBEL_X),
                      filt(s, K_SOBEL_Y)], dim=1)


class NCA(nn.Module):
    """The automaton: ``forward(s, iterations)`` applies the update ``iterations`` times.

    Args:
        update_channels: ``"all"`` (seed: every channel evolves) or ``"rgb"``.
        activation: ``"sigmoid"`` (seed) or ``"tanh"``.
        bias_init: initial value of every entry of b (-0.5 with W = 0 is the identity).
        w_init_std: standard deviation of W's initial Gaussian values.
    """

    def __init__(self, update_channels: str = "all", activation: str = "sigmoid",
                 bias_init: float = -0.5, w_init_std: float = 0.0, generator=None,
                 noise_gate: bool = False, gate_init: tuple[float, float] = (0.0, 2.0),
                 gate_max: float = 1.0):
        super().__init__()
        self.noise_gate = bool(noise_gate)
        self.gate_max = float(gate_max)  # γ in (0, gate_max)
        if self.noise_gate:  # (u, v) of γ(ℓ) = sigmoid(v + u ℓ)
            self.gate_u = nn.Parameter(torch.tensor(float(gate_init[0])))
            self.gate_v = nn.Parameter(torch.tensor(float(gate_init[1])))
        if update_channels not in UPDATE_CHANNELS:
            raise ValueError(f"update_channels: expected one of {UPDATE_CHANNELS}")
        if activation not in ACTIVATIONS:
            raise ValueError(f"activation: expected one of {ACTIVATIONS}")
        self.update_channels = update_channels
        self.activation = activation
        w = torch.zeros(PERCEPTION_CHANNELS, STATE_CHANNELS)
        if w_init_std > 0:
            w.normal_(0.0, w_init_std, generator=generator)
        self.W = nn.Parameter(w)
        self.b = nn.Parameter(torch.full((STATE_CHANNELS,), float(bias_init)))
        mask = torch.ones(STATE_CHANNELS)
        if update_channels == "rgb":
            mask[RGB:] = 0
        self.register_buffer("mask", mask, persistent=False)

    def act(self, z: torch.Tensor) -> torch.Tensor:
        return torch.sigmoid(z) if self.activation == "sigmoid" else torch.tanh(z)

    def step_size(self, level: torch.Tensor | float | None, n: int) -> torch.Tensor | float:
        """γ per batch item, (N, 1, 1, 1), from the noise level ℓ (scalar or (N,)); 1.0 without
        the gate. ``level=None`` with the gate means 1 spp (ℓ = 0)."""
        if not self.noise_gate:
            return 1.0
        # on the parameters' device: a level built on the CPU stopped the model on CUDA; a
        # number is filled in there (no host-to-device copy)
        dev = self.gate_u.device
        if level is None:
            lv = torch.zeros(n, device=dev)
        elif isinstance(level, (int, float)):
            lv = torch.full((), float(level), dtype=torch.float32, device=dev)
        else:
            lv = torch.as_tensor(level, dtype=torch.float32, device=dev)
        lv = lv.reshape(-1)[:, None, None, None] if lv.ndim else lv.reshape(1, 1, 1, 1)
        return self.gate_max * torch.sigmoid(self.gate_v + self.gate_u * lv)

    def step(self, s: torch.Tensor, gamma: torch.Tensor | float = 1.0) -> torch.Tensor:
        """One update: s + γ (sigmoid(p · W) + b) (masked to RGB when update_channels="rgb")."""
        p = perceive(s)
        z = torch.einsum("nphw,pc->nchw", p, self.W)
        ds = gamma * (self.act(z) + self.b[None, :, None, None])
        if self.update_channels == "rgb":
            return torch.cat([s[:, :RGB] + ds[:, :RGB], s[:, RGB:]], dim=1)
        return s + ds

    def forward(self, s: torch.Tensor, iterations: int,
                level: torch.Tensor | float | None = None) -> torch.Tensor:
        gamma = self.step_size(level, s.shape[0])
        for _ in range(int(iterations)):
            s = self.step(s, gamma)
        return s


def count_parameters(module: nn.Module) -> int:
    return sum(p.numel() for p in module.parameters() if p.requires_grad)


def folded_kernel(W: np.ndarray) -> np.ndarray:
    """The (9, 9, 3, 3) convolution (out, in, ky, kx) equal to ``perceive`` followed by · W.

    Output channel o reads input channel c through sum_j W[j, o] K_j over the perception
    channels j that read c.
    """
    W = np.asarray(W, np.float64)
    if W.shape != (PERCEPTION_CHANNELS, STATE_CHANNELS):
        raise ValueError(f"W: expected shape (39, 9), got {W.shape}")
    K = np.zeros((STATE_CHANNELS, STATE_CHANNELS, 3, 3), np.float64)
    for j, (kern, c) in enumerate(perception_map()):
        K[:, c] += W[j][:, None, None] * kern[None].astype(np.float64)
    return K.astype(np.float32)



class FoldedNCA(nn.Module):
    """The fast path of an :class:`NCA` as a module (what ``export.py``'s ONNX Loop runs and
    the device path uses): per step replicate padding, one 3x3 convolution with the folded
    weights (:func:`folded_kernel`: perception followed by · W), the activation, + b, × γ, + s.

    ``forward(s, iterations, level)`` as :meth:`NCA.forward`: s (N, 9, H, W) → (N, 9, H, W);
    γ from the wrapped NCA's noise gate. The folded weights are computed once, in float64 and
    rounded to float32 like :func:`folded_kernel`, from the NCA's W when the module is built.
    """

    def __init__(self, nca: NCA):
        super().__init__()
        self.nca = nca
        basis = torch.zeros(PERCEPTION_CHANNELS, STATE_CHANNELS, 3, 3, dtype=torch.float64)
        for j, (kern, c) in enumerate(perception_map()):
            basis[j, c] = torch.from_numpy(kern.astype(np.float64))
        with torch.no_grad():
            K = torch.einsum("jo,jcyx->ocyx", nca.W.detach().to(torch.float64), basis)
        cout = STATE_CHANNELS if nca.update_channels == "all" else RGB
        self.register_buffer("K", K.to(torch.float32)[:cout].contiguous(), persistent=False)

    def step(self, s: torch.Tensor, gamma: torch.Tensor | float = 1.0) -> torch.Tensor:
        z = torch.nn.functional.conv2d(torch.nn.functional.pad(s, (1, 1, 1, 1),
                                                               mode="replicate"), self.K)
        cout = self.K.shape[0]
        ds = gamma * (self.nca.act(z) + self.nca.b[:cout][None, :, None, None])
        if cout == RGB:
            return torch.cat([s[:, :RGB] + ds, s[:, RGB:]], dim=1)
        return s + ds

    def forward(self, s: torch.Tensor, iterations: int,
                level: torch.Tensor | float | None = None) -> torch.Tensor:
        gamma = self.nca.step_size(level, s.shape[0])
        for _ in range(int(iterations)):
            s = self.step(s, gamma)
        return s
