"""Filtering effective illumination: the seed-002 filter as a post-process (docs/methods/jbf.md §2.2,
simplified), its readable reference and its fast path on the shared Numba kernel."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...errors import DbenchInputError
from ..checks import check_positive, check_radius
from ..kernels.bilateral.guide import Guide, color_planes, image_shape, make_guide
from ..kernels.bilateral.numba2d import accumulate
from ..kernels.bilateral.reference import shift_slices
from .fast import resolve_backend


@dataclass(frozen=True)
class IlluminationSetup:
    """Everything the illumination filter needs besides the colour.

    guide: window, labels (hit / isolated) and, with ``use_position``, the position feature
    with Σ⁻¹ = 1/σ_P² (so that ½Σ⁻¹|ΔP|² = |ΔP|²/(2σ_P²)); its ``spatial`` holds α|o|².
    normal: (H, W, 3) float64; albedo: (H, W, 3) float64 (0 at isolated pixels);
    log_c: ln C, C = s / Σ_{o≠0} exp(−α|o|²), s = 1 − self_weight_min.
    """

    guide: Guide
    normal: np.ndarray
    albedo: np.ndarray
    alpha: float
    beta: float
    log_c: float
    eps_albedo: float
    settings: dict


def make_illumination_setup(albedo: Any, normal: Any, depth: Any = None, position: Any = None, *,
                            radius: int = 20, window: str = "square", alpha: float = 0.005,
                            beta: float = 10.0, self_weight_min: float = 0.5,
                            eps_albedo: float = 1e-3, use_position: bool = False,
                            sigma_P: float = 0.05, hit_mask: bool = True,
                            shape: tuple[int, int] | None = None) -> IlluminationSetup:
    """Check inputs and parameters of the illumination filter (docs/methods/jbf.md §2.2)."""
    radius = check_radius(radius)
    alpha = check_positive("alpha", alpha, allow_zero=True)
    beta = check_positive("beta", beta, allow_zero=True)
    swm = check_positive("self_weight_min", self_weight_min, allow_zero=True)
    if swm > 1:
        raise DbenchInputError(f"self_weight_min: expected a number in [0, 1], got {self_weight_min!r}")
    eps_albedo = check_positive("eps_albedo", eps_albedo, allow_zero=True)
    sigma_P = check_positive("sigma_P", sigma_P, allow_inf=True)
    features = ("albedo", "normal", "position") if use_position else ("albedo", "normal")
    # Build the guide with the JBF machinery (labels, validity, window), then replace its
    # feature terms: only the position enters as a squared distance here.
    g = make_guide(albedo, normal, depth, position, radius=radius, window=window,
                   features=features, hit_mask=hit_mask, shape=shape)
    h, w = g.shape
    alb = np.moveaxis(g.features[0:3], 0, -1).copy()
    nrm = np.moveaxis(g.features[3:6], 0, -1).copy()
    if use_position:
        feats, inv = g.features[6:9], np.full(3, 0.0 if math.isinf(sigma_P) else 1.0 / sigma_P ** 2)
    else:
        feats, inv = np.zeros((0, h, w)), np.zeros(0)
    spatial = alpha * (g.dy * g.dy + g.dx * g.dx).astype(np.float64)
    others = spatial[(g.dy != 0) | (g.dx != 0)]
    total = float(np.sum(np.exp(-others)))
    s = 1.0 - swm
    log_c = math.log(s / total) if (total > 0 and s > 0) else -math.inf
    guide = Guide(feats, inv, g.labels, g.dy, g.dx, spatial, radius, g.window,
                  dict(radius=radius, window=g.window, hit_mask=bool(hit_mask)))
    settings = dict(radius=radius, window=g.window, alpha=alpha, beta=beta,
                    self_weight_min=swm, eps_albedo=eps_albedo, use_position=bool(use_position),
                    sigma_P=sigma_P, hit_mask=bool(hit_mask), C=math.exp(log_c))
    return IlluminationSetup(guide, nrm, alb, alpha, beta, log_c, eps_albedo, settings)


def _illumination_inputs(color: Any, setup: IlluminationSetup):
    """E = L/a per channel, the per-channel validity v_c and the pixel validity."""
    col, valid = color_planes(color, setup.guide.shape)
    usable = (setup.albedo > setup.eps_albedo) & ~setup.guide.isolated[..., None]
    e = np.divide(col, setup.albedo, out=np.zeros_like(col), where=usable)
    v = usable & valid[..., None]
    return col, valid, usable, np.where(v, e, 0.0), v


def _illumination_combine(col, valid, usable, e, v, setup, num, den):
    """Ẽ = (1 − Σw) E + Σ w E' for valid pixels; missing pixels take Σ w E'/Σ w; remodulate."""
    a = setup.albedo
    e_self = e + (num - den * e)                          # w_pp E_p + Σ w E_p'
    e_missing = np.divide(num, den, out=np.zeros_like(num), where=den > 0)
    e_tilde = np.where(v, e_self, e_missing)
    out = np.where(usable, a * e_tilde, np.where(valid[..., None], col, 0.0))
    return out


def illumination_reference(color: Any, setup: IlluminationSetup, *, return_weights: bool = False):
    """Readable illumination filter (docs/methods/jbf.md §2.2 steps 2-5, float64).

    The whole colour is filtered: there is no direct/indirect split in this post-process
    variant (L_dir = 0, L_ind = color).

    Returns:
        (H, W, 3) float64; with ``return_weights`` also the (O, H, W, 3) weights w_{p←p'} per
        offset (the centre offset holds w_pp), for checks.
    """
    g = setup.guide
    h, w = g.shape
    col, valid, usable, e, v = _illumination_inputs(color, setup)
    num = np.zeros((h, w, 3))
    den = np.zeros((h, w, 3))
    stack = []
    C = math.exp(setup.log_c)
    for k in range(len(g.dy)):
        dy, dx = int(g.dy[k]), int(g.dx[k])
        wk = np.zeros((h, w, 3))
        if dy != 0 or dx != 0:
            (ys, xs), (yn, xn) = shift_slices(dy, dx, h, w)
            if ys.start < ys.stop and xs.start < xs.stop:
                n_i, n_j = setup.normal[ys, xs], setup.normal[yn, xn]
                dot = np.sum(n_i * n_j, axis=-1)
                gk = np.exp(-setup.alpha * (dx * dx + dy * dy)) * np.exp(-setup.beta * (1.0 - dot))
                for f, iv in zip(g.features, g.inv_var):      # optional position term
                    gk = gk * np.exp(-0.5 * iv * (f[yn, xn] - f[ys, xs]) ** 2)
                gk = gk * (dot > 0) * (g.labels[ys, xs] == g.labels[yn, xn])
                wk[ys, xs] = C * gk[..., None] * v[yn, xn]
                num[ys, xs] += wk[ys, xs] * e[yn, xn]
                den += wk
        stack.append(wk)
    out = _illumination_combine(col, valid, usable, e, v, setup, num, den)
    if return_weights:
        ws = np.stack(stack)
        centre = int(np.flatnonzero((g.dy == 0) & (g.dx == 0))[0])
        ws[centre] = np.where(v, 1.0 - den, 0.0)
        return out, ws
    return out


def illumination_fast(color: Any, setup: IlluminationSetup) -> np.ndarray:
    """Numba illumination filter, same kernel as the JBF (float32 weights): (H, W, 3) float32."""
    col, valid, usable, e, v = _illumination_inputs(color, setup)
    planes = np.concatenate([np.moveaxis(e, -1, 0), np.moveaxis(v, -1, 0).astype(np.float64)])
    if math.isinf(setup.log_c):
        sums = np.zeros(planes.shape)
    else:
        sums = accumulate(setup.guide, planes, dot_normal=np.moveaxis(setup.normal, -1, 0),
                          beta=setup.beta, horizon=True, extra_exponent=-setup.log_c)
    num = np.moveaxis(sums[:3], 0, -1)
    den = np.moveaxis(sums[3:], 0, -1)
    out = _illumination_combine(col, valid, usable, e, v, setup, num, den)
    return out.astype(np.float32)


def illumination_filter(color: Any, albedo: Any, normal: Any, depth: Any = None,
                        position: Any = None, *, backend: str = "numba",
                        **options: Any) -> np.ndarray:
    """Seed-002 effective-illumination filter as a post-process (docs/methods/jbf.md §2.2, simplified).

    E = color/albedo per channel (channels with albedo ≤ eps_albedo pass through unfiltered and
    are not neighbours), weights C·exp(−α|o|²)·exp(−β(1 − n·n'))·[exp(−|ΔP|²/2σ_P²)]·H(n·n')
    from noise-free data only (no colour term), self-weight w_pp = 1 − Σ w ≥ self_weight_min,
    then remodulation L = a ⊙ Ẽ. No direct/indirect split: the whole colour is filtered.

    Args:
        color, albedo, normal: (H, W, 3); depth (H, W, 1) or None; position (H, W, 3) with
            ``use_position``.
        backend: ``"numba"`` (default) or ``"reference"``.
        **options: :func:`make_illumination_setup` keywords (radius, window, alpha, beta,
            self_weight_min, eps_albedo, use_position, sigma_P, hit_mask).

    Returns:
        (H, W, 3) float32.
    """
    backend = resolve_backend(backend, allow_torch=False)
    if backend == "torch":
        backend = "numba"
    setup = make_illumination_setup(albedo, normal, depth, position, shape=image_shape(color),
                                    **options)
    if backend == "reference":
        return illumination_reference(color, setup).astype(np.float32)
    return illumination_fast(color, setup)
