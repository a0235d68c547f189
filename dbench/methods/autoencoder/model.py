"""The recurrent denoising autoencoder in PyTorch: the readable reference (docs/methods/autoencoder.md).

Architecture (docs/methods/autoencoder.md §2, dbench's exact definition), for encoder widths e = (32, 43, 57, 76, 101)
scaled by ``width_scale`` and decoder widths d = (76, 57, 43, 32, 32) scaled alike::

    encoder level l = 1..5:
        x   = LReLU(conv3(x; c_prev -> e_l))
        a   = LReLU(conv3(x; e_l -> e_l))                    # recurrent block
        b   = LReLU(conv3(concat(a, h_l); 2 e_l -> e_l))     # h_l: o_l of the previous frame
        o_l = LReLU(conv3(b; e_l -> e_l));  h_l <- o_l
        x   = maxpool2(o_l)
    bottleneck: x = LReLU(conv3(x; e_5 -> e_5))              (resolution / 32)
    decoder level l = 5..1:
        x = upsample2(x); x = concat(x, o_l)
        x = LReLU(conv3(x; . -> d)); x = LReLU(conv3(x; d -> d))
    output: conv3(x; d_1 -> 3), no activation

LeakyReLU slope 0.1, 3x3 convolutions with zero "same" padding, 2x2 max pooling, nearest
upsampling. With 9 input channels and ``width_scale=1`` the model has 1,454,924 parameters
(docs/methods/autoencoder.md §6.1).

Input encoding (docs/methods/autoencoder.md §1, dbench): channel order ``log1p(color / a_eff)`` (3), then the feature
buffers in ``FEATURE_ORDER`` order: normal (3, in [-1, 1]), albedo (3, in [0, 1]) and optionally
depth (1, divided by the frame's largest finite depth). ``a_eff`` is the albedo where it exceeds
1e-3 (per channel) and 1 elsewhere (docs/methods/svgf.md §2). The network predicts the demodulated
illumination in log1p space; :func:`decode` remodulates: ``out = max(expm1(y), 0) * a_eff``.

Example:
    >>> import torch
    >>> net = RecurrentAE(in_channels=9)
    >>> count_parameters(net)
    1454924
    >>> y, h = net(torch.zeros(1, 9, 64, 32))
    >>> tuple(y.shape), [tuple(t.shape[1:]) for t in h][:2]
    ((1, 3, 64, 32), [(32, 64, 32), (43, 32, 16)])
"""
from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from .codec import (ALBEDO_EPS, FEATURE_CHANNELS, FEATURE_ORDER, LEVELS, MULTIPLE,  # noqa: F401
                    SLOPE, decode, encode, in_channels_for, pad_to_multiple)

ENCODER_WIDTHS = (32, 43, 57, 76, 101)
DECODER_WIDTHS = (76, 57, 43, 32, 32)


def widths(width_scale: float = 1.0) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """Encoder and decoder widths for ``width_scale`` (each rounded, at least 1)."""
    enc = tuple(max(1, int(round(w * width_scale))) for w in ENCODER_WIDTHS)
    dec = tuple(max(1, int(round(w * width_scale))) for w in DECODER_WIDTHS)
    return enc, dec


def _conv(cin: int, cout: int) -> nn.Conv2d:
    return nn.Conv2d(cin, cout, 3, padding=1)


class RecurrentAE(nn.Module):
    """U-Net with a recurrent block per encoder level (docs/methods/autoencoder.md §2).

    Args:
        in_channels: input channels (9 for colour + normal + albedo).
        width_scale: multiplies every width (rounded).
        recurrent: False replaces every hidden state by zeros (the seed's model).
        residual: [dbench option, not in the paper] add the input's 3 colour channels to the
            output, so the network predicts a correction of the noisy (demodulated, log1p)
            colour; noise-free pixels such as visible lights then pass through easily.
        blend: [dbench option, not in the paper; excludes ``residual``] the last convolution
            gives 4 channels, a prediction f (3) and a gate logit g (1), and the output is
            ``sigmoid(g) * x_rgb + (1 - sigmoid(g)) * f``: per pixel, the network chooses
            between keeping the input colour (visible lights, converged pixels) and replacing
            it (noise), instead of only correcting it.
        level_gate: [dbench option, with ``residual``] the index of the input's noise-level
            plane ℓ = log2(spp)/10; the correction is scaled by γ(ℓ) = gate_max ·
            sigmoid(v + u ℓ) (two trained numbers, ``self.level_gate`` = (u, v)), the NCA's
            step size (docs/methods/nca.md, dbench), so that one scalar can pass a converged input
            (ℓ → 1) through. Tried against the shipped model's gap at 256-1024 spp and worse
            (results/learned.md); not used by the shipped model.
        gate_max, gate_init: γ's upper bound and the initial (u, v).
        pixel_gate: [dbench option, with ``residual``] the last convolution gives 4 channels,
            a correction Δ (3) and a logit g (1), and the output is x_rgb + sigmoid(g) Δ: the
            network can switch its correction off per pixel (edges, texture of a converged
            input) with one saturating channel instead of driving three to exactly zero. Tried
            and worse (results/learned.md); not used by the shipped model.

    ``forward(x, hidden=None)``: x (N, C, H, W) with H, W multiples of 32; hidden a list of
    ``LEVELS`` tensors (N, e_l, H / 2^(l-1), W / 2^(l-1)) or None (zeros, i.e. frame 0).
    Returns (y (N, 3, H, W), new hidden list).
    """

    def __init__(self, in_channels: int = 9, width_scale: float = 1.0, recurrent: bool = True,
                 residual: bool = False, blend: bool = False, level_gate: int | None = None,
                 gate_max: float = 2.0, gate_init: tuple[float, float] = (-4.0, 2.0),
                 pixel_gate: bool = False):
        super().__init__()
        if residual and blend:
            raise ValueError("residual and blend exclude each other")
        if pixel_gate and not residual:
            raise ValueError("pixel_gate: needs residual")
        self.pixel_gate = pixel_gate
        if level_gate is not None and not (residual and 3 <= level_gate < in_channels):
            raise ValueError(f"level_gate: expected a residual model and a channel index in "
                             f"[3, {in_channels}), got {level_gate!r}")
        self.level_channel = level_gate
        self.gate_max = float(gate_max)
        if level_gate is not None:
            self.level_gate = nn.Parameter(torch.tensor(gate_init, dtype=torch.float32))
        self.blend = blend
        self.in_channels = in_channels
        self.width_scale = width_scale
        self.recurrent = recurrent
        self.residual = residual
        enc, dec = widths(width_scale)
        self.enc_widths, self.dec_widths = enc, dec
        self.enc_in = nn.ModuleList()
        self.rec_a = nn.ModuleList()
        self.rec_b = nn.ModuleList()
        self.rec_o = nn.ModuleList()
        c = in_channels
        for e in enc:
            self.enc_in.append(_conv(c, e))
            self.rec_a.append(_conv(e, e))
            self.rec_b.append(_conv(2 * e, e))
            self.rec_o.append(_conv(e, e))
            c = e
        self.bottleneck = _conv(enc[-1], enc[-1])
        self.dec_a = nn.ModuleList()
        self.dec_b = nn.ModuleList()
        c = enc[-1]
        for level in reversed(range(LEVELS)):
            d = dec[LEVELS - 1 - level]
            self.dec_a.append(_conv(c + enc[level], d))
            self.dec_b.append(_conv(d, d))
            c = d
        self.out = _conv(c, 4 if (blend or pixel_gate) else 3)

    def hidden_shapes(self, n: int, h: int, w: int) -> list[tuple[int, int, int, int]]:
        """Shapes of the hidden states for an (n, C, h, w) input."""
        return [(n, e, h >> l, w >> l) for l, e in enumerate(self.enc_widths)]

    def zero_hidden(self, n: int, h: int, w: int, device=None) -> list[torch.Tensor]:
        return [torch.zeros(s, device=device) for s in self.hidden_shapes(n, h, w)]

    def forward(self, x: torch.Tensor, hidden: list[torch.Tensor] | None = None
                ) -> tuple[torch.Tensor, list[torch.Tensor]]:
        n, c, h, w = x.shape
        if c != self.in_channels:
            raise ValueError(f"x: expected (N, {self.in_channels}, H, W), got {tuple(x.shape)}")
        if h % MULTIPLE or w % MULTIPLE:
            raise ValueError(f"x: H and W must be multiples of {MULTIPLE}, got {h}x{w}")
        if hidden is None or not self.recurrent:
            hidden = self.zero_hidden(n, h, w, device=x.device)
        x_in = x
        skips, new_hidden = [], []
        for level in range(LEVELS):
            x = F.leaky_relu(self.enc_in[level](x), SLOPE)
            a = F.leaky_relu(self.rec_a[level](x), SLOPE)
            b = F.leaky_relu(self.rec_b[level](torch.cat([a, hidden[level]], 1)), SLOPE)
            o = F.leaky_relu(self.rec_o[level](b), SLOPE)
            skips.append(o)
            new_hidden.append(o)
            x = F.max_pool2d(o, 2)
        x = F.leaky_relu(self.bottleneck(x), SLOPE)
        for i, level in enumerate(reversed(range(LEVELS))):
            x = F.interpolate(x, scale_factor=2, mode="nearest")
            x = torch.cat([x, skips[level]], 1)
            x = F.leaky_relu(self.dec_a[i](x), SLOPE)
            x = F.leaky_relu(self.dec_b[i](x), SLOPE)
        y = self.out(x)
        if self.pixel_gate:
            y = y[:, :3] * torch.sigmoid(y[:, 3:4])
        if self.level_channel is not None:
            lv = x_in[:, self.level_channel:self.level_channel + 1]
            y = y * (self.gate_max * torch.sigmoid(self.level_gate[1] + self.level_gate[0] * lv))
        if self.residual:
            y = y + x_in[:, :3]
        elif self.blend:
            keep = torch.sigmoid(y[:, 3:4])
            y = y[:, :3] + keep * (x_in[:, :3] - y[:, :3])
        return y, new_hidden


def count_parameters(module: nn.Module) -> int:
    """Trainable parameters (weights and biases)."""
    return sum(p.numel() for p in module.parameters() if p.requires_grad)
