"""Synthetic frames, videos and sequences made without a renderer (shapes (H, W, C) float32,
statistics (H, W, 3) float64; dbench/data.py): what the stress matrix, the speed benchmarks,
the learned methods' checks and the tests run methods on.

* :func:`base_frame`: a steady frame with G-buffers and sample statistics (default 24×24);
* :func:`base_video`: a transient (H, W, T, 3) video with statistics;
* :func:`synthetic_sequence`: a panning sequence with motion vectors and exact references;
* :func:`synthetic_frame`: piecewise-constant G-buffers with noisy colour (the joint bilateral
  filter's speed figures)."""
from __future__ import annotations

import numpy as np

from .data import Frame, SampleStats, Sequence, TransientFrame


def synthetic_sequence(height: int, width: int, frames: int = 12, shift: int = 2, seed: int = 0
                       ) -> Sequence:
    """A moving synthetic sequence at any size (no renderer): a textured, shaded plane pair seen
    by a camera panning ``shift`` px per frame (integer motion vectors), 1-spp-like noise,
    an exact reference, and a gradient buffer equal to the previous frame's colour (what
    re-shading the previous samples under an unchanged light gives)."""
    rng = np.random.default_rng(seed)
    total_w = width + shift * frames
    y, x = np.mgrid[0:height, 0:total_w].astype(np.float32)
    clean = 0.5 + 0.4 * np.sin(x / 37.0)[..., None] * np.cos(y / 23.0)[..., None]
    clean = np.repeat(clean, 3, axis=2) * np.array([1.0, 0.8, 0.6], np.float32)
    clean[:, total_w // 2:] *= 0.3
    albedo = np.where(((x // 16 + y // 16) % 2)[..., None] > 0, 0.8, 0.3) * np.ones(3, np.float32)
    normal = np.zeros((height, total_w, 3), np.float32)
    normal[..., 2] = 1.0
    normal[height // 2:] = (0.0, 1.0, 0.0)
    depth = np.where(np.arange(height)[:, None] < height // 2, 2.0, 2.5) * np.ones((1, total_w))
    position = np.dstack([x / 100, y / 100, depth]).astype(np.float32)
    radiance = clean * albedo
    noise = rng.exponential(1.0, (frames, height, total_w)).astype(np.float32)
    out = []
    prev = None
    for i in range(frames):
        sl = (slice(None), slice(i * shift, i * shift + width))
        color = radiance[sl] * noise[i][sl][..., None]
        grad = color if prev is None else prev  # static light: re-shading = previous frame
        prev = color
        motion = np.zeros((height, width, 2), np.float32)
        motion[..., 0] = shift if i > 0 else 0.0
        out.append(Frame(color=color, albedo=albedo[sl], normal=normal[sl],
                         depth=depth[sl][..., None], position=position[sl],
                         reference=radiance[sl], motion=motion, gradient=grad,
                         meta={"frame": i}))
    return Sequence(out, meta={"scene": "synthetic", "ev": 0.0})


BASE_SIZE = (24, 24)


def base_frame(h: int = BASE_SIZE[0], w: int = BASE_SIZE[1], seed: int = 0, spp: int = 16,
               dtype=np.float32) -> Frame:
    """A small frame with every buffer: smooth light, an edge, two materials, stats of spp
    Gaussian samples (identity transform)."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    clean = 0.4 + 0.3 * np.sin(x / 5.0 + y / 7.0)
    clean = np.stack([clean, 0.8 * clean, 0.6 * clean], -1)
    clean[:, w // 2:] *= 0.25
    albedo = np.where(((x // 4 + y // 4) % 2)[..., None] > 0, 0.8, 0.2) * np.ones(3)
    normal = np.zeros((h, w, 3))
    normal[..., 2] = 1.0
    normal[h // 2:] = (0.0, 1.0, 0.0)
    sigma = 0.3 * np.sqrt(clean + 1e-3)
    color = clean + sigma / np.sqrt(spp) * rng.standard_normal(clean.shape)
    stats = SampleStats(n=np.full(clean.shape, float(spp)), mean=color,
                        var_mean=sigma ** 2 / spp, m3=np.zeros_like(clean),
                        transform="identity", lam=1.0)
    position = np.dstack([x / w, y / h, np.zeros_like(x)])
    # a small light in the top-left corner: fully covered pixels 1, its edge 0.5
    emitter = np.zeros((h, w, 1))
    emitter[:max(h // 6, 1), :max(w // 6, 1)] = 0.5
    emitter[:max(h // 6 - 1, 0), :max(w // 6 - 1, 0)] = 1.0
    return Frame(color=color.astype(dtype), albedo=albedo.astype(dtype), normal=normal,
                 depth=np.ones((h, w, 1)), position=position, stats=stats,
                 reference=clean.astype(np.float32), emitter=emitter)


def base_video(h: int = 12, w: int = 12, t: int = 10, seed: int = 0, spp: int = 16
               ) -> TransientFrame:
    """A small video with every buffer: a pulse travelling across the image over the bins
    (empty first and last bins), shared G-buffers, identity statistics of spp samples."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    bins = np.arange(t, dtype=np.float64)[None, None, :]
    front = 1.0 + (x + y)[..., None] * (t - 3) / max(h + w - 2, 1)
    clean = np.exp(-0.5 * (bins - front) ** 2)[..., None] * np.array([0.5, 0.4, 0.3])
    clean[:, :, 0] = 0.0
    clean[:, :, -1] = 0.0
    sigma = 0.3 * np.sqrt(clean + 1e-3)
    color = np.where(clean > 0, clean + sigma / np.sqrt(spp) * rng.standard_normal(clean.shape),
                     0.0)
    stats = SampleStats(n=np.full(clean.shape, float(spp)), mean=color,
                        var_mean=np.where(clean > 0, sigma ** 2 / spp, 0.0),
                        m3=np.zeros_like(clean), transform="identity", lam=1.0)
    albedo = np.where(((x // 3 + y // 3) % 2)[..., None] > 0, 0.8, 0.2) * np.ones(3)
    normal = np.zeros((h, w, 3))
    normal[..., 2] = 1.0
    # the bins are independent here, so the noisy total's variance is the sum of theirs
    total_var = stats.var_mean.sum(axis=2)
    return TransientFrame(color=color.astype(np.float32), stats=stats, albedo=albedo,
                          normal=normal, depth=np.ones((h, w, 1)),
                          reference=clean.astype(np.float32), total_var=total_var,
                          meta={"start_opl": 3.0, "bin_width_opl": 0.05, "units": "m"})


def synthetic_frame(height: int, width: int, seed: int = 0) -> dict[str, np.ndarray]:
    """Piecewise-constant G-buffers with a background band and noisy colour."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:height, 0:width]
    block = (yy // 37) * 101 + (xx // 53)
    albedo = rng.random((int(block.max()) + 1, 3))[block].astype(np.float32)
    normal = rng.normal(size=(int(block.max()) + 1, 3))
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    normal = normal[block].astype(np.float32)
    depth = np.where(yy < height // 8, 0.0, 1.0 + xx / width)[..., None].astype(np.float32)
    color = (albedo * rng.gamma(2.0, 0.5, size=(height, width, 3))).astype(np.float32)
    return dict(color=color, albedo=albedo, normal=normal, depth=depth)
