"""The steps of SVGF / A-SVGF on a chosen backend, NumPy in and out: ``"reference"``
(:mod:`.reference`, float64), ``"numba"`` (:mod:`.numba_path`, float32, CPU) or ``"torch"``
(:mod:`.torch_path`: vectorised PyTorch, CUDA when available, else CPU). The wrapper in
:mod:`dbench.methods.svgf` calls only these: :func:`prepare`, :func:`depth_gradient`,
:func:`atrous`, :func:`spatial_variance`, :func:`remodulate`, :func:`stratum_gradients`,
:func:`filter_gradients` and :func:`adaptive_history`."""
from __future__ import annotations

import numpy as np

from ..temporal import to_numpy
from .numba_path import (HAVE_NUMBA, adaptive_history_fast, atrous_fast, depth_gradient_fast,
                         prepare_fast, remodulate_fast, spatial_variance_fast,
                         stratum_gradients_fast)
from .params import ALBEDO_FLOOR
from .reference import (adaptive_history_reference, atrous_reference, depth_gradient_reference,
                        prepare_reference, remodulate_reference, spatial_variance_reference,
                        stratum_gradients_reference)
from .torch_path import (adaptive_history_torch, atrous_torch, depth_gradient_torch, prepare_torch,
                         remodulate_torch, spatial_variance_torch, stratum_gradients_torch)


def prepare(backend: str, color, albedo, emission, hit, albedo_floor: float = ALBEDO_FLOOR
            ) -> dict[str, np.ndarray]:
    """:func:`~.reference.prepare_reference` on ``backend`` ("numba":
    :func:`~.numba_path.prepare_fast`, "torch": :func:`~.torch_path.prepare_torch`); NumPy out.
    ``albedo_floor``: a_eff = clip(albedo, floor, 1) (:data:`~.params.ALBEDO_FLOOR`)."""
    if backend == "torch":
        return {k: to_numpy(v) for k, v in prepare_torch(color, albedo, emission, hit,
                                                         albedo_floor=albedo_floor).items()}
    if backend == "numba" and HAVE_NUMBA:
        return prepare_fast(color, albedo, emission, hit, albedo_floor)
    return prepare_reference(color, albedo, emission, hit, albedo_floor)


def remodulate(illum: np.ndarray, a_eff: np.ndarray, emission: np.ndarray,
               backend: str = "numba") -> np.ndarray:
    """(H, W, 3) float32 output = a_eff · I + E from planar (3, H, W) buffers."""
    if backend == "torch":
        return np.ascontiguousarray(to_numpy(remodulate_torch(illum, a_eff, emission)))
    if backend == "reference" or not HAVE_NUMBA:
        return remodulate_reference(illum, a_eff, emission)
    return remodulate_fast(illum, a_eff, emission)


def depth_gradient(z: np.ndarray, hit: np.ndarray, backend: str = "reference"
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Screen-space depth gradient (gx, gy), each (H, W) float32, in depth units per pixel.

    Where both neighbours are hit surfaces: the one-sided difference of smaller magnitude
    (equal to the central difference on planes, where both agree; at a depth discontinuity it is
    the difference on the pixel's own side — the spec's central difference would put half the
    step into the gradient there and let the depth weight pass taps across the step, failing
    docs/methods/svgf.md §9 check 5). One-sided next to borders and pixels without hit, 0 where
    neither neighbour is usable or the pixel itself has no hit.
    """
    if backend == "torch":
        return tuple(to_numpy(g) for g in depth_gradient_torch(z, hit))
    if backend == "numba" and HAVE_NUMBA:
        return depth_gradient_fast(z, hit)
    return depth_gradient_reference(z, hit)


def atrous(backend: str, *args, **kw):
    """One à-trous iteration on ``backend`` (arguments of :func:`~.reference.atrous_reference`),
    float32 NumPy (colour (3, H, W), variance (H, W))."""
    if backend == "torch":
        c, v = atrous_torch(*args, **kw)
        return to_numpy(c), to_numpy(v)
    if backend == "reference" or not HAVE_NUMBA:
        c, v = atrous_reference(*args, **kw)
        return c.astype(np.float32), v.astype(np.float32)
    return atrous_fast(*args, **kw)


def spatial_variance(backend: str, mom, z, gx, gy, normal, tap, hit, select, **kw):
    """Spatial variance (docs/methods/svgf.md §4) on ``backend`` where ``select``, 0 elsewhere: (H, W) float32."""
    if backend == "torch":
        return to_numpy(spatial_variance_torch(mom, z, gx, gy, normal, tap, hit, select, **kw))
    if backend == "reference" or not HAVE_NUMBA:
        v = spatial_variance_reference(mom, z, gx, gy, normal, tap, hit, **kw)
        return np.where(select, v, 0.0).astype(np.float32)
    return spatial_variance_fast(mom, z, gx, gy, normal, tap, hit, select, **kw)


def stratum_gradients(l_prev, l_grad, prev_hit, prev_depth, prev_normal, size=3,
                      backend="reference"):
    """Per-stratum temporal gradient of docs/methods/svgf.md §6.1/§6.4 at 1/size resolution.

    Args:
        l_prev: (H, W) luminance of frame i−1's noisy colour.
        l_grad: (H, W) luminance of frame i's gradient render (lights of i, camera, seeds of i−1).
        prev_hit, prev_depth, prev_normal: frame i−1's G-buffer ((H, W), (H, W), (3, H, W)).
    Returns:
        dict with ``delta``, ``norm`` (Δ), ``g`` (G), ``has`` (stratum usable), ``depth``,
        ``normal`` (3, hs, ws) of the chosen samples.
    """
    if backend == "torch":
        out = stratum_gradients_torch(l_prev, l_grad, prev_hit, prev_depth, prev_normal, size)
        return {k: to_numpy(v) for k, v in out.items()}
    if backend == "numba" and HAVE_NUMBA:
        return stratum_gradients_fast(l_prev, l_grad, prev_hit, prev_depth, prev_normal, size)
    return stratum_gradients_reference(l_prev, l_grad, prev_hit, prev_depth, prev_normal, size)


def filter_gradients(strata: dict, iterations: int = 3, sigma_z: float = 1.0,
                     sigma_n: float = 128.0, backend: str = "numba") -> dict:
    """À-trous (docs/methods/svgf.md §5, w_l off) over the stratum image of [δ, Δ, G], ``iterations`` steps
    1, 2, 4 …; returns filtered ``delta``, ``norm``, ``g`` (hs, ws) float32."""
    img = np.stack([strata["delta"], strata["norm"], strata["g"]]).astype(np.float32)
    has = strata["has"]
    gx, gy = depth_gradient(strata["depth"], has, backend)
    var = np.zeros(has.shape, np.float32)
    for i in range(iterations):
        img, _ = atrous(backend, img, var, strata["depth"], gx, gy, strata["normal"], has, has,
                        has, 2 ** i, sigma_z=sigma_z, sigma_n=sigma_n, use_lum=False)
    return {"delta": img[0], "norm": img[1], "g": np.clip(img[2], 0.0, 1.0)}


def adaptive_history(low: np.ndarray, motion: np.ndarray, hit: np.ndarray, n_hist: np.ndarray,
                     n_max: float = 256.0, mode: str = "seed", alpha0: float = 0.2,
                     backend: str = "numba", size: int = 3):
    """Full-resolution G (:func:`~.reference.gradient_at_pixels`), N' and α
    (:func:`~.reference.asvgf_history`; ``mode="paper"``: α = max(mix(α0, 1, λ), 1/N')) in one
    pass. Returns three (H, W) float32."""
    if backend == "torch":
        return tuple(to_numpy(t) for t in adaptive_history_torch(
            low, motion, hit, n_hist, n_max, mode, alpha0, size))
    if backend == "reference" or not HAVE_NUMBA:
        return adaptive_history_reference(low, motion, hit, n_hist, n_max, mode, alpha0, size)
    return adaptive_history_fast(low, motion, hit, n_hist, n_max, mode, alpha0, size)
