"""Checks shared by the learned methods' tests (nca, autoencoder): convergence on a synthetic
image whose noise falls as 1/sqrt(spp), and exposure invariance."""
from __future__ import annotations

import numpy as np

from dbench.data import Frame


def synthetic_frame(spp: int, h: int = 64, w: int = 64, seed: int = 0, scale: float = 1.0
                    ) -> tuple[Frame, np.ndarray]:
    """(frame at ``spp`` with meta["spp"], its noise-free image): smooth shading times a blocky
    albedo, Gaussian sample noise of relative sd 0.8 per sample (clipped at 0), clean
    G-buffers."""
    rng = np.random.default_rng(seed + spp)
    y, x = np.mgrid[0:h, 0:w] / max(h, w)
    light = 0.6 + 0.4 * np.sin(5 * x + 1.0) * np.cos(4 * y)
    albedo = np.where(((x * 6).astype(int) + (y * 6).astype(int)) % 2 == 0, 0.75, 0.3)
    albedo = albedo[..., None] * np.array([1.0, 0.8, 0.6])
    clean = scale * light[..., None] * albedo
    noisy = np.maximum(clean * (1 + 0.8 / np.sqrt(spp) * rng.standard_normal(clean.shape)), 0)
    normal = np.zeros((h, w, 3))
    normal[..., 2] = 1
    frame = Frame(color=noisy.astype(np.float32), albedo=albedo.astype(np.float32),
                  normal=normal.astype(np.float32), depth=np.ones((h, w, 1), np.float32),
                  meta={"spp": spp})
    return frame, clean


def relmse(a: np.ndarray, ref: np.ndarray) -> float:
    return float(np.mean((a - ref) ** 2 / (ref ** 2 + 1e-2)))


def convergence(denoise, spps=(4, 64, 1024)) -> list[tuple[int, float, float]]:
    """(spp, noisy relMSE, method relMSE) on :func:`synthetic_frame` for each spp."""
    out = []
    for spp in spps:
        frame, clean = synthetic_frame(spp)
        out.append((spp, relmse(frame.color, clean), relmse(denoise(frame), clean)))
    return out


def assert_converges(denoise, spps=(4, 64, 1024)) -> None:
    """Below the noisy input at every spp, and the error falling as spp grows."""
    res = convergence(denoise, spps)
    for spp, noisy, method in res:
        assert method < noisy, f"{spp} spp: method relMSE {method:.3g} >= noisy {noisy:.3g}"
    errs = [m for _, _, m in res]
    assert all(b < a for a, b in zip(errs, errs[1:])), f"error does not fall with spp: {res}"
