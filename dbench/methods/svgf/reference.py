"""SVGF / A-SVGF, readable NumPy reference (float64, exact ``exp``; docs/methods/svgf.md): albedo
demodulation, depth gradients, the edge-stopping à-trous iteration, the spatial variance
estimate, A-SVGF temporal gradients and adaptive history.

Layout: planar images, colour (3, H, W), scalars (H, W), normals (3, H, W).

À-trous iteration with step s (docs/methods/svgf.md §3, §5), for centre p and tap q = p + s·o, o ∈ {−2..2}²::

    w_n = max(0, n_p·n_q)^σ_n
    w_z = exp(−|z_p − z_q| / (σ_z·|∇z_p·(s·o)| + ε_z))
    w_l = exp(−|l_p − l_q| / (σ_l·sqrt(g₃ₓ₃(Var)_p + ε_var)))
    I'(p)   = Σ h(o) w I(q) / Σ h(o) w
    Var'(p) = Σ h(o)² w² Var(q) / (Σ h(o) w)²

The centre has w = 1. Taps outside the image, without hit or missing (empty history) get
w = 0; a pixel without hit is only its own centre tap. A missing centre (no usable sample and no
history) contributes nothing; if nothing contributes the output is 0.
"""
from __future__ import annotations

import numpy as np

from ...data import check_buffer
from ..temporal import luminance
from .params import ALBEDO_FLOOR, EPS_VAR, EPS_Z, G3, H1, SPATIAL_RADIUS


def demodulation_albedo(albedo: np.ndarray, floor: float = ALBEDO_FLOOR) -> np.ndarray:
    """a_eff (3, H, W) float32: the albedo clipped to [floor, 1] where it is finite, else 1
    ([dbench] rule of :data:`~.params.ALBEDO_FLOOR`, in place of docs/methods/svgf.md §2's "> 1e-3, else 1");
    values above 1 (unphysical: e.g. Mitsuba's albedo AOV of rough conductors) count as 1."""
    a = np.asarray(albedo, np.float32)
    return np.where(np.isfinite(a), np.clip(a, np.float32(floor), np.float32(1.0)),
                    np.float32(1.0)).astype(np.float32)


def emission_planar(emission, h: int, w: int) -> np.ndarray:
    """The optional ``emission`` buffer (H, W, 3) as planar (3, H, W) float32; zeros when
    absent; non-finite or negative values count as 0."""
    if emission is None:
        return np.zeros((3, h, w), np.float32)
    e = check_buffer("emission", emission, (h, w, 3))
    e = np.where(np.isfinite(e) & (e > 0), e, 0.0)
    return np.ascontiguousarray(e.transpose(2, 0, 1), dtype=np.float32)


def prepare_reference(color: np.ndarray, albedo: np.ndarray, emission: np.ndarray | None,
                      hit: np.ndarray, albedo_floor: float = ALBEDO_FLOOR
                      ) -> dict[str, np.ndarray]:
    """Per-frame inputs of SVGF/BMFR from interleaved (H, W, 3) buffers (NumPy reference).

    Returns planar float32 ``illum`` = (C − E)/a_eff (0 where the sample is missing), ``a_eff``,
    ``emission``, ``moments`` [l, l²] of ``illum``, ``lum_raw`` (luminance of C, NaN where
    missing) and bool ``present`` (colour finite), ``emitter`` (hit and E > 0).
    """
    c = np.ascontiguousarray(np.transpose(color, (2, 0, 1)), np.float32)
    h, w = c.shape[1:]
    present = np.isfinite(c).all(0)
    a_eff = demodulation_albedo(np.transpose(albedo, (2, 0, 1)), albedo_floor)
    e = emission_planar(emission, h, w)
    illum = np.where(present, (c - e) / a_eff, 0.0).astype(np.float32)
    lum = luminance(illum)
    lum_raw = np.where(present, luminance(np.where(present, c, 0.0)), np.nan).astype(np.float32)
    return {"illum": illum, "a_eff": a_eff, "emission": e, "present": present,
            "emitter": hit & (e.max(0) > 0), "moments": np.stack([lum, lum * lum]),
            "lum_raw": lum_raw}


def remodulate_reference(illum: np.ndarray, a_eff: np.ndarray, emission: np.ndarray) -> np.ndarray:
    """(H, W, 3) float32 output = a_eff · I + E from planar (3, H, W) buffers (NumPy)."""
    return np.ascontiguousarray(np.transpose(illum * a_eff + emission, (1, 2, 0)), np.float32)


def depth_gradient_reference(z: np.ndarray, hit: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`~dbench.methods.svgf.dispatch.depth_gradient` in NumPy (float64 differences,
    float32 out)."""
    z = np.asarray(z, np.float64)
    out = []
    for axis in (1, 0):
        zp = np.roll(z, -1, axis)
        zm = np.roll(z, 1, axis)
        hp = np.roll(hit, -1, axis)
        hm = np.roll(hit, 1, axis)
        n = z.shape[axis]
        idx = np.arange(n)
        first = (idx == 0).reshape((-1, 1) if axis == 0 else (1, -1))
        last = (idx == n - 1).reshape((-1, 1) if axis == 0 else (1, -1))
        hp = hp & ~last
        hm = hm & ~first
        fwd, bwd = zp - z, z - zm
        both = np.where(np.abs(fwd) <= np.abs(bwd), fwd, bwd)
        g = np.where(hp & hm, both, np.where(hp, fwd, np.where(hm, bwd, 0.0)))
        out.append(np.where(hit, g, 0.0).astype(np.float32))
    return out[0], out[1]


def blur3(var: np.ndarray) -> np.ndarray:
    """g₃ₓ₃(Var): separable (1, 2, 1)/4 blur with edge replication, (H, W) float64."""
    v = np.pad(np.asarray(var, np.float64), 1, mode="edge")
    v = G3[0] * v[:, :-2] + G3[1] * v[:, 1:-1] + G3[2] * v[:, 2:]
    return G3[0] * v[:-2] + G3[1] * v[1:-1] + G3[2] * v[2:]


def normal_weight(dot: np.ndarray, sigma_n: float) -> np.ndarray:
    """w_n = max(0, n·n')^σ_n (docs/methods/svgf.md §3)."""
    return np.maximum(0.0, dot) ** sigma_n


def asvgf_history(n: np.ndarray | float, g: np.ndarray | float, n_max: float = 256.0):
    """A-SVGF adaptive history and blend (docs/methods/svgf.md §6.1): returns (N', α) with
    ``N' = min(N·(1 − G)^10 + 1, n_max)`` and ``α = mix(1/N', 1, G) = (1 − G)/N' + G``.

    >>> [round(float(v), 5) for v in asvgf_history(45, 0.01)]
    [41.69719, 0.03374]
    """
    n = np.asarray(n, np.float64)
    g = np.clip(np.asarray(g, np.float64), 0.0, 1.0)
    n_new = np.minimum(n * (1.0 - g) ** 10 + 1.0, n_max)
    return n_new, (1.0 - g) / n_new + g


def gradient_value(l_prev: np.ndarray, l_new: np.ndarray) -> np.ndarray:
    """G = (|L_new − L_prev| / max(L_prev, L_new))², 0 where the max is ≤ 0 (docs/methods/svgf.md §6.1)."""
    l_prev = np.asarray(l_prev, np.float64)
    l_new = np.asarray(l_new, np.float64)
    d = np.maximum(l_prev, l_new)
    with np.errstate(divide="ignore", invalid="ignore"):
        g = np.where(d > 0, (np.abs(l_new - l_prev) / d) ** 2, 0.0)
    return np.clip(np.nan_to_num(g, nan=0.0), 0.0, 1.0)


def _shift(a: np.ndarray, dy: int, dx: int, fill=0.0) -> np.ndarray:
    """out[..., y, x] = a[..., y + dy, x + dx] (``fill`` outside)."""
    out = np.full_like(a, fill)
    h, w = a.shape[-2:]
    ys, ye = max(0, -dy), min(h, h - dy)
    xs, xe = max(0, -dx), min(w, w - dx)
    if ys < ye and xs < xe:
        out[..., ys:ye, xs:xe] = a[..., ys + dy:ye + dy, xs + dx:xe + dx]
    return out


def atrous_reference(color, var, z, gx, gy, normal, tap, centre, hit, step, sigma_z=1.0,
                     sigma_n=128.0, sigma_l=4.0, eps_z=EPS_Z, eps_var=EPS_VAR, use_lum=True,
                     lum_kernel="laplacian"):
    """One à-trous iteration (docs/methods/svgf.md §5), readable NumPy in float64.

    Args:
        color: (3, H, W) demodulated colour I_i; var (H, W) its variance Var_i.
        z, gx, gy: (H, W) depth and its gradient; normal (3, H, W).
        tap: (H, W) bool, pixel usable as a neighbour (hit and not empty).
        centre: (H, W) bool, pixel's own value usable (not empty).
        hit: (H, W) bool, pixel may gather from neighbours.
        step: tap spacing 2^i. use_lum: False turns w_l off (A-SVGF gradient filter).
        lum_kernel: "laplacian", w_l = exp(−|l_p − l_q| / (σ_l √(g(Var)) + ε)) (docs/methods/svgf.md §3, the
        SVGF paper), or "gaussian", w_l = exp(−(|l_p − l_q| / (σ_l √(g(Var)) + ε))²) (Schied's
        A-SVGF code; :data:`~.params.LUM_KERNELS`).
    Returns:
        (color (3, H, W), var (H, W)), float64.
    """
    c = np.asarray(color, np.float64)
    v = np.asarray(var, np.float64)
    z = np.asarray(z, np.float64)
    n = np.asarray(normal, np.float64)
    lum = luminance(c)
    if use_lum:
        inv_sl = 1.0 / (sigma_l * np.sqrt(np.maximum(blur3(v), 0.0) + eps_var))
    else:
        inv_sl = np.zeros_like(z)
    tapf = np.asarray(tap, np.float64)
    h0 = H1[2] * H1[2]
    cen = np.asarray(centre, np.float64) * h0
    sw = cen.copy()
    sc = cen * c
    sv = cen * cen * v
    hitp = np.asarray(hit, np.float64)
    for oy in range(-2, 3):
        for ox in range(-2, 3):
            if ox == 0 and oy == 0:
                continue
            dy, dx = oy * step, ox * step
            nq = _shift(n, dy, dx)
            zq = _shift(z, dy, dx)
            lq = _shift(lum, dy, dx)
            tq = _shift(tapf, dy, dx)
            wn = normal_weight((n * nq).sum(0), sigma_n)
            wz = np.abs(z - zq) / (sigma_z * np.abs(gx * dx + gy * dy) + eps_z)
            wl = np.abs(lum - lq) * inv_sl
            if lum_kernel == "gaussian":
                wl = wl * wl
            w = H1[ox + 2] * H1[oy + 2] * wn * np.exp(-(wz + wl)) * tq * hitp
            sw += w
            sc += w * _shift(c, dy, dx)
            sv += w * w * _shift(v, dy, dx)
    with np.errstate(divide="ignore", invalid="ignore"):
        out_c = np.where(sw > 0, sc / sw, 0.0)
        out_v = np.where(sw > 0, sv / (sw * sw), 0.0)
    return out_c, out_v


def spatial_variance_reference(mom, z, gx, gy, normal, tap, hit, sigma_z=1.0, sigma_n=128.0,
                               eps_z=EPS_Z, radius=SPATIAL_RADIUS):
    """Spatial variance estimate (docs/methods/svgf.md §4) for every pixel: weights w_z·w_n over a
    (2r+1)² window of the moments (2, H, W); Var = max(0, m2 − m1²). (H, W) float64.

    The centre always counts (weight 1); neighbours need ``tap`` and the centre ``hit``.
    """
    m = np.asarray(mom, np.float64)
    z = np.asarray(z, np.float64)
    n = np.asarray(normal, np.float64)
    hitp = np.asarray(hit, np.float64)
    tapf = np.asarray(tap, np.float64)
    sw = np.ones_like(z)
    s1 = m[0].copy()
    s2 = m[1].copy()
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            if dx == 0 and dy == 0:
                continue
            wn = normal_weight((n * _shift(n, dy, dx)).sum(0), sigma_n)
            wz = np.exp(-np.abs(z - _shift(z, dy, dx))
                        / (sigma_z * np.abs(gx * dx + gy * dy) + eps_z))
            w = wn * wz * _shift(tapf, dy, dx) * hitp
            sw += w
            s1 += w * _shift(m[0], dy, dx)
            s2 += w * _shift(m[1], dy, dx)
    m1, m2 = s1 / sw, s2 / sw
    return np.maximum(0.0, m2 - m1 * m1)


def stratum_samples(l_prev: np.ndarray, usable: np.ndarray, size: int = 3
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The max-luminance usable pixel of every size×size stratum of the previous frame.

    Returns (qy, qx, has) each (ceil(H/size), ceil(W/size)); ``has`` False for strata without
    a usable pixel. Ties go to the first pixel in row-major order inside the stratum.
    """
    h, w = l_prev.shape
    hs, ws = -(-h // size), -(-w // size)
    pad = np.full((hs * size, ws * size), -np.inf)
    pad[:h, :w] = np.where(usable, l_prev, -np.inf)
    blocks = pad.reshape(hs, size, ws, size).transpose(0, 2, 1, 3).reshape(hs, ws, size * size)
    k = np.argmax(blocks, axis=-1)
    has = np.isfinite(np.take_along_axis(blocks, k[..., None], -1)[..., 0])
    qy = np.arange(hs)[:, None] * size + k // size
    qx = np.arange(ws)[None, :] * size + k % size
    return np.minimum(qy, h - 1), np.minimum(qx, w - 1), has


def stratum_gradients_reference(l_prev, l_grad, prev_hit, prev_depth, prev_normal, size=3):
    """:func:`~dbench.methods.svgf.dispatch.stratum_gradients` in NumPy."""
    usable = prev_hit & np.isfinite(l_prev) & np.isfinite(l_grad)
    qy, qx, has = stratum_samples(l_prev, usable, size)
    lp = np.where(has, l_prev[qy, qx], 0.0)
    lg = np.where(has, l_grad[qy, qx], 0.0)
    return {"delta": (lg - lp).astype(np.float32), "norm": np.maximum(lp, lg).astype(np.float32),
            "g": gradient_value(lp, lg).astype(np.float32), "has": has,
            "depth": np.where(has, prev_depth[qy, qx], 0.0).astype(np.float32),
            "normal": np.where(has, prev_normal[:, qy, qx], 0.0).astype(np.float32)}


def gradient_at_pixels(low: np.ndarray, motion: np.ndarray, hit: np.ndarray, size: int = 3
                       ) -> np.ndarray:
    """Full-resolution (H, W) values of a stratum image of frame i−1, gathered through the motion
    vectors of frame i: pixel p reads the stratum holding round(p + motion(p)); 0 where the
    motion is unknown, the pixel has no hit or p← falls outside the image.

    This is the gather form of the spec's forward projection (docs/methods/svgf.md §6.4); with a static camera
    (motion 0) both are the nearest-neighbour upsampling of the stratum image.
    """
    h, w = hit.shape
    yy, xx = np.mgrid[0:h, 0:w]
    with np.errstate(invalid="ignore"):
        qx = np.floor(xx + motion[0] + 0.5)
        qy = np.floor(yy + motion[1] + 0.5)
    ok = hit & np.isfinite(qx) & np.isfinite(qy) & (qx >= 0) & (qy >= 0) & (qx < w) & (qy < h)
    sy = np.where(ok, qy, 0).astype(np.int64) // size
    sx = np.where(ok, qx, 0).astype(np.int64) // size
    return np.where(ok, low[sy, sx], 0.0).astype(np.float32)


def adaptive_history_reference(low, motion, hit, n_hist, n_max=256.0, mode="seed", alpha0=0.2,
                               size=3):
    """:func:`~dbench.methods.svgf.dispatch.adaptive_history` in NumPy."""
    g = gradient_at_pixels(np.clip(np.nan_to_num(low), 0, 1), motion, hit, size)
    n_new, a = asvgf_history(n_hist, g, n_max)
    if mode == "paper":
        a = np.maximum((1 - g) * alpha0 + g, 1.0 / n_new)
    return g, n_new.astype(np.float32), a.astype(np.float32)
