"""The statistical denoiser of one steady image on the chosen backend, NumPy in and out
(docs/methods/statistical.md): :func:`statistical_filter` builds the base filter's guide
(:func:`~dbench.methods.kernels.bilateral.guide.make_guide`), the statistics' planes
(:func:`.reference.stat_planes`) and the threshold (:func:`.params.resolve_threshold`), then runs
``"reference"`` (:func:`.reference.statistical_reference`, float64) or ``"numba"`` / ``"torch"``
(:func:`.fast.statistical_fast`); ``"auto"`` is ``"numba"`` (:func:`resolve_backend`).

Example:
    >>> import numpy as np
    >>> from dbench.data import SampleStats
    >>> rng = np.random.default_rng(0)
    >>> y = rng.normal(1.0, 1.0, size=(16, 16, 3, 64))
    >>> stats = SampleStats(n=np.full((16, 16, 3), 64.0), mean=y.mean(-1),
    ...                     var_mean=y.var(-1, ddof=1) / 64,
    ...                     m3=((y - y.mean(-1, keepdims=True)) ** 3).mean(-1),
    ...                     transform="identity")
    >>> flat = np.zeros((16, 16, 3)); flat[..., 2] = 1
    >>> out, info = statistical_filter(y.mean(-1), stats, np.full((16, 16, 3), 0.5), flat,
    ...                                radius=3, backend="numba", return_info=True)
    >>> out.shape, round(info["gamma_t"], 4)
    ((16, 16, 3), 2.8573)
"""
from __future__ import annotations

from typing import Any

import numpy as np

from ...data import SampleStats
from ..checks import check_choice
from ..kernels.bilateral.guide import image_shape, make_guide
from ..kernels.bilateral.params import SEED_SIGMA
from .fast import statistical_fast
from .params import BACKENDS, DEFAULT_ALPHA, resolve_threshold
from .reference import stat_planes, statistical_reference

__all__ = ["resolve_backend", "statistical_filter"]


def resolve_backend(backend: str) -> str:
    """The backend a call runs: ``backend`` checked against :data:`.params.BACKENDS`, "auto"
    resolved to "numba"."""
    check_choice("backend", backend, BACKENDS)
    if backend == "auto":
        # on a GPU the harness runs the device path (docs/gpu.md §3); the host-side "torch"
        # path, which copied the frame across the bus inside every call, only on request
        return "numba"
    return backend


def statistical_filter(color: Any, stats: SampleStats, albedo: Any, normal: Any, depth: Any = None,
                       position: Any = None, *, radius: int = 20,
                       alpha: float | None = DEFAULT_ALPHA,
                       gamma: float | None = None, sigma=SEED_SIGMA,
                       sigma_convention: str = "variance", window: str = "square",
                       hit_mask: bool = True, features=("xy", "albedo", "normal"),
                       membership_on: bool = True, backend: str = "auto",
                       return_info: bool = False, emitter: Any = None):
    """Statistical denoiser of docs/methods/statistical.md on one steady image.

    Args:
        color: (H, W, 3) linear noisy colour (the image that is filtered).
        stats: SampleStats with (H, W, 3) n, mean, var_mean, m3 of the transformed samples
            (θ̂ = stats.theta, Var(θ̂) = stats.var_mean).
        albedo, normal: (H, W, 3); depth: (H, W, 1) or None (all pixels hit); position: (H, W, 3)
            when ``features`` include it; emitter: (H, W, 1) emitter coverage or None (lights
            seen directly get their own label, as in ``jbf``'s guide: docs/methods/jbf.md §1.3).
        radius, sigma, sigma_convention, window, hit_mask, features: base filter ρ
            (docs/methods/jbf.md).
        alpha: test level, γ_t = t_{1−α/2, n_i+n_j−2}; gamma: threshold given directly (wins).
        membership_on: False gives the plain JBF (every membership forced on; ablation).
        backend: "auto" (Numba), "numba", "torch", "reference".
        return_info: also return a dict of resolved settings (γ_t, ν, transform, backend...).

    Returns:
        (H, W, 3) float32 (and the info dict).
    """
    shape = image_shape(color)
    backend = resolve_backend(backend)
    guide = make_guide(albedo, normal, depth, position, radius=radius, sigma=sigma,
                       sigma_convention=sigma_convention, window=window, hit_mask=hit_mask,
                       features=features, shape=shape, emitter=emitter)
    sp = stat_planes(stats, shape)
    thr = resolve_threshold(sp.nint, alpha, gamma, valid=np.broadcast_to(~sp.bad, sp.nint.shape))
    if backend == "reference":
        out = statistical_reference(color, sp, guide, thr,
                                    membership_on=membership_on).astype(np.float32)
    else:
        out = statistical_fast(color, sp, guide, thr, backend=backend, membership_on=membership_on)
    if not return_info:
        return out
    info = dict(guide.settings, alpha=thr.alpha, gamma=thr.gamma, gamma_t=thr.gamma_t, nu=thr.nu,
                threshold_source=thr.source, uniform_n=thr.table is None,
                transform=sp.transform, lam=sp.lam, membership=bool(membership_on),
                backend=backend, n_bad_stats=int(sp.bad.sum()))
    return out, info
