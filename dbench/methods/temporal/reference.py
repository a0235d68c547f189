"""Readable reprojection (docs/methods/temporal.md §3.3-3.5, per pixel, float64) and accumulation (§2)."""
from __future__ import annotations

import math

import numpy as np

from .params import BILINEAR, EPS_F, FALLBACK, FALLBACK_KERNEL, N_MAX, TAU_D, TAU_N


def _tap_valid(qx, qy, prev_ok, prev_depth, prev_normal, n_p, d_exp, tau_d, tau_n):
    h, w = prev_ok.shape
    if qx < 0 or qy < 0 or qx >= w or qy >= h or not prev_ok[qy, qx]:
        return False
    if abs(prev_depth[qy, qx] - d_exp) > tau_d * d_exp:
        return False
    dot = (prev_normal[0, qy, qx] * n_p[0] + prev_normal[1, qy, qx] * n_p[1]
           + prev_normal[2, qy, qx] * n_p[2])
    return dot >= tau_n


def reproject_reference(history: np.ndarray, motion: np.ndarray, cur_hit: np.ndarray,
                        cur_normal: np.ndarray, d_exp: np.ndarray, prev_ok: np.ndarray,
                        prev_depth: np.ndarray, prev_normal: np.ndarray, tau_d: float = TAU_D,
                        tau_n: float = TAU_N, eps_f: float = EPS_F
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Readable per-pixel transcription of docs/methods/temporal.md §3.3-3.5 (float64 arithmetic).

    Shapes: history (C, H, W); motion (2, H, W); cur_hit, prev_ok, d_exp, prev_depth (H, W);
    cur_normal, prev_normal (3, H, W). Returns (reprojected (C, H, W) in history's dtype,
    status (H, W) uint8: 0 reset, 1 bilinear, 2 fallback). Reset pixels hold 0.
    """
    c, h, w = history.shape
    out = np.zeros(history.shape, np.float64)
    status = np.zeros((h, w), np.uint8)
    for y in range(h):
        for x in range(w):
            mx, my = float(motion[0, y, x]), float(motion[1, y, x])
            if not cur_hit[y, x] or not (math.isfinite(mx) and math.isfinite(my)):
                continue
            n_p = cur_normal[:, y, x].astype(np.float64)
            de = float(d_exp[y, x])
            px, py = x + mx, y + my
            x0, y0 = math.floor(px), math.floor(py)
            wx, wy = px - x0, py - y0
            taps = (((x0, y0), (1 - wx) * (1 - wy)), ((x0 + 1, y0), wx * (1 - wy)),
                    ((x0, y0 + 1), (1 - wx) * wy), ((x0 + 1, y0 + 1), wx * wy))
            f, acc = 0.0, np.zeros(c)
            for (qx, qy), b in taps:
                if b > 0 and _tap_valid(qx, qy, prev_ok, prev_depth, prev_normal, n_p, de,
                                        tau_d, tau_n):
                    f += b
                    acc += b * history[:, qy, qx]
            if f > eps_f:
                out[:, y, x] = acc / f
                status[y, x] = BILINEAR
                continue
            cx, cy = math.floor(px + 0.5), math.floor(py + 0.5)
            g, acc = 0.0, np.zeros(c)
            for dy in (-1, 0, 1):
                for dx in (-1, 0, 1):
                    if _tap_valid(cx + dx, cy + dy, prev_ok, prev_depth, prev_normal, n_p, de,
                                  tau_d, tau_n):
                        k = FALLBACK_KERNEL[dy + 1, dx + 1]
                        g += k
                        acc += k * history[:, cy + dy, cx + dx]
            if g > 0:
                out[:, y, x] = acc / g
                status[y, x] = FALLBACK
    return out.astype(history.dtype), status


def accumulate(sample: np.ndarray, history: np.ndarray, n_hist: np.ndarray, ok: np.ndarray,
               alpha_min: float = 0.0, n_max: float = N_MAX, alpha: np.ndarray | None = None,
               sample_ok: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One accumulation step: ``C' = α·C + (1 − α)·C'←`` (docs/methods/temporal.md §2).

    Args:
        sample: (C, H, W) this frame's values.
        history: (C, H, W) reprojected history; n_hist (H, W) its (reprojected) length.
        ok: (H, W) bool, reprojection succeeded (else reset: C' = C, N = 1).
        alpha_min, n_max: α = max(α_min, 1/N) with N = min(N← + 1, N_max).
        alpha: (H, W) explicit α (A-SVGF) replacing the rule above where ok.
        sample_ok: (H, W) bool, the sample is usable (finite); where False the history is kept
            unchanged (N not incremented) or, without history, the pixel becomes empty (0, N = 0).
    Returns:
        (accumulated (C, H, W) float32, N (H, W) float32, α (H, W) float32).
    """
    ok = np.asarray(ok, bool)
    n = np.where(ok, np.minimum(n_hist + 1.0, n_max), 1.0).astype(np.float32)
    if alpha is None:
        a = np.maximum(np.float32(alpha_min), 1.0 / n)
    else:
        a = np.asarray(alpha, np.float32)
    a = np.where(ok, a, 1.0).astype(np.float32)
    if sample_ok is None:
        out = a * sample + (1.0 - a) * history
    else:
        s = np.where(sample_ok, sample, 0.0)
        out = np.where(sample_ok, a * s + (1.0 - a) * history, np.where(ok, history, 0.0))
        n = np.where(sample_ok, n, np.where(ok, n_hist, 0.0)).astype(np.float32)
        a = np.where(sample_ok, a, 0.0).astype(np.float32)
    return out.astype(np.float32), n, a
