"""SVGF / A-SVGF functional core (spec/svgf.md): edge-stopping à-trous, variance estimates,
albedo demodulation, A-SVGF temporal gradients and adaptive history.

Layout: planar float32 images, colour (3, H, W), scalars (H, W), normals (3, H, W).

Every filter has a readable NumPy reference (float64, exact ``exp``) and a compiled Numba fast
path (float32, parallel over rows, inner loops over x written so that LLVM vectorises them, and a
polynomial ``exp``: relative error ≤ 2e-5 on the weights). Tests prove them equal within 1e-4
(relative to the image scale) — see tests/methods/test_svgf.py. The ``"torch"`` backend
(:mod:`dbench.methods.svgf.torch_core`: vectorised PyTorch, CUDA when available, else CPU) is
reached through the same dispatchers (:func:`prepare`, :func:`depth_gradient`, :func:`atrous`,
:func:`spatial_variance`, :func:`remodulate`, :func:`stratum_gradients`,
:func:`adaptive_history`), which take and return NumPy.

À-trous iteration with step s (spec §3, §5), for centre p and tap q = p + s·o, o ∈ {−2..2}²::

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

import math

import numpy as np

from ...errors import DbenchInputError
from ..temporal import LUMA, luminance, to_numpy

try:
    from numba import njit, prange
    HAVE_NUMBA = True
except ImportError:  # pragma: no cover
    HAVE_NUMBA = False

#: B3-spline taps h1 (spec §5).
H1 = np.array([1 / 16, 1 / 4, 3 / 8, 1 / 4, 1 / 16])
#: 3×3 Gaussian (1,2,1)ᵀ(1,2,1)/16 that blurs the variance before each iteration (spec §3).
G3 = np.array([0.25, 0.5, 0.25])
EPS_Z = 1e-6       # [dbench]
EPS_VAR = 1e-4     # [Falcor varianceEpsilon]
ALBEDO_EPS = np.float32(1e-3)  # spec §2
N_SPATIAL = 4      # history below this: spatial variance (spec §4)
SPATIAL_RADIUS = 3  # 7×7 window


# ---------------------------------------------------------------------------------------------
# small pieces


def demodulation_albedo(albedo: np.ndarray) -> np.ndarray:
    """a_eff (3, H, W) float32: the albedo where it is finite and > 1e-3, else 1 (spec §2);
    values above 1 (unphysical: e.g. Mitsuba's albedo AOV of rough conductors) count as 1."""
    a = np.asarray(albedo, np.float32)
    return np.where(np.isfinite(a) & (a > ALBEDO_EPS), np.minimum(a, 1.0), 1.0).astype(np.float32)


def emission_planar(emission, h: int, w: int) -> np.ndarray:
    """The optional ``emission`` buffer (H, W, 3) as planar (3, H, W) float32; zeros when
    absent; non-finite or negative values count as 0."""
    if emission is None:
        return np.zeros((3, h, w), np.float32)
    from ...data import check_buffer
    e = check_buffer("emission", emission, (h, w, 3))
    e = np.where(np.isfinite(e) & (e > 0), e, 0.0)
    return np.ascontiguousarray(e.transpose(2, 0, 1), dtype=np.float32)


def prepare_reference(color: np.ndarray, albedo: np.ndarray, emission: np.ndarray | None,
                      hit: np.ndarray) -> dict[str, np.ndarray]:
    """Per-frame inputs of SVGF/BMFR from interleaved (H, W, 3) buffers (NumPy reference).

    Returns planar float32 ``illum`` = (C − E)/a_eff (0 where the sample is missing), ``a_eff``,
    ``emission``, ``moments`` [l, l²] of ``illum``, ``lum_raw`` (luminance of C, NaN where
    missing) and bool ``present`` (colour finite), ``emitter`` (hit and E > 0).
    """
    c = np.ascontiguousarray(np.transpose(color, (2, 0, 1)), np.float32)
    h, w = c.shape[1:]
    present = np.isfinite(c).all(0)
    a_eff = demodulation_albedo(np.transpose(albedo, (2, 0, 1)))
    e = emission_planar(emission, h, w)
    illum = np.where(present, (c - e) / a_eff, 0.0).astype(np.float32)
    lum = luminance(illum)
    lum_raw = np.where(present, luminance(np.where(present, c, 0.0)), np.nan).astype(np.float32)
    return {"illum": illum, "a_eff": a_eff, "emission": e, "present": present,
            "emitter": hit & (e.max(0) > 0), "moments": np.stack([lum, lum * lum]),
            "lum_raw": lum_raw}


def prepare(backend: str, color, albedo, emission, hit) -> dict[str, np.ndarray]:
    """:func:`prepare_reference` on ``backend`` ("numba": :func:`prepare_fast`, "torch":
    :func:`~dbench.methods.svgf.torch_core.prepare_torch`); NumPy out."""
    if backend == "torch":
        from .torch_core import prepare_torch
        return {k: to_numpy(v) for k, v in prepare_torch(color, albedo, emission, hit).items()}
    if backend == "numba" and HAVE_NUMBA:
        return prepare_fast(color, albedo, emission, hit)
    return prepare_reference(color, albedo, emission, hit)


def prepare_fast(color, albedo, emission, hit) -> dict[str, np.ndarray]:
    """Compiled :func:`prepare_reference` (one parallel pass)."""
    from ...data import check_buffer
    h, w = color.shape[:2]
    e_in = np.zeros((0, 0, 3), np.float32) if emission is None else \
        check_buffer("emission", emission, (h, w, 3))
    out = {"illum": np.empty((3, h, w), np.float32), "a_eff": np.empty((3, h, w), np.float32),
           "emission": np.empty((3, h, w), np.float32), "present": np.empty((h, w), np.bool_),
           "emitter": np.empty((h, w), np.bool_), "moments": np.empty((2, h, w), np.float32),
           "lum_raw": np.empty((h, w), np.float32)}
    _prepare_nb(np.ascontiguousarray(color, np.float32), np.ascontiguousarray(albedo, np.float32),
                e_in, np.ascontiguousarray(hit, np.bool_), out["illum"], out["a_eff"],
                out["emission"], out["present"], out["emitter"], out["moments"], out["lum_raw"])
    return out


def remodulate(illum: np.ndarray, a_eff: np.ndarray, emission: np.ndarray,
               backend: str = "numba") -> np.ndarray:
    """(H, W, 3) float32 output = a_eff · I + E from planar (3, H, W) buffers."""
    if backend == "torch":
        from .torch_core import remodulate_torch
        return np.ascontiguousarray(to_numpy(remodulate_torch(illum, a_eff, emission)))
    if backend == "reference" or not HAVE_NUMBA:
        return np.ascontiguousarray(np.transpose(illum * a_eff + emission, (1, 2, 0)), np.float32)
    out = np.empty(illum.shape[1:] + (3,), np.float32)
    _remodulate_nb(np.ascontiguousarray(illum, np.float32), a_eff, emission, out)
    return out


def depth_gradient(z: np.ndarray, hit: np.ndarray, backend: str = "reference"
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Screen-space depth gradient (gx, gy), each (H, W) float32, in depth units per pixel.

    Where both neighbours are hit surfaces: the one-sided difference of smaller magnitude
    (equal to the central difference on planes, where both agree; at a depth discontinuity it is
    the difference on the pixel's own side — the spec's central difference would put half the
    step into the gradient there and let the depth weight pass taps across the step, failing
    spec/svgf.md §9 check 5). One-sided next to borders and pixels without hit, 0 where
    neither neighbour is usable or the pixel itself has no hit.
    """
    if backend == "torch":
        from .torch_core import depth_gradient_torch
        return tuple(to_numpy(g) for g in depth_gradient_torch(z, hit))
    if backend == "numba" and HAVE_NUMBA:
        gx = np.empty(z.shape, np.float32)
        gy = np.empty(z.shape, np.float32)
        _depth_gradient_nb(np.ascontiguousarray(z, np.float32), np.ascontiguousarray(hit, np.bool_),
                           gx, gy)
        return gx, gy
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
    """w_n = max(0, n·n')^σ_n (spec §3)."""
    return np.maximum(0.0, dot) ** sigma_n


def asvgf_history(n: np.ndarray | float, g: np.ndarray | float, n_max: float = 256.0):
    """A-SVGF adaptive history and blend (spec §6.1): returns (N', α) with
    ``N' = min(N·(1 − G)^10 + 1, n_max)`` and ``α = mix(1/N', 1, G) = (1 − G)/N' + G``.

    >>> [round(float(v), 5) for v in asvgf_history(45, 0.01)]
    [41.69719, 0.03374]
    """
    n = np.asarray(n, np.float64)
    g = np.clip(np.asarray(g, np.float64), 0.0, 1.0)
    n_new = np.minimum(n * (1.0 - g) ** 10 + 1.0, n_max)
    return n_new, (1.0 - g) / n_new + g


def gradient_value(l_prev: np.ndarray, l_new: np.ndarray) -> np.ndarray:
    """G = (|L_new − L_prev| / max(L_prev, L_new))², 0 where the max is ≤ 0 (spec §6.1)."""
    l_prev = np.asarray(l_prev, np.float64)
    l_new = np.asarray(l_new, np.float64)
    d = np.maximum(l_prev, l_new)
    with np.errstate(divide="ignore", invalid="ignore"):
        g = np.where(d > 0, (np.abs(l_new - l_prev) / d) ** 2, 0.0)
    return np.clip(np.nan_to_num(g, nan=0.0), 0.0, 1.0)


if HAVE_NUMBA:
    @njit(cache=True, parallel=True, error_model="numpy")
    def _prepare_nb(color, albedo, emission, hit, illum, a_eff, emis, present, emitter, mom,
                    lum_raw):
        h, w = color.shape[:2]
        has_e = emission.shape[0] > 0
        l0, l1, l2 = np.float32(LUMA[0]), np.float32(LUMA[1]), np.float32(LUMA[2])
        for y in prange(h):
            for x in range(w):
                ok = True
                for k in range(3):
                    ok = ok and np.isfinite(color[y, x, k])
                present[y, x] = ok
                emax = np.float32(0.0)
                for k in range(3):
                    a = albedo[y, x, k]
                    a = min(a, np.float32(1.0)) if (np.isfinite(a) and a > ALBEDO_EPS) \
                        else np.float32(1.0)
                    a_eff[k, y, x] = a
                    e = np.float32(0.0)
                    if has_e:
                        e = emission[y, x, k]
                        if not (np.isfinite(e) and e > 0):
                            e = np.float32(0.0)
                    emis[k, y, x] = e
                    emax = max(emax, e)
                    illum[k, y, x] = (color[y, x, k] - e) / a if ok else np.float32(0.0)
                emitter[y, x] = hit[y, x] and emax > 0
                lum = l0 * illum[0, y, x] + l1 * illum[1, y, x] + l2 * illum[2, y, x]
                mom[0, y, x] = lum
                mom[1, y, x] = lum * lum
                lum_raw[y, x] = (l0 * color[y, x, 0] + l1 * color[y, x, 1]
                                 + l2 * color[y, x, 2]) if ok else np.float32(np.nan)

    @njit(cache=True, parallel=True)
    def _remodulate_nb(illum, a_eff, emis, out):
        _, h, w = illum.shape
        for y in prange(h):
            for x in range(w):
                for k in range(3):
                    out[y, x, k] = illum[k, y, x] * a_eff[k, y, x] + emis[k, y, x]

    @njit(cache=True, parallel=True)
    def _depth_gradient_nb(z, hit, gx, gy):
        h, w = z.shape
        for y in prange(h):
            for x in range(w):
                if not hit[y, x]:
                    gx[y, x] = 0.0
                    gy[y, x] = 0.0
                    continue
                zc = np.float64(z[y, x])
                hp = x + 1 < w and hit[y, x + 1]
                hm = x > 0 and hit[y, x - 1]
                if hp and hm:
                    f = np.float64(z[y, x + 1]) - zc
                    b = zc - np.float64(z[y, x - 1])
                    g = f if abs(f) <= abs(b) else b
                elif hp:
                    g = np.float64(z[y, x + 1]) - zc
                elif hm:
                    g = zc - np.float64(z[y, x - 1])
                else:
                    g = 0.0
                gx[y, x] = g
                hp = y + 1 < h and hit[y + 1, x]
                hm = y > 0 and hit[y - 1, x]
                if hp and hm:
                    f = np.float64(z[y + 1, x]) - zc
                    b = zc - np.float64(z[y - 1, x])
                    g = f if abs(f) <= abs(b) else b
                elif hp:
                    g = np.float64(z[y + 1, x]) - zc
                elif hm:
                    g = zc - np.float64(z[y - 1, x])
                else:
                    g = 0.0
                gy[y, x] = g


# ---------------------------------------------------------------------------------------------
# à-trous: reference


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
                     sigma_n=128.0, sigma_l=4.0, eps_z=EPS_Z, eps_var=EPS_VAR, use_lum=True):
    """One à-trous iteration (spec §5), readable NumPy in float64.

    Args:
        color: (3, H, W) demodulated colour I_i; var (H, W) its variance Var_i.
        z, gx, gy: (H, W) depth and its gradient; normal (3, H, W).
        tap: (H, W) bool, pixel usable as a neighbour (hit and not empty).
        centre: (H, W) bool, pixel's own value usable (not empty).
        hit: (H, W) bool, pixel may gather from neighbours.
        step: tap spacing 2^i. use_lum: False turns w_l off (A-SVGF gradient filter).
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
    """Spatial variance estimate (spec §4) for every pixel: weights w_z·w_n over a
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


# ---------------------------------------------------------------------------------------------
# à-trous: compiled fast path

_F0 = np.float32(0.0)
_F1 = np.float32(1.0)
_EXP_CLAMP = np.float32(30.0)
_INV64 = np.float32(1.0 / 64.0)
_CHUNK = 256  # pixels per chunk of the à-trous row loop
#: Taylor coefficients of e^−y: (−1)^k / k!
_P1, _P2, _P3, _P4, _P5, _P6, _P7 = (np.float32((-1) ** k / math.factorial(k)) for k in range(1, 8))

if HAVE_NUMBA:
    @njit(cache=True, inline="always", fastmath=True, error_model="numpy")
    def fast_exp_neg(x):
        """exp(−x) for x ≥ 0 in float32 without a vector math library: exp(−x/64)^64 with a
        degree-7 Taylor polynomial; relative error ≤ 2e-5, arguments above 30 give e^−30."""
        y = min(x, _EXP_CLAMP) * _INV64
        p = _P7
        p = p * y + _P6
        p = p * y + _P5
        p = p * y + _P4
        p = p * y + _P3
        p = p * y + _P2
        p = p * y + _P1
        p = p * y + _F1
        p = p * p
        p = p * p
        p = p * p
        p = p * p
        p = p * p
        return p * p

    @njit(cache=True, parallel=True, fastmath=True, error_model="numpy")
    def _atrous_nb(c, var, z, gx, gy, nrm, tap, centre, hitp, step, sigma_z, sigma_n, sigma_l,
                   eps_z, eps_var, use_lum, h1, out_c, out_v):
        _, h, w = c.shape
        lum = np.empty((h, w), np.float32)
        isl = np.empty((h, w), np.float32)
        for y in prange(h):  # one parallel region for both pre-passes
            for x in range(w):
                lum[y, x] = (np.float32(LUMA[0]) * c[0, y, x] + np.float32(LUMA[1]) * c[1, y, x]
                             + np.float32(LUMA[2]) * c[2, y, x])
            ym = max(y - 1, 0)
            yp = min(y + 1, h - 1)
            for x in range(w):
                xm = max(x - 1, 0)
                xp = min(x + 1, w - 1)
                if use_lum:
                    g = (0.25 * (0.25 * var[ym, xm] + 0.5 * var[ym, x] + 0.25 * var[ym, xp])
                         + 0.5 * (0.25 * var[y, xm] + 0.5 * var[y, x] + 0.25 * var[y, xp])
                         + 0.25 * (0.25 * var[yp, xm] + 0.5 * var[yp, x] + 0.25 * var[yp, xp]))
                    isl[y, x] = np.float32(1.0 / (sigma_l * math.sqrt(max(g, 0.0) + eps_var)))
                else:
                    isl[y, x] = _F0
        sz = np.float32(sigma_z)
        ez = np.float32(eps_z)
        sn = np.float32(sigma_n)
        is128 = sigma_n == 128.0
        h0 = np.float32(h1[2] * h1[2])
        for y in prange(h):
            sw = np.empty(_CHUNK, np.float32)
            s0 = np.empty(_CHUNK, np.float32)
            s1 = np.empty(_CHUNK, np.float32)
            s2 = np.empty(_CHUNK, np.float32)
            sv = np.empty(_CHUNK, np.float32)
            nx, ny, nz = nrm[0, y], nrm[1, y], nrm[2, y]
            zr, gxr, gyr, lr, ir, hr = z[y], gx[y], gy[y], lum[y], isl[y], hitp[y]
            # chunks of _CHUNK pixels keep the centre data and the sums in L1 over all 25 taps
            for x0 in range(0, w, _CHUNK):
                x1 = min(x0 + _CHUNK, w)
                for x in range(x0, x1):
                    wc = h0 * centre[y, x]
                    sw[x - x0] = wc
                    s0[x - x0] = wc * c[0, y, x]
                    s1[x - x0] = wc * c[1, y, x]
                    s2[x - x0] = wc * c[2, y, x]
                    sv[x - x0] = wc * wc * var[y, x]
                for oy in range(-2, 3):
                    yq = y + oy * step
                    if yq < 0 or yq >= h:
                        continue
                    nxq, nyq, nzq = nrm[0, yq], nrm[1, yq], nrm[2, yq]
                    zq, lq, tq, vq = z[yq], lum[yq], tap[yq], var[yq]
                    c0q, c1q, c2q = c[0, yq], c[1, yq], c[2, yq]
                    for ox in range(-2, 3):
                        if ox == 0 and oy == 0:
                            continue
                        dx = ox * step
                        fx = np.float32(dx)
                        fy = np.float32(oy * step)
                        hk = np.float32(h1[ox + 2] * h1[oy + 2])
                        xs = max(x0, -dx)
                        xe = min(x1, w - dx)
                        if xe <= xs:
                            continue
                        # 1-D views starting at 0, so every index is the loop counter (no
                        # negative index handling): the loops below vectorise.
                        a_nx, a_ny, a_nz = nx[xs:xe], ny[xs:xe], nz[xs:xe]
                        a_z, a_gx, a_gy = zr[xs:xe], gxr[xs:xe], gyr[xs:xe]
                        a_l, a_i, a_h = lr[xs:xe], ir[xs:xe], hr[xs:xe]
                        qs, qe = xs + dx, xe + dx
                        b_nx, b_ny, b_nz = nxq[qs:qe], nyq[qs:qe], nzq[qs:qe]
                        b_z, b_l, b_t, b_v = zq[qs:qe], lq[qs:qe], tq[qs:qe], vq[qs:qe]
                        b_0, b_1, b_2 = c0q[qs:qe], c1q[qs:qe], c2q[qs:qe]
                        os_, oe = xs - x0, xe - x0
                        o_w, o_0, o_1 = sw[os_:oe], s0[os_:oe], s1[os_:oe]
                        o_2, o_v = s2[os_:oe], sv[os_:oe]
                        if is128:
                            for i in range(xe - xs):
                                d = max(a_nx[i] * b_nx[i] + a_ny[i] * b_ny[i]
                                        + a_nz[i] * b_nz[i], _F0)
                                d = d * d
                                d = d * d
                                d = d * d
                                d = d * d
                                d = d * d
                                d = d * d
                                d = d * d
                                den = sz * abs(a_gx[i] * fx + a_gy[i] * fy) + ez
                                e = abs(a_z[i] - b_z[i]) / den + abs(a_l[i] - b_l[i]) * a_i[i]
                                wt = hk * d * fast_exp_neg(e) * b_t[i] * a_h[i]
                                o_w[i] += wt
                                o_0[i] += wt * b_0[i]
                                o_1[i] += wt * b_1[i]
                                o_2[i] += wt * b_2[i]
                                o_v[i] += wt * wt * b_v[i]
                        else:  # any other exponent: scalar pow, slower
                            for i in range(xe - xs):
                                d = max(a_nx[i] * b_nx[i] + a_ny[i] * b_ny[i]
                                        + a_nz[i] * b_nz[i], _F0)
                                d = d ** sn
                                den = sz * abs(a_gx[i] * fx + a_gy[i] * fy) + ez
                                e = abs(a_z[i] - b_z[i]) / den + abs(a_l[i] - b_l[i]) * a_i[i]
                                wt = hk * d * fast_exp_neg(e) * b_t[i] * a_h[i]
                                o_w[i] += wt
                                o_0[i] += wt * b_0[i]
                                o_1[i] += wt * b_1[i]
                                o_2[i] += wt * b_2[i]
                                o_v[i] += wt * wt * b_v[i]
                for x in range(x0, x1):
                    k = x - x0
                    if sw[k] > _F0:
                        inv = _F1 / sw[k]
                        out_c[0, y, x] = s0[k] * inv
                        out_c[1, y, x] = s1[k] * inv
                        out_c[2, y, x] = s2[k] * inv
                        out_v[y, x] = sv[k] * inv * inv
                    else:
                        out_c[0, y, x] = _F0
                        out_c[1, y, x] = _F0
                        out_c[2, y, x] = _F0
                        out_v[y, x] = _F0

    @njit(cache=True, parallel=True, fastmath=True, error_model="numpy")
    def _spatial_variance_nb(mom, z, gx, gy, nrm, tap, hit, select, sigma_z, sigma_n, eps_z,
                             radius, out):
        _, h, w = mom.shape
        for y in prange(h):
            for x in range(w):
                if not select[y, x]:
                    continue
                sw = 1.0
                s1 = np.float64(mom[0, y, x])
                s2 = np.float64(mom[1, y, x])
                if hit[y, x]:
                    for yq in range(max(0, y - radius), min(h, y + radius + 1)):
                        for xq in range(max(0, x - radius), min(w, x + radius + 1)):
                            if (yq == y and xq == x) or not tap[yq, xq]:
                                continue
                            d = (nrm[0, y, x] * nrm[0, yq, xq] + nrm[1, y, x] * nrm[1, yq, xq]
                                 + nrm[2, y, x] * nrm[2, yq, xq])
                            if d <= 0:
                                continue
                            wt = math.exp(sigma_n * math.log(d) - abs(z[y, x] - z[yq, xq]) / (
                                sigma_z * abs(gx[y, x] * (xq - x) + gy[y, x] * (yq - y))
                                + eps_z))
                            sw += wt
                            s1 += wt * mom[0, yq, xq]
                            s2 += wt * mom[1, yq, xq]
                m1 = s1 / sw
                out[y, x] = max(0.0, s2 / sw - m1 * m1)


def atrous_fast(color, var, z, gx, gy, normal, tap, centre, hit, step, sigma_z=1.0,
                sigma_n=128.0, sigma_l=4.0, eps_z=EPS_Z, eps_var=EPS_VAR, use_lum=True):
    """Compiled :func:`atrous_reference` (same arguments), float32 outputs."""
    f32 = lambda a: np.ascontiguousarray(a, np.float32)  # noqa: E731
    c = f32(color)
    out_c = np.empty_like(c)
    out_v = np.empty(c.shape[1:], np.float32)
    _atrous_nb(c, f32(var), f32(z), f32(gx), f32(gy), f32(normal), f32(tap), f32(centre),
               f32(hit), int(step), float(sigma_z), float(sigma_n), float(sigma_l), float(eps_z),
               float(eps_var), bool(use_lum), H1, out_c, out_v)
    return out_c, out_v


def spatial_variance_fast(mom, z, gx, gy, normal, tap, hit, select=None, sigma_z=1.0,
                          sigma_n=128.0, eps_z=EPS_Z, radius=SPATIAL_RADIUS):
    """Compiled :func:`spatial_variance_reference`, evaluated only where ``select`` (H, W) is
    True (0 elsewhere); float32 (H, W)."""
    mom = np.ascontiguousarray(mom, np.float32)
    h, w = mom.shape[1:]
    sel = np.ones((h, w), bool) if select is None else np.ascontiguousarray(select, np.bool_)
    out = np.zeros((h, w), np.float32)
    _spatial_variance_nb(mom, np.ascontiguousarray(z, np.float32),
                         np.ascontiguousarray(gx, np.float32), np.ascontiguousarray(gy, np.float32),
                         np.ascontiguousarray(normal, np.float32), np.ascontiguousarray(tap, np.bool_),
                         np.ascontiguousarray(hit, np.bool_), sel, float(sigma_z), float(sigma_n),
                         float(eps_z), int(radius), out)
    return out


def atrous(backend: str, *args, **kw):
    """One à-trous iteration on ``backend`` (arguments of :func:`atrous_reference`), float32
    NumPy (colour (3, H, W), variance (H, W))."""
    if backend == "torch":
        from .torch_core import atrous_torch
        c, v = atrous_torch(*args, **kw)
        return to_numpy(c), to_numpy(v)
    if backend == "reference" or not HAVE_NUMBA:
        c, v = atrous_reference(*args, **kw)
        return c.astype(np.float32), v.astype(np.float32)
    return atrous_fast(*args, **kw)


def spatial_variance(backend: str, mom, z, gx, gy, normal, tap, hit, select, **kw):
    """Spatial variance (spec §4) on ``backend`` where ``select``, 0 elsewhere: (H, W) float32."""
    if backend == "torch":
        from .torch_core import spatial_variance_torch
        return to_numpy(spatial_variance_torch(mom, z, gx, gy, normal, tap, hit, select, **kw))
    if backend == "reference" or not HAVE_NUMBA:
        v = spatial_variance_reference(mom, z, gx, gy, normal, tap, hit, **kw)
        return np.where(select, v, 0.0).astype(np.float32)
    return spatial_variance_fast(mom, z, gx, gy, normal, tap, hit, select, **kw)


# ---------------------------------------------------------------------------------------------
# A-SVGF temporal gradients (spec §6)


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


def stratum_gradients(l_prev, l_grad, prev_hit, prev_depth, prev_normal, size=3,
                      backend="reference"):
    """Per-stratum temporal gradient of spec §6.1/§6.4 at 1/size resolution.

    Args:
        l_prev: (H, W) luminance of frame i−1's noisy colour.
        l_grad: (H, W) luminance of frame i's gradient render (lights of i, camera, seeds of i−1).
        prev_hit, prev_depth, prev_normal: frame i−1's G-buffer ((H, W), (H, W), (3, H, W)).
    Returns:
        dict with ``delta``, ``norm`` (Δ), ``g`` (G), ``has`` (stratum usable), ``depth``,
        ``normal`` (3, hs, ws) of the chosen samples.
    """
    if backend == "torch":
        from .torch_core import stratum_gradients_torch
        out = stratum_gradients_torch(l_prev, l_grad, prev_hit, prev_depth, prev_normal, size)
        return {k: to_numpy(v) for k, v in out.items()}
    if backend == "numba" and HAVE_NUMBA:
        h, w = l_prev.shape
        hs, ws = -(-h // size), -(-w // size)
        out = {"delta": np.empty((hs, ws), np.float32), "norm": np.empty((hs, ws), np.float32),
               "g": np.empty((hs, ws), np.float32), "has": np.empty((hs, ws), np.bool_),
               "depth": np.empty((hs, ws), np.float32),
               "normal": np.empty((3, hs, ws), np.float32)}
        _strata_nb(np.ascontiguousarray(l_prev, np.float32), np.ascontiguousarray(l_grad, np.float32),
                   np.ascontiguousarray(prev_hit, np.bool_),
                   np.ascontiguousarray(prev_depth, np.float32),
                   np.ascontiguousarray(prev_normal, np.float32), size, out["delta"],
                   out["norm"], out["g"], out["has"], out["depth"], out["normal"])
        return out
    usable = prev_hit & np.isfinite(l_prev) & np.isfinite(l_grad)
    qy, qx, has = stratum_samples(l_prev, usable, size)
    lp = np.where(has, l_prev[qy, qx], 0.0)
    lg = np.where(has, l_grad[qy, qx], 0.0)
    return {"delta": (lg - lp).astype(np.float32), "norm": np.maximum(lp, lg).astype(np.float32),
            "g": gradient_value(lp, lg).astype(np.float32), "has": has,
            "depth": np.where(has, prev_depth[qy, qx], 0.0).astype(np.float32),
            "normal": np.where(has, prev_normal[:, qy, qx], 0.0).astype(np.float32)}


if HAVE_NUMBA:
    @njit(cache=True, error_model="numpy")
    def _strata_nb(l_prev, l_grad, hit, depth, normal, size, delta, norm, g, has, dep, nrm):
        h, w = l_prev.shape
        hs, ws = delta.shape
        for sy in range(hs):
            for sx in range(ws):
                best = -np.inf
                by = -1
                bx = -1
                for y in range(sy * size, min(sy * size + size, h)):
                    for x in range(sx * size, min(sx * size + size, w)):
                        lp = l_prev[y, x]
                        if hit[y, x] and np.isfinite(lp) and np.isfinite(l_grad[y, x]) \
                                and lp > best:
                            best = lp
                            by = y
                            bx = x
                if by < 0:
                    has[sy, sx] = False
                    delta[sy, sx] = 0.0
                    norm[sy, sx] = 0.0
                    g[sy, sx] = 0.0
                    dep[sy, sx] = 0.0
                    for k in range(3):
                        nrm[k, sy, sx] = 0.0
                    continue
                lp = np.float64(l_prev[by, bx])
                lg = np.float64(l_grad[by, bx])
                m = max(lp, lg)
                has[sy, sx] = True
                delta[sy, sx] = lg - lp
                norm[sy, sx] = m
                gg = (abs(lg - lp) / m) ** 2 if m > 0 else 0.0
                g[sy, sx] = min(max(gg, 0.0), 1.0)
                dep[sy, sx] = depth[by, bx]
                for k in range(3):
                    nrm[k, sy, sx] = normal[k, by, bx]


def filter_gradients(strata: dict, iterations: int = 3, sigma_z: float = 1.0,
                     sigma_n: float = 128.0, backend: str = "numba") -> dict:
    """À-trous (spec §5, w_l off) over the stratum image of [δ, Δ, G], ``iterations`` steps
    1, 2, 4 …; returns filtered ``delta``, ``norm``, ``g`` (hs, ws) float32."""
    img = np.stack([strata["delta"], strata["norm"], strata["g"]]).astype(np.float32)
    has = strata["has"]
    gx, gy = depth_gradient(strata["depth"], has)
    var = np.zeros(has.shape, np.float32)
    for i in range(iterations):
        img, _ = atrous(backend, img, var, strata["depth"], gx, gy, strata["normal"], has, has,
                        has, 2 ** i, sigma_z=sigma_z, sigma_n=sigma_n, use_lum=False)
    return {"delta": img[0], "norm": img[1], "g": np.clip(img[2], 0.0, 1.0)}


def gradient_at_pixels(low: np.ndarray, motion: np.ndarray, hit: np.ndarray, size: int = 3
                       ) -> np.ndarray:
    """Full-resolution (H, W) values of a stratum image of frame i−1, gathered through the motion
    vectors of frame i: pixel p reads the stratum holding round(p + motion(p)); 0 where the
    motion is unknown, the pixel has no hit or p← falls outside the image.

    This is the gather form of the spec's forward projection (spec §6.4); with a static camera
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


if HAVE_NUMBA:
    @njit(cache=True, parallel=True, error_model="numpy")
    def _adaptive_nb(low, motion, hit, n_hist, n_max, size, paper, alpha0, g_out, n_out, a_out):
        h, w = hit.shape
        hs, ws = low.shape
        for y in prange(h):
            for x in range(w):
                g = 0.0
                if hit[y, x]:
                    qx = math.floor(x + np.float64(motion[0, y, x]) + 0.5)
                    qy = math.floor(y + np.float64(motion[1, y, x]) + 0.5)
                    if qx >= 0 and qy >= 0 and qx < w and qy < h:  # False for NaN motion
                        g = min(max(np.float64(low[int(qy) // size, int(qx) // size]), 0.0), 1.0)
                n_new = min(n_hist[y, x] * (1.0 - g) ** 10 + 1.0, n_max)
                a = (1.0 - g) / n_new + g
                if paper:
                    a = max((1.0 - g) * alpha0 + g, 1.0 / n_new)
                g_out[y, x] = g
                n_out[y, x] = n_new
                a_out[y, x] = a


def adaptive_history(low: np.ndarray, motion: np.ndarray, hit: np.ndarray, n_hist: np.ndarray,
                     n_max: float = 256.0, mode: str = "seed", alpha0: float = 0.2,
                     backend: str = "numba", size: int = 3):
    """Full-resolution G (:func:`gradient_at_pixels`), N' and α (:func:`asvgf_history`;
    ``mode="paper"``: α = max(mix(α0, 1, λ), 1/N')) in one pass. Returns three (H, W) float32."""
    if backend == "torch":
        from .torch_core import adaptive_history_torch
        return tuple(to_numpy(t) for t in adaptive_history_torch(
            low, motion, hit, n_hist, n_max, mode, alpha0, size))
    if backend == "reference" or not HAVE_NUMBA:
        g = gradient_at_pixels(np.clip(np.nan_to_num(low), 0, 1), motion, hit, size)
        n_new, a = asvgf_history(n_hist, g, n_max)
        if mode == "paper":
            a = np.maximum((1 - g) * alpha0 + g, 1.0 / n_new)
        return g, n_new.astype(np.float32), a.astype(np.float32)
    h, w = hit.shape
    if low.shape != (-(-h // size), -(-w // size)):
        raise DbenchInputError(f"gradient strata: expected shape ({-(-h // size)}, "
                               f"{-(-w // size)}), got {low.shape}")
    g, n_new, a = (np.empty((h, w), np.float32) for _ in range(3))
    _adaptive_nb(np.ascontiguousarray(np.nan_to_num(low), np.float32),
                 np.ascontiguousarray(motion, np.float32), np.ascontiguousarray(hit, np.bool_),
                 np.ascontiguousarray(n_hist, np.float32), float(n_max), int(size),
                 mode == "paper", float(alpha0), g, n_new, a)
    return g, n_new, a
