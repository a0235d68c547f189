"""SVGF / A-SVGF compiled with Numba: float32, parallel over rows, inner loops over x written so
that LLVM vectorises them, and a polynomial ``exp`` (:func:`fast_exp_neg`, relative error
≤ 2e-5 on the weights). Each function computes its :mod:`dbench.methods.svgf.reference`
counterpart; tests/methods/test_svgf.py holds them equal within 1e-4 (relative to the image
scale)."""
from __future__ import annotations

import math

import numpy as np

from ...data import check_buffer
from ...errors import DbenchInputError
from ..kernels.arrays import kernel_input
from ..temporal import LUMA
from .params import ALBEDO_FLOOR, EPS_VAR, EPS_Z, H1, SPATIAL_RADIUS


try:
    from numba import njit, prange
    HAVE_NUMBA = True
except ImportError:  # pragma: no cover
    HAVE_NUMBA = False


if HAVE_NUMBA:
    @njit(cache=True, parallel=True, error_model="numpy")
    def _prepare_nb(color, albedo, emission, hit, floor, illum, a_eff, emis, present, emitter,
                    mom, lum_raw):
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
                    a = min(max(a, floor), np.float32(1.0)) if np.isfinite(a) \
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


def prepare_fast(color, albedo, emission, hit, albedo_floor: float = ALBEDO_FLOOR
                 ) -> dict[str, np.ndarray]:
    """Compiled :func:`prepare_reference` (one parallel pass)."""
    h, w = color.shape[:2]
    e_in = np.zeros((0, 0, 3), np.float32) if emission is None else \
        check_buffer("emission", emission, (h, w, 3))
    out = {"illum": np.empty((3, h, w), np.float32), "a_eff": np.empty((3, h, w), np.float32),
           "emission": np.empty((3, h, w), np.float32), "present": np.empty((h, w), np.bool_),
           "emitter": np.empty((h, w), np.bool_), "moments": np.empty((2, h, w), np.float32),
           "lum_raw": np.empty((h, w), np.float32)}
    # read-only inputs (methods/kernels/arrays.py): one specialisation whoever calls
    _prepare_nb(kernel_input(color, np.float32), kernel_input(albedo, np.float32),
                kernel_input(e_in, np.float32), kernel_input(hit, np.bool_),
                np.float32(albedo_floor),
                out["illum"], out["a_eff"],
                out["emission"], out["present"], out["emitter"], out["moments"], out["lum_raw"])
    return out


def remodulate_fast(illum: np.ndarray, a_eff: np.ndarray, emission: np.ndarray) -> np.ndarray:
    """Compiled :func:`~dbench.methods.svgf.reference.remodulate_reference`."""
    out = np.empty(illum.shape[1:] + (3,), np.float32)
    _remodulate_nb(np.ascontiguousarray(illum, np.float32), a_eff, emission, out)
    return out


def depth_gradient_fast(z: np.ndarray, hit: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Compiled :func:`~dbench.methods.svgf.reference.depth_gradient_reference`."""
    gx = np.empty(z.shape, np.float32)
    gy = np.empty(z.shape, np.float32)
    _depth_gradient_nb(np.ascontiguousarray(z, np.float32), np.ascontiguousarray(hit, np.bool_),
                       gx, gy)
    return gx, gy


_F0 = np.float32(0.0)
_F1 = np.float32(1.0)
_EXP_CLAMP = np.float32(30.0)
_DL_CAP = np.float32(1e4)  # w_l's scaled luminance distance, capped before squaring
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
                   eps_z, eps_var, use_lum, gaussian, h1, out_c, out_v):
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
        # w_l's exponent: d (laplacian) or d² (gaussian) as d·(g·d + 1 − g), branch-free so the
        # tap loops still vectorise; d is capped at 1e4 (exp clamps above 30 anyway), so the
        # product is never 0·inf
        g_sq = np.float32(1.0 if gaussian else 0.0)
        g_one = np.float32(1.0) - g_sq
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
                                dl = min(abs(a_l[i] - b_l[i]) * a_i[i], _DL_CAP)
                                e = abs(a_z[i] - b_z[i]) / den + dl * (g_sq * dl + g_one)
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
                                dl = min(abs(a_l[i] - b_l[i]) * a_i[i], _DL_CAP)
                                e = abs(a_z[i] - b_z[i]) / den + dl * (g_sq * dl + g_one)
                                wt = hk * d * fast_exp_neg(e) * b_t[i] * a_h[i]
                                o_w[i] += wt
                                o_0[i] += wt * b_0[i]
                                o_1[i] += wt * b_1[i]
                                o_2[i] += wt * b_2[i]
                                o_v[i] += wt * wt * b_v[i]
                for x in range(x0, x1):
                    k = x - x0
                    if sw[k] > _F0:
                        # in float64: a pixel without its own sample can gather only taps
                        # whose weights are subnormal (w_n = 0.5^128 at 60°), and 1 / sw
                        # overflows float32 to +Inf there (Inf · 0 = NaN)
                        inv = 1.0 / np.float64(sw[k])
                        out_c[0, y, x] = np.float32(s0[k] * inv)
                        out_c[1, y, x] = np.float32(s1[k] * inv)
                        out_c[2, y, x] = np.float32(s2[k] * inv)
                        out_v[y, x] = np.float32(sv[k] * inv * inv)
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
                sigma_n=128.0, sigma_l=4.0, eps_z=EPS_Z, eps_var=EPS_VAR, use_lum=True,
                lum_kernel="laplacian"):
    """Compiled :func:`atrous_reference` (same arguments), float32 outputs. The sums are
    float32: where every weight of a pixel is subnormal (a pixel without its own sample whose
    taps face away, w_n = 0.5^128 at 60°) the colour is still the weighted mean, but the
    weights' squares underflow and its variance comes out 0."""
    f32 = lambda a: np.ascontiguousarray(a, np.float32)  # noqa: E731
    c = f32(color)
    out_c = np.empty_like(c)
    out_v = np.empty(c.shape[1:], np.float32)
    _atrous_nb(c, f32(var), f32(z), f32(gx), f32(gy), f32(normal), f32(tap), f32(centre),
               f32(hit), int(step), float(sigma_z), float(sigma_n), float(sigma_l), float(eps_z),
               float(eps_var), bool(use_lum), lum_kernel == "gaussian", H1, out_c, out_v)
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


if HAVE_NUMBA:
    @njit(cache=True, parallel=True, error_model="numpy")
    def _strata_nb(l_prev, l_grad, hit, depth, normal, size, delta, norm, g, has, dep, nrm):
        h, w = l_prev.shape
        hs, ws = delta.shape
        for sy in prange(hs):  # rows of strata are independent
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


def stratum_gradients_fast(l_prev, l_grad, prev_hit, prev_depth, prev_normal, size=3):
    """Compiled :func:`~dbench.methods.svgf.reference.stratum_gradients_reference`."""
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


def adaptive_history_fast(low, motion, hit, n_hist, n_max=256.0, mode="seed", alpha0=0.2, size=3):
    """Compiled :func:`~dbench.methods.svgf.reference.adaptive_history_reference`; the stratum
    image must have the shape of ``hit`` divided by ``size`` (rounded up)."""
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
