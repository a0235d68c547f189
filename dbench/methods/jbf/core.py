"""Joint (cross) bilateral filter: functional core, reference and fast paths (spec/jbf.md).

Everything here is a plain function on NumPy arrays; :mod:`dbench.methods.jbf` wraps it as the
registered ``jbf`` method and :mod:`dbench.methods.statistical` reuses the same weight code as its
base filter ρ (spec/statistical.md §7).

Layout (kornia style: one functional core, thin wrappers):

* :func:`make_guide` checks the G-buffers and turns them into a :class:`Guide`: the feature
  planes, the diagonal Σ⁻¹, the window offsets with their spatial exponent, and the mask labels
  (hit / background / isolated, spec/jbf.md §1.3).
* :func:`reference_weights` is the readable definition of ρ_ij·h_ij for one offset (NumPy, float64,
  whole shifted images). :func:`jbf_reference` and the statistical reference build on it.
* :func:`accumulate` is the fast path shared with the statistical denoiser: a Numba kernel (float32
  weights, optional float64 Welch test, symmetric pair evaluation, parallel over row bands) or an
  equivalent PyTorch loop over offsets (used on CUDA).
* :func:`accumulate3d` is the same kernel over (x, y, t) for transient videos (spec/jbf.md §1.4,
  spec/statistical.md §11.3): the spatial JBF weights replicated along time times a temporal
  factor (:func:`temporal_factors`, box or Gaussian), optional float64 Welch test between bins,
  half of the 3D window evaluated, spatial weights computed once per row and reused by every
  bin, bins outside the video (or not handed in) absent. A guide of the ``"xy"`` feature only is
  the plain 3D Gaussian of ``gauss3d``.
* :func:`joint_bilateral_filter` and :func:`illumination_filter` are the public entry points.

Shapes: images are (H, W, 3), ``depth`` is (H, W, 1) or (H, W); all outputs are (H, W, 3) float32
from the fast paths and float64 from the references.

Precision and speed of the Numba path: features, weights and per-band sums are float32 (a
vectorisable Cephes-style exp, since Numba has no vector exp without SVML); the final sums and
the division are float64; the statistical Welch test is float64. Measured max relative
difference to the float64 reference ≈ 1e-6 (tests assert 1e-5). Loop order: parallel over row
bands, then rows, then window offsets, innermost the pixels of a row (vectorised); the weight of
a pair is symmetric, so only half of the window is evaluated. 1280×720, r = 20 on 2 cores:
≈ 1-2 s (reference ≈ 40-60 s), see :mod:`dbench.methods.jbf.bench`.

Non-finite input policy (both filters): a colour pixel with a NaN/Inf channel is *missing*: it
gets no weight as a neighbour, and its own output is the filtered value of its valid neighbours
(0 if it has none), so NaN never spreads. A pixel whose G-buffers (albedo, normal, position, depth)
are not finite is *isolated*: it is nobody's neighbour and has no neighbours (its output is its own
colour, or 0 if that is missing too).

Example:
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> color = rng.random((16, 16, 3)).astype(np.float32)
    >>> albedo = np.full((16, 16, 3), 0.5, np.float32)
    >>> normal = np.zeros((16, 16, 3), np.float32); normal[..., 2] = 1
    >>> out = joint_bilateral_filter(color, albedo, normal, radius=3)
    >>> out.shape, out.dtype
    ((16, 16, 3), dtype('float32'))
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import llvmlite.ir as llvm_ir
import numba
import numpy as np
from numba import njit, prange
from numba.core import types as nb_types
from numba.extending import intrinsic

from ...data import check_buffer
from ...errors import DbenchInputError
from ..checks import check_choice, check_positive, check_radius

#: Σ of the seed (spec/jbf.md §1.1): (x, y, albedo r, g, b, normal x, y, z), a covariance.
SEED_SIGMA: tuple[float, ...] = (10.0, 10.0, 0.02, 0.02, 0.02, 0.1, 0.1, 0.1)
#: Named parameter sets (spec/jbf.md §1.2).
PRESETS: dict[str, dict[str, Any]] = {
    "seed": dict(sigma_convention="variance", window="square", radius=20),
    "statmc": dict(sigma_convention="sd", window="disk", radius=20),
}
FEATURES = ("xy", "albedo", "normal", "position", "depth")
SIGMA_CONVENTIONS = ("variance", "sd")
WINDOWS = ("square", "disk")
#: Temporal profiles of the 3D base filter (spec/jbf.md §1.4).
TEMPORAL_PROFILES = ("box", "gaussian")
BACKENDS = ("auto", "numba", "torch", "reference")

#: Mask labels: pixels mix only with pixels of the same label. 0 = background (depth ≤ 0),
#: 1 = hit, ≥ 2 = isolated pixels (one label each).
# Pixels of different labels never weigh each other: background (nothing hit), surfaces,
# emitters seen directly (from the ``emitter`` buffer), and one label per isolated pixel.
LABEL_BACKGROUND, LABEL_HIT, LABEL_EMITTER, LABEL_FIRST_ISOLATED = 0, 1, 2, 3
#: In the Numba kernel the label becomes a feature plane 16·label; distinct labels differ by
#: ≥ 16, i.e. add ≥ 256 to the exponent, and exp(−s) is exactly 0 for s ≥ 87 (see _exp32).
_LABEL_SCALE = 16.0
_EXP_CUTOFF = 87.0


# ---------------------------------------------------------------------------------------------
# Parameter checks (the shared ones: dbench/methods/checks.py)
# ---------------------------------------------------------------------------------------------

def check_sigma(sigma: Any) -> tuple[float, ...]:
    """Σ diagonal as 8 numbers (x, y, albedo ×3, normal ×3), each > 0 (∞ switches a term off)."""
    try:
        vals = tuple(float(s) for s in sigma)
    except (TypeError, ValueError):
        raise DbenchInputError(f"sigma: expected 8 numbers (x, y, albedo r, g, b, normal x, y, z), "
                               f"got {sigma!r}") from None
    if len(vals) != 8:
        raise DbenchInputError(f"sigma: expected 8 numbers (x, y, albedo r, g, b, normal x, y, z), "
                               f"got {len(vals)}")
    for v in vals:
        if math.isnan(v) or v <= 0:
            raise DbenchInputError(f"sigma: every entry must be > 0 (inf allowed), got {sigma!r}")
    return vals


def inverse_variance(sigma: float, convention: str) -> float:
    """Σ⁻¹ entry for one Σ entry: 1/σ for ``"variance"``, 1/σ² for ``"sd"`` (spec/jbf.md §1.2)."""
    var = sigma if convention == "variance" else sigma * sigma
    return 0.0 if math.isinf(var) else 1.0 / var


def window_offsets(radius: int, window: str = "square") -> tuple[np.ndarray, np.ndarray]:
    """Offsets (dy, dx) of the window, row-major, including (0, 0).

    ``square``: |dx|, |dy| ≤ r, (2r+1)² taps; ``disk``: dx² + dy² ≤ r² (spec/jbf.md §1.2).
    """
    radius = check_radius(radius)
    check_choice("window", window, WINDOWS)
    oy, ox = np.mgrid[-radius:radius + 1, -radius:radius + 1]
    keep = np.ones_like(oy, bool) if window == "square" else (oy * oy + ox * ox <= radius * radius)
    return oy[keep].astype(np.int64), ox[keep].astype(np.int64)


# ---------------------------------------------------------------------------------------------
# Guide: everything ρ needs, computed once per frame
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Guide:
    """Noise-free guide data of the base filter ρ (spec/jbf.md §1, spec/statistical.md §7).

    Attributes:
        features: (K, H, W) float64 feature values p_k (albedo, normal, optional position/depth),
            0 at isolated pixels.
        inv_var: (K,) float64 diagonal Σ⁻¹ of the features.
        labels: (H, W) int64 mask labels; pixels mix only with equal labels (0 background,
            1 hit, ≥ 2 isolated).
        dy, dx: (O,) int64 window offsets, row-major, including (0, 0).
        spatial: (O,) float64 spatial exponent ½(dx²Σ⁻¹_x + dy²Σ⁻¹_y); ρ_spatial = exp(−spatial).
        radius, window: the window.
        settings: the resolved parameters, for reports.
    """

    features: np.ndarray
    inv_var: np.ndarray
    labels: np.ndarray
    dy: np.ndarray
    dx: np.ndarray
    spatial: np.ndarray
    radius: int
    window: str
    settings: dict

    @property
    def shape(self) -> tuple[int, int]:
        return tuple(self.labels.shape)

    @property
    def isolated(self) -> np.ndarray:
        """(H, W) bool: pixels that are nobody's neighbour (non-finite G-buffers, bad stats)."""
        return self.labels >= LABEL_FIRST_ISOLATED

    def isolate(self, mask: np.ndarray) -> "Guide":
        """A copy in which the pixels of ``mask`` (H, W) are isolated as well."""
        mask = np.asarray(mask, bool) & ~self.isolated
        if not mask.any():
            return self
        labels = self.labels.copy()
        start = max(int(labels.max()) + 1, LABEL_FIRST_ISOLATED)
        labels[mask] = start + np.arange(int(mask.sum()))
        features = self.features.copy()
        features[:, mask] = 0.0
        return Guide(features, self.inv_var, labels, self.dy, self.dx, self.spatial,
                     self.radius, self.window, self.settings)


def _image_shape(color: Any, name: str = "color") -> tuple[int, int]:
    arr = np.asarray(color) if color is not None else None
    if arr is None or arr.ndim != 3 or arr.shape[2] != 3 or 0 in arr.shape:
        raise DbenchInputError(f"{name}: expected shape (H, W, 3), got "
                               f"{None if arr is None else tuple(arr.shape)}")
    return arr.shape[0], arr.shape[1]


def _depth_buffer(depth: Any, h: int, w: int) -> np.ndarray:
    arr = np.asarray(depth)
    if arr.ndim == 2:
        arr = arr[..., None]
    return check_buffer("depth", arr, (h, w, 1), dtype=np.float64)[..., 0]


def make_guide(albedo: Any, normal: Any, depth: Any = None, position: Any = None, *,
               radius: int = 20, sigma: Sequence[float] = SEED_SIGMA,
               sigma_convention: str = "variance", window: str = "square",
               features: Sequence[str] = ("xy", "albedo", "normal"),
               sigma_position: float = 0.01, sigma_depth: float = 0.01,
               hit_mask: bool = True, shape: tuple[int, int] | None = None,
               emitter: Any = None) -> Guide:
    """Check the G-buffers and build the :class:`Guide` of the JBF (spec/jbf.md §1).

    Args:
        albedo: (H, W, 3) linear albedo (needed when ``"albedo"`` is a feature).
        normal: (H, W, 3) shading normal, not renormalised (needed when ``"normal"`` is a feature).
        depth: (H, W, 1) or (H, W) camera distance, 0 where nothing is hit; None = all pixels hit.
        position: (H, W, 3) world position (needed when ``"position"`` is a feature).
        radius: window radius r ≥ 0.
        sigma: Σ diagonal (x, y, albedo ×3, normal ×3); ``inf`` switches a term off.
        sigma_convention: ``"variance"`` (seed, Σ entries are variances) or ``"sd"`` (StatMC code).
        window: ``"square"`` or ``"disk"``.
        features: subset of ("xy", "albedo", "normal", "position", "depth").
        sigma_position, sigma_depth: Σ entry of each position coordinate / of depth (same
            convention), defaults 0.01 [dbench].
        hit_mask: h_ij = 0 when exactly one of i, j is a hit (depth > 0) (spec/jbf.md §1.3).
        shape: (H, W) expected; taken from the first buffer given otherwise.
        emitter: (H, W, 1) emitter coverage in [0, 1] or None: pixels with coverage ≥ 0.5
            form their own label (a light never mixes with the surfaces around it, whatever
            its albedo says) [dbench].

    Raises:
        DbenchInputError: naming the buffer or parameter that is wrong.
    """
    radius = check_radius(radius)
    sigma = check_sigma(sigma)
    check_choice("sigma_convention", sigma_convention, SIGMA_CONVENTIONS)
    check_choice("window", window, WINDOWS)
    if isinstance(features, str):
        features = (features,)
    features = tuple(features)
    for f in features:
        check_choice("features", f, FEATURES)
    sigma_position = check_positive("sigma_position", sigma_position, allow_inf=True)
    sigma_depth = check_positive("sigma_depth", sigma_depth, allow_inf=True)

    buffers = {"albedo": albedo, "normal": normal, "position": position}
    if shape is None:
        for name in ("albedo", "normal", "position"):
            if buffers[name] is not None:
                shape = _image_shape(buffers[name], name)
                break
        else:
            if depth is None:
                raise DbenchInputError("make_guide: no G-buffer given; pass shape=(H, W)")
            shape = np.asarray(depth).shape[:2]
    h, w = shape

    planes: list[np.ndarray] = []
    inv: list[float] = []
    for name, first in (("albedo", 2), ("normal", 5)):
        if name in features:
            arr = check_buffer(name, buffers[name], (h, w, 3), dtype=np.float64)
            planes += [arr[..., c] for c in range(3)]
            inv += [inverse_variance(sigma[first + c], sigma_convention) for c in range(3)]
    if "position" in features:
        arr = check_buffer("position", position, (h, w, 3), dtype=np.float64)
        planes += [arr[..., c] for c in range(3)]
        inv += [inverse_variance(sigma_position, sigma_convention)] * 3
    depth_arr = None if depth is None else _depth_buffer(depth, h, w)
    if "depth" in features:
        if depth_arr is None:
            raise DbenchInputError(f"depth: missing; expected an array of shape ({h}, {w}, 1) "
                                   "because features include 'depth'")
        planes.append(depth_arr)
        inv.append(inverse_variance(sigma_depth, sigma_convention))
    feats = np.stack(planes) if planes else np.zeros((0, h, w))
    inv_var = np.asarray(inv, np.float64)

    bad = ~np.all(np.isfinite(feats), axis=0)
    if depth_arr is not None:
        bad |= ~np.isfinite(depth_arr)
    if hit_mask and depth_arr is not None:
        labels = np.where(depth_arr > 0, LABEL_HIT, LABEL_BACKGROUND).astype(np.int64)
    else:
        labels = np.full((h, w), LABEL_HIT, np.int64)
    if emitter is not None:
        seen = check_buffer("emitter", emitter, (h, w, 1), dtype=np.float64)[..., 0]
        labels[np.nan_to_num(seen) >= 0.5] = LABEL_EMITTER
    if bad.any():
        labels[bad] = LABEL_FIRST_ISOLATED + np.arange(int(bad.sum()))
        feats = feats.copy()
        feats[:, bad] = 0.0

    dy, dx = window_offsets(radius, window)
    if "xy" in features:
        ix = inverse_variance(sigma[0], sigma_convention)
        iy = inverse_variance(sigma[1], sigma_convention)
        spatial = 0.5 * (dx * dx * ix + dy * dy * iy)
    else:
        spatial = np.zeros(dy.shape, np.float64)
    settings = dict(radius=radius, sigma=sigma, sigma_convention=sigma_convention, window=window,
                    features=features, sigma_position=sigma_position, sigma_depth=sigma_depth,
                    hit_mask=bool(hit_mask))
    return Guide(feats, inv_var, labels, dy, dx, spatial.astype(np.float64), radius, window, settings)


# ---------------------------------------------------------------------------------------------
# Reference implementation (readable NumPy, float64)
# ---------------------------------------------------------------------------------------------

def shift_slices(dy: int, dx: int, h: int, w: int):
    """Slices (centre, neighbour) such that ``a[centre]`` pairs pixel i with ``b[neighbour]`` = i + o.

    Only centres whose neighbour lies inside the image appear: out-of-image neighbours simply
    do not exist (no padding enters any sum, spec/jbf.md §1.3).
    """
    ny = max(0, h - abs(dy))
    nx = max(0, w - abs(dx))
    y0, x0 = max(0, -dy), max(0, -dx)
    ys, xs = slice(y0, y0 + ny), slice(x0, x0 + nx)
    yn, xn = slice(y0 + dy, y0 + dy + ny), slice(x0 + dx, x0 + dx + nx)
    return (ys, xs), (yn, xn)


def reference_weights(guide: Guide, k: int) -> np.ndarray:
    """ρ_ij · h_ij for offset ``k`` of the guide, for every centre i: (H, W) float64.

    ρ_ij = exp(−½ Σ_k (p_j,k − p_i,k)² Σ⁻¹_kk) with the spatial part precomputed per offset
    (spec/jbf.md §1.1); h_ij = [label_i == label_j]; 0 where j = i + o lies outside the image.
    """
    h, w = guide.shape
    dy, dx = int(guide.dy[k]), int(guide.dx[k])
    out = np.zeros((h, w))
    (ys, xs), (yn, xn) = shift_slices(dy, dx, h, w)
    if ys.start >= ys.stop or xs.start >= xs.stop:
        return out
    expo = np.full(out[ys, xs].shape, guide.spatial[k])
    for f, iv in zip(guide.features, guide.inv_var):
        if iv != 0.0:
            expo += 0.5 * (f[yn, xn] - f[ys, xs]) ** 2 * iv
    same = guide.labels[yn, xn] == guide.labels[ys, xs]
    out[ys, xs] = np.exp(-expo) * same
    return out


def _color_planes(color: Any, shape: tuple[int, int] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(H, W, 3) colour as float64 with missing pixels zeroed, and the (H, W) validity mask."""
    h, w = _image_shape(color) if shape is None else shape
    col = check_buffer("color", color, (h, w, 3), dtype=np.float64)
    valid = np.all(np.isfinite(col), axis=-1)
    return np.where(valid[..., None], col, 0.0), valid


def jbf_reference(color: Any, guide: Guide, *, return_weights: bool = False):
    """Readable JBF: loop over offsets, accumulate shifted whole images (float64).

    out_i = Σ_j ρ_ij h_ij v_j L_j / Σ_j ρ_ij h_ij v_j with v_j = colour finite (spec/jbf.md §1.1).

    Returns:
        (H, W, 3) float64; with ``return_weights`` also the (O, H, W) normalised weights w_ij
        per offset (guide.dy, guide.dx), for checks.
    """
    col, valid = _color_planes(color, guide.shape)
    num = np.zeros(col.shape)
    den = np.zeros(guide.shape)
    stack = [] if return_weights else None
    for k in range(len(guide.dy)):
        (ys, xs), (yn, xn) = shift_slices(int(guide.dy[k]), int(guide.dx[k]), *guide.shape)
        wk = reference_weights(guide, k)
        wk[ys, xs] *= valid[yn, xn]
        num[ys, xs] += wk[ys, xs, None] * col[yn, xn]
        den += wk
        if stack is not None:
            stack.append(wk)
    out = np.divide(num, den[..., None], out=np.zeros_like(num), where=den[..., None] > 0)
    if return_weights:
        ws = np.stack(stack)
        return out, np.divide(ws, den, out=np.zeros_like(ws), where=den > 0)
    return out


# ---------------------------------------------------------------------------------------------
# Fast path: Numba kernel shared with the statistical denoiser
# ---------------------------------------------------------------------------------------------

@intrinsic
def _bits_to_float32(typingctx, bits):
    """Reinterpret an int32 as float32 (vectorisable, unlike ldexp)."""
    sig = nb_types.float32(nb_types.int32)

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], llvm_ir.FloatType())

    return sig, codegen


_F0 = np.float32(0.0)
_F1 = np.float32(1.0)
_F_HALF = np.float32(0.5)
_F_CUT = np.float32(_EXP_CUTOFF)
_F_HI = np.float32(88.0)
_F_LOG2E = np.float32(1.44269504088896341)
_F_C1 = np.float32(0.693359375)
_F_C2 = np.float32(-2.12194440e-4)
_P0 = np.float32(1.9875691500e-4)
_P1 = np.float32(1.3981999507e-3)
_P2 = np.float32(8.3334519073e-3)
_P3 = np.float32(4.1665795894e-2)
_P4 = np.float32(1.6666665459e-1)
_P5 = np.float32(5.0000001201e-1)


@njit(inline="always", cache=True)
def _exp32(x):
    """float32 exp(x) (Cephes expf, ≈ 1 ulp), exactly 0 for x ≤ −87.

    Written out so that LLVM vectorises it: Numba has no vector exp without Intel SVML.
    """
    xc = min(max(x, -_F_CUT), _F_HI)
    fx = np.floor(xc * _F_LOG2E + _F_HALF)
    r = xc - fx * _F_C1 - fx * _F_C2
    p = _P0
    p = p * r + _P1
    p = p * r + _P2
    p = p * r + _P3
    p = p * r + _P4
    p = p * r + _P5
    p = p * r * r + r + _F1
    scale = _bits_to_float32((np.int32(fx) + np.int32(127)) << np.int32(23))
    return p * scale if x > -_F_CUT else _F0


@njit(inline="always", cache=True)
def _row_weights(fsq, fdot, beta, horizon, y, yy, x0, x1, dx, e, w):
    """w[0:n] = base weights of the pairs (y, x) – (yy, x + dx), x in [x0, x1).

    The exponent is e + Σ_g Σ_q (F_i − F_j)² (pre-scaled features, groups of 4 planes) and, for
    the illumination filter, + β(1 − n_i·n_j) with the horizon step [n_i·n_j > 0].
    """
    _row_exponent(fsq, y, yy, x0, x1, dx, e, w)
    _row_exp(fdot, beta, horizon, y, yy, x0, x1, dx, w)


@njit(inline="always", cache=True)
def _row_exponent(fsq, y, yy, x0, x1, dx, e, w):
    """w[0:n] = e + Σ_g Σ_q (F_i − F_j)², the feature part of the exponent."""
    n = x1 - x0
    for i in range(n):
        w[i] = e
    for g in range(fsq.shape[0]):
        a0 = fsq[g, 0, y, x0:x1]
        b0 = fsq[g, 0, yy, x0 + dx:x1 + dx]
        a1 = fsq[g, 1, y, x0:x1]
        b1 = fsq[g, 1, yy, x0 + dx:x1 + dx]
        a2 = fsq[g, 2, y, x0:x1]
        b2 = fsq[g, 2, yy, x0 + dx:x1 + dx]
        a3 = fsq[g, 3, y, x0:x1]
        b3 = fsq[g, 3, yy, x0 + dx:x1 + dx]
        for i in range(n):
            t0 = a0[i] - b0[i]
            t1 = a1[i] - b1[i]
            t2 = a2[i] - b2[i]
            t3 = a3[i] - b3[i]
            w[i] += (t0 * t0 + t1 * t1) + (t2 * t2 + t3 * t3)


@njit(inline="always", cache=True)
def _row_exp(fdot, beta, horizon, y, yy, x0, x1, dx, w):
    """w ← exp(−w), with the illumination filter's normal term when ``fdot`` has planes."""
    n = x1 - x0
    if fdot.shape[0] > 0:
        a0 = fdot[0, y, x0:x1]
        b0 = fdot[0, yy, x0 + dx:x1 + dx]
        a1 = fdot[1, y, x0:x1]
        b1 = fdot[1, yy, x0 + dx:x1 + dx]
        a2 = fdot[2, y, x0:x1]
        b2 = fdot[2, yy, x0 + dx:x1 + dx]
        for i in range(n):
            dot = a0[i] * b0[i] + a1[i] * b1[i] + a2[i] * b2[i]
            v = _exp32(-(w[i] + beta * (_F1 - dot)))
            w[i] = v if (dot > _F0 or not horizon) else _F0
    else:
        for i in range(n):
            w[i] = _exp32(-w[i])


@njit(inline="always", cache=True)
def _row_welch(theta, var, g2, y, yy, x0, x1, dx, w):
    """Zero w where the Welch test fails in any channel (constant threshold γ_t² = g2).

    pass_c = (d² < γ_t² S) or (d == 0), computed in float64 exactly as the reference does
    (spec/statistical.md §5.2), so decisions are identical to it.
    """
    # the 3D kernel's pair form with both ends in the same planes; w·1.0 == w exactly
    _row_welch_pair(theta, var, theta, var, g2, y, yy, x0, x1, dx, w, 1.0, w)


@njit(inline="always", cache=True)
def _row_welch_table(theta, var, nint, table, y, yy, x0, x1, dx, w):
    """As _row_welch with γ_t² looked up per channel from ν = n_i + n_j − 2 (non-uniform n)."""
    _row_welch_pair_table(theta, var, nint, theta, var, nint, table, y, yy, x0, x1, dx, w)


@njit(parallel=True, cache=True)
def _accumulate_kernel(fsq, fdot, beta, horizon, planes, dys, dxs, es,
                       theta, var, nint, g2, table, test_mode, nbands, halo):
    """Σ_{j ≠ i} W_ij · planes[:, j] for every pixel i: (P, H, W) float64.

    W_ij = base weight × (Welch membership if test_mode > 0) is symmetric in (i, j), so only the
    half window (dy > 0, or dy = 0 and dx > 0) is evaluated and each pair is added to both
    pixels. Rows are split into ``nbands`` bands processed in parallel; each band owns a private
    float32 accumulator of its rows plus ``halo`` (= r) rows below, summed at the end in float64.
    Memory: P·(H + nbands·r)·W floats; no unfolded tensor.
    """
    H = fsq.shape[2]
    W = fsq.shape[3]
    P = planes.shape[0]
    B = (H + nbands - 1) // nbands
    acc = np.zeros((nbands, P, B + halo, W), np.float32)
    for b in prange(nbands):
        y0 = b * B
        y1 = min(H, y0 + B)
        w = np.empty(W, np.float32)
        for y in range(y0, y1):
            for o in range(dys.shape[0]):
                dy = dys[o]
                dx = dxs[o]
                yy = y + dy
                if yy >= H:
                    break  # offsets are sorted by dy
                x0 = max(0, -dx)
                x1 = min(W, W - dx)
                n = x1 - x0
                if n <= 0 or es[o] >= _F_CUT:
                    continue  # no pair in the image / weight underflows to exactly 0
                _row_exponent(fsq, y, yy, x0, x1, dx, es[o], w)
                _row_exp(fdot, beta, horizon, y, yy, x0, x1, dx, w)
                if test_mode == 1:
                    _row_welch(theta, var, g2, y, yy, x0, x1, dx, w)
                elif test_mode == 2:
                    _row_welch_table(theta, var, nint, table, y, yy, x0, x1, dx, w)
                r0 = y - y0
                r1 = yy - y0
                for p in range(P):
                    pa = planes[p, y, x0:x1]
                    pb = planes[p, yy, x0 + dx:x1 + dx]
                    aa = acc[b, p, r0, x0:x1]
                    ab = acc[b, p, r1, x0 + dx:x1 + dx]
                    # two loops, not one: with a single store stream each, LLVM vectorises
                    # them (the fused loop ran 4x slower)
                    for i in range(n):
                        aa[i] += w[i] * pb[i]
                    for i in range(n):
                        ab[i] += w[i] * pa[i]
    out = np.zeros((P, H, W), np.float64)
    for y in prange(H):
        for b in range(nbands):
            r = y - b * B
            if 0 <= r < B + halo:
                for p in range(P):
                    for x in range(W):
                        out[p, y, x] += acc[b, p, r, x]
    return out


_EMPTY_F64 = np.zeros((3, 1, 1), np.float64)
_EMPTY_I32 = np.zeros((3, 1, 1), np.int32)
_EMPTY_TABLE = np.zeros(1, np.float64)


def _scaled_feature_groups(guide: Guide) -> np.ndarray:
    """(G, 4, H, W) float32 planes F with (F_i − F_j)² summing to the exponent of ρ.

    F_k = p_k·sqrt(½Σ⁻¹_kk) (centred per plane to keep float32 precision) plus the label plane
    16·label; zero planes pad the count to a multiple of 4.
    """
    h, w = guide.shape
    planes = []
    for f, iv in zip(guide.features, guide.inv_var):
        if iv == 0.0:
            continue
        centre = float(np.mean(f)) if f.size else 0.0
        planes.append((f - centre) * math.sqrt(0.5 * iv))
    if np.any(guide.labels != guide.labels.flat[0]):
        if guide.labels.max() >= 2 ** 24:
            raise DbenchInputError("too many isolated pixels (non-finite G-buffers) for the "
                                   "float32 label plane; clean the G-buffers first")
        planes.append(guide.labels * _LABEL_SCALE)
    while len(planes) % 4:
        planes.append(np.zeros((h, w)))
    if not planes:
        return np.zeros((0, 4, h, w), np.float32)
    return np.ascontiguousarray(np.stack(planes).reshape(-1, 4, h, w), dtype=np.float32)


def _half_window(guide: Guide, extra_exponent: float = 0.0):
    """Offsets with dy > 0 or (dy = 0, dx > 0), sorted by dy, and their float32 exponents."""
    half = (guide.dy > 0) | ((guide.dy == 0) & (guide.dx > 0))
    order = np.lexsort((guide.dx[half], guide.dy[half]))
    dys = np.ascontiguousarray(guide.dy[half][order])
    dxs = np.ascontiguousarray(guide.dx[half][order])
    es = (guide.spatial[half][order] + extra_exponent).astype(np.float32)
    return dys, dxs, es


def _num_bands(h: int) -> int:
    return max(1, min(numba.get_num_threads(), h))


def accumulate(guide: Guide, planes: np.ndarray, *, dot_normal: np.ndarray | None = None,
               beta: float = 0.0, horizon: bool = False, extra_exponent: float = 0.0,
               theta: np.ndarray | None = None, var: np.ndarray | None = None,
               nint: np.ndarray | None = None, g2: float | None = None,
               g2_table: np.ndarray | None = None) -> np.ndarray:
    """Numba fast path: Σ_{j ≠ i, j in window} W_ij · planes_j for every pixel i.

    Args:
        guide: the base filter (features, labels, window).
        planes: (P, H, W) values to sum (premultiplied by each neighbour's validity).
        dot_normal: (3, H, W) normals for the illumination filter's β(1 − n·n') term, or None.
        beta, horizon: that term's β and whether to apply the horizon step [n_i·n_j > 0].
        extra_exponent: a constant added to every exponent (−ln C of the illumination filter).
        theta, var: (3, H, W) float64 statistics for the Welch membership test, or None.
        nint: (3, H, W) int32 sample counts, with ``g2_table`` (γ_t² indexed by ν) when n is not
            uniform; otherwise ``g2`` = γ_t², one value.

    Returns:
        (P, H, W) float64 sums without the centre term (the caller adds it).

    Weights are float32 (relative error ≈ 1e-7·exponent); the membership test is float64 and
    bit-identical to the reference; band sums are float32, the final sum float64.
    """
    h, w = guide.shape
    planes, scale = _scaled_planes(planes)
    fsq = _scaled_feature_groups(guide)
    fdot = (np.zeros((0, 1, 1), np.float32) if dot_normal is None
            else np.ascontiguousarray(dot_normal, dtype=np.float32))
    dys, dxs, es = _half_window(guide, extra_exponent)
    if theta is None:
        test_mode, th, va, ni, table, gg = 0, _EMPTY_F64, _EMPTY_F64, _EMPTY_I32, _EMPTY_TABLE, 0.0
    else:
        th = np.ascontiguousarray(theta, dtype=np.float64)
        va = np.ascontiguousarray(var, dtype=np.float64)
        if g2_table is None:
            test_mode, ni, table, gg = 1, _EMPTY_I32, _EMPTY_TABLE, float(g2)
        else:
            test_mode, gg = 2, 0.0
            ni = np.ascontiguousarray(nint, dtype=np.int32)
            table = np.ascontiguousarray(g2_table, dtype=np.float64)
    nbands = _num_bands(h)
    sums = _accumulate_kernel(fsq, fdot, np.float32(beta), bool(horizon), planes, dys, dxs, es,
                              th, va, ni, np.float64(gg), table, int(test_mode), nbands,
                              int(guide.radius))
    if scale is not None:
        sums *= scale[:, None, None]
    return sums


#: Largest |value| a plane may hold in the float32 band sums of :func:`accumulate`: a window of
#: (2·20 + 1)² = 1681 taps of weight ≤ 1 then sums to ≤ 1.7e33, far below the float32 maximum.
PLANE_MAX = 1e30


def _scaled_planes(planes: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """(P, H, W) planes as float32 for the kernel, and the per-plane factors to multiply the
    (float64) sums by, or None. A plane whose largest finite |value| exceeds :data:`PLANE_MAX`
    (a demodulated colour near the float32 maximum: 3e38 / 1e-3 is Inf in float32) is divided
    by a power of two (exact) first, so its float32 sums stay finite; other planes, i.e. every
    ordinary input, are passed unchanged bit for bit."""
    p64 = np.asarray(planes, np.float64)
    with np.errstate(invalid="ignore"):
        peak = np.max(np.where(np.isfinite(p64), np.abs(p64), 0.0),
                      axis=tuple(range(1, p64.ndim))) if p64.size else np.zeros(len(p64))
    if not np.any(peak > PLANE_MAX):
        return np.ascontiguousarray(planes, dtype=np.float32), None
    exps = np.where(peak > PLANE_MAX, np.ceil(np.log2(peak / PLANE_MAX)), 0.0)
    scale = np.exp2(exps)
    scaled = p64 / scale.reshape((-1,) + (1,) * (p64.ndim - 1))
    return np.ascontiguousarray(scaled, dtype=np.float32), scale


# ---------------------------------------------------------------------------------------------
# Fast path in 3D (x, y, t): transient videos (spec/jbf.md §1.4, spec/statistical.md §11.3)
# ---------------------------------------------------------------------------------------------

@njit(inline="always", cache=True)
def _row_welch_pair(ta, va, tb, vb, g2, y, yy, x0, x1, dx, ro, f, w):
    """w = ro·f where the Welch test passes, else 0, with the centres in bin planes (ta, va), row
    y, and the neighbours in (tb, vb), row yy: the float64 predicate of :func:`_row_welch`, so
    decisions equal the reference's."""
    n = x1 - x0
    ta0 = ta[0, y, x0:x1]
    tb0 = tb[0, yy, x0 + dx:x1 + dx]
    ta1 = ta[1, y, x0:x1]
    tb1 = tb[1, yy, x0 + dx:x1 + dx]
    ta2 = ta[2, y, x0:x1]
    tb2 = tb[2, yy, x0 + dx:x1 + dx]
    va0 = va[0, y, x0:x1]
    vb0 = vb[0, yy, x0 + dx:x1 + dx]
    va1 = va[1, y, x0:x1]
    vb1 = vb[1, yy, x0 + dx:x1 + dx]
    va2 = va[2, y, x0:x1]
    vb2 = vb[2, yy, x0 + dx:x1 + dx]
    for i in range(n):
        d0 = ta0[i] - tb0[i]
        d1 = ta1[i] - tb1[i]
        d2 = ta2[i] - tb2[i]
        ok = (((d0 * d0 < g2 * (va0[i] + vb0[i])) | (d0 == 0.0))
              & ((d1 * d1 < g2 * (va1[i] + vb1[i])) | (d1 == 0.0))
              & ((d2 * d2 < g2 * (va2[i] + vb2[i])) | (d2 == 0.0)))
        w[i] = ro[i] * f if ok else _F0


@njit(inline="always", cache=True)
def _row_welch_pair_table(ta, va, na, tb, vb, nb, table, y, yy, x0, x1, dx, w):
    """As :func:`_row_welch_table` for centres in bin (ta, va, na) and neighbours in (tb, vb, nb)."""
    n = x1 - x0
    last = table.shape[0] - 1
    for c in range(3):
        a = ta[c, y, x0:x1]
        b = tb[c, yy, x0 + dx:x1 + dx]
        sa = va[c, y, x0:x1]
        sb = vb[c, yy, x0 + dx:x1 + dx]
        ca = na[c, y, x0:x1]
        cb = nb[c, yy, x0 + dx:x1 + dx]
        for i in range(n):
            nu = min(max(ca[i] + cb[i] - 2, 0), last)
            d = a[i] - b[i]
            ok = (d * d < table[nu] * (sa[i] + sb[i])) | (d == 0.0)
            w[i] = w[i] if ok else _F0


@njit(parallel=True, cache=True)
def _accumulate3d_kernel(fsq, fdot, planes, dys, dxs, es, dt_first, tfac, nbr, active,
                         theta, var, nint, g2, table, test_mode, nbands, halo):
    """Σ_{j ≠ i} W_ij · planes[j] over a 3D window for every voxel i of the bins in play.

    Voxel i = (bin k, row y, column x); j = (nbr[k, τ], y + dy, x + dx) for the spatial offsets
    (dys, dxs) of the half window (the centre (0, 0) first, then dy > 0 or dy = 0, dx > 0) and
    the temporal offsets τ = dt_first[o] − r_t .. r_t (all of them for a non-centre spatial
    offset, only τ > 0 for the centre). W_ij = ρ_spatial(y, x; o) · tfac[τ] · (Welch membership)
    is symmetric, so each pair is evaluated once and added to both voxels. The spatial base
    weights of a row are computed once per row for all offsets and reused by every bin.

    Pairs with neither end ``active`` are skipped; sums into an inactive bin are not made
    (its output is not wanted). Row bands run in parallel, each with a private float32
    accumulator of its rows + ``halo`` rows for every bin, returned as (nbands, K, P, B + halo,
    W); :func:`_merge_bands3d` / :func:`_merge_normalise3d` merge them in float64.
    """
    K = planes.shape[0]
    P = planes.shape[1]
    H = planes.shape[2]
    W = planes.shape[3]
    O = dys.shape[0]
    NT = tfac.shape[0]
    B = (H + nbands - 1) // nbands
    acc = np.zeros((nbands, K, P, B + halo, W), np.float32)
    for b in prange(nbands):
        y0 = b * B
        y1 = min(H, y0 + B)
        rho = np.zeros((O, W), np.float32)
        live = np.zeros(O, np.bool_)
        w = np.empty(W, np.float32)
        for y in range(y0, y1):
            for o in range(O):
                dx = dxs[o]
                yy = y + dys[o]
                x0 = max(0, -dx)
                x1 = min(W, W - dx)
                live[o] = yy < H and x1 > x0 and es[o] < _F_CUT
                if live[o]:
                    _row_exponent(fsq, y, yy, x0, x1, dx, es[o], rho[o])
                    _row_exp(fdot, _F0, False, y, yy, x0, x1, dx, rho[o])
            r0 = y - y0
            for k in range(K):
                act_k = active[k]
                for o in range(O):
                    if not live[o]:
                        continue
                    dx = dxs[o]
                    yy = y + dys[o]
                    x0 = max(0, -dx)
                    x1 = min(W, W - dx)
                    n = x1 - x0
                    r1 = yy - y0
                    ro = rho[o]
                    for ti in range(dt_first[o], NT):
                        kk = nbr[k, ti]
                        if kk < 0:
                            continue
                        act_kk = active[kk]
                        if not (act_k or act_kk):
                            continue
                        f = tfac[ti]
                        if f <= _F0:
                            continue
                        if test_mode == 1:
                            _row_welch_pair(theta[k], var[k], theta[kk], var[kk], g2,
                                            y, yy, x0, x1, dx, ro, f, w)
                        else:
                            for i in range(n):
                                w[i] = ro[i] * f
                        if test_mode == 2:
                            _row_welch_pair_table(theta[k], var[k], nint[k], theta[kk], var[kk],
                                                  nint[kk], table, y, yy, x0, x1, dx, w)
                        for p in range(P):
                            if act_k:
                                pb = planes[kk, p, yy, x0 + dx:x1 + dx]
                                aa = acc[b, k, p, r0, x0:x1]
                                for i in range(n):
                                    aa[i] += w[i] * pb[i]
                            if act_kk:
                                pa = planes[k, p, y, x0:x1]
                                ab = acc[b, kk, p, r1, x0 + dx:x1 + dx]
                                for i in range(n):
                                    ab[i] += w[i] * pa[i]
    return acc


@njit(parallel=True, cache=True)
def _merge_bands3d(acc, active, H):
    """Sum the band accumulators of :func:`_accumulate3d_kernel`: (K, P, H, W) float64."""
    nbands, K, P, BH, W = acc.shape
    halo = BH - (H + nbands - 1) // nbands
    B = BH - halo
    out = np.zeros((K, P, H, W), np.float64)
    for y in prange(H):
        for bb in range(nbands):
            r = y - bb * B
            if 0 <= r < B + halo:
                for k in range(K):
                    if active[k]:
                        for p in range(P):
                            for x in range(W):
                                out[k, p, y, x] += acc[bb, k, p, r, x]
    return out


@njit(parallel=True, cache=True)
def _merge_normalise3d(acc, planes, active, bins, out):
    """Band sums + centre term, normalised by the last plane, written as a video.

    For every active bin k: out[y, x, bins[k], c] = (Σ_b acc[c] + planes[k, c]) / (Σ_b acc[P−1]
    + planes[k, P−1]) in float64 (0 where the denominator is 0), c < P − 1; ``out`` is
    (H, W, T, P − 1) float32.
    """
    nbands, K, P, BH, W = acc.shape
    H = planes.shape[2]
    halo = BH - (H + nbands - 1) // nbands
    B = BH - halo
    C = P - 1
    for y in prange(H):
        s = np.empty((P, W), np.float64)
        for k in range(K):
            if not active[k]:
                continue
            for p in range(P):
                for x in range(W):
                    s[p, x] = planes[k, p, y, x]
            for bb in range(nbands):
                r = y - bb * B
                if 0 <= r < B + halo:
                    for p in range(P):
                        for x in range(W):
                            s[p, x] += acc[bb, k, p, r, x]
            t = bins[k]
            for x in range(W):
                d = s[C, x]
                for c in range(C):
                    out[y, x, t, c] = s[c, x] / d if d > 0 else 0.0


_EMPTY_F64_4D = np.zeros((1, 3, 1, 1), np.float64)
_EMPTY_I32_4D = np.zeros((1, 3, 1, 1), np.int32)


def temporal_factors(radius_t: int, profile: str = "box", sigma_t: float = 1.0) -> np.ndarray:
    """(2r_t+1,) float64 temporal factor of the offsets τ = −r_t..r_t (spec/jbf.md §1.4):
    1 for ``"box"``, exp(−½τ²/σ_t²) for ``"gaussian"`` (σ_t in bins; ∞ gives the box)."""
    radius_t = check_radius(radius_t, "radius_t")
    check_choice("temporal_profile", profile, TEMPORAL_PROFILES)
    sigma_t = check_positive("sigma_t", sigma_t, allow_inf=True)
    tau = np.arange(-radius_t, radius_t + 1, dtype=np.float64)
    if profile == "box" or math.isinf(sigma_t):
        return np.ones_like(tau)
    return np.exp(-0.5 * tau * tau / (sigma_t * sigma_t))


def _half_window_3d(guide: Guide):
    """Spatial offsets for the 3D half window: the centre first, then the 2D half window."""
    dys, dxs, es = _half_window(guide)
    dys = np.concatenate([[0], dys]).astype(np.int64)
    dxs = np.concatenate([[0], dxs]).astype(np.int64)
    es = np.concatenate([[0.0], es]).astype(np.float32)
    return dys, dxs, es


def accumulate3d(guide: Guide, planes: np.ndarray, tfac: np.ndarray, bins: np.ndarray,
                 active: np.ndarray | None = None, *, n_bins: int | None = None,
                 theta: np.ndarray | None = None, var: np.ndarray | None = None,
                 nint: np.ndarray | None = None, g2: float | None = None,
                 g2_table: np.ndarray | None = None,
                 normalise_into: np.ndarray | None = None) -> np.ndarray:
    """Numba fast path in 3D: Σ_{j ≠ i} W_ij · planes_j over a (2r+1)² × (2r_t+1) window.

    The base weight is the JBF of ``guide`` replicated along time (its G-buffers are per pixel)
    times a temporal factor, W_ij = ρ_ij · tfac[τ] (spec/jbf.md §1.4); with a guide of the
    ``"xy"`` feature only and no hit mask this is the plain 3D Gaussian of ``gauss3d`` when
    ``tfac`` is Gaussian. Bins outside the video get no weight.

    Args:
        guide: the spatial base filter (features, labels, window of radius r).
        planes: (K, P, H, W) values of the K bins in play (premultiplied by validity).
        tfac: (2r_t+1,) temporal factors of τ = −r_t..r_t.
        bins: (K,) increasing time indices of the planes' bins in the video; a neighbour bin that
            is not among them is absent (no weight), as are bins outside [0, n_bins).
        active: (K,) bool, the bins whose sums are wanted (default all); pairs between two
            inactive bins are skipped and inactive bins come back as 0.
        n_bins: T of the video (default bins[-1] + 1).
        theta, var: (K, 3, H, W) float64 statistics for the Welch test, or None (plain base
            filter); nint (K, 3, H, W) int32 with ``g2_table`` for non-uniform n, else ``g2``.
            A NaN θ fails every test, which makes that voxel nobody's neighbour.

        normalise_into: optional (H, W, n_bins, P − 1) float32 video; the active bins are then
            written there as (sums + planes)[:P−1] / (sums + planes)[P−1] (the centre term
            added, 0 where the denominator is 0) and the video is returned instead of the sums.

    Returns:
        (K, P, H, W) float64 sums without the centre term (the caller adds it), or
        ``normalise_into``.

    Precision as :func:`accumulate`: float32 weights and band sums, float64 Welch test and merge.
    """
    planes = np.ascontiguousarray(planes, dtype=np.float32)
    k_, _, h, w = planes.shape
    if (h, w) != guide.shape:
        raise DbenchInputError(f"planes: expected shape (K, P, {guide.shape[0]}, "
                               f"{guide.shape[1]}), got {planes.shape}")
    bins = np.asarray(bins, np.int64)
    if bins.shape != (k_,) or (k_ > 1 and np.any(np.diff(bins) <= 0)) or (k_ and bins[0] < 0):
        raise DbenchInputError(f"bins: expected {k_} increasing indices ≥ 0, got {bins!r}")
    n_bins = int(bins[-1] + 1) if n_bins is None and k_ else int(n_bins or 0)
    active = (np.ones(k_, np.bool_) if active is None
              else np.ascontiguousarray(active, dtype=np.bool_))
    tfac = np.asarray(tfac, np.float64)
    r_t = (len(tfac) - 1) // 2
    lookup = np.full(max(n_bins, 1), -1, np.int64)
    lookup[bins] = np.arange(k_)
    tau = np.arange(-r_t, r_t + 1)
    tt = bins[:, None] + tau[None, :]
    nbr = np.where((tt >= 0) & (tt < n_bins), lookup[np.clip(tt, 0, max(n_bins - 1, 0))], -1)
    fsq = _scaled_feature_groups(guide)
    dys, dxs, es = _half_window_3d(guide)
    dt_first = np.where((dys == 0) & (dxs == 0), r_t + 1, 0).astype(np.int64)
    if theta is None:
        test_mode, th, va, ni, table, gg = 0, _EMPTY_F64_4D, _EMPTY_F64_4D, _EMPTY_I32_4D, \
            _EMPTY_TABLE, 0.0
    else:
        th = np.ascontiguousarray(theta, dtype=np.float64)
        va = np.ascontiguousarray(var, dtype=np.float64)
        if g2_table is None:
            test_mode, ni, table, gg = 1, _EMPTY_I32_4D, _EMPTY_TABLE, float(g2)
        else:
            test_mode, gg = 2, 0.0
            ni = np.ascontiguousarray(nint, dtype=np.int32)
            table = np.ascontiguousarray(g2_table, dtype=np.float64)
    if normalise_into is not None:
        shape = (h, w, n_bins, planes.shape[1] - 1)
        if (normalise_into.shape != shape or normalise_into.dtype != np.float32
                or not normalise_into.flags.c_contiguous):
            raise DbenchInputError(f"normalise_into: expected a C-contiguous float32 array of "
                                   f"shape {shape}")
    if k_ == 0:
        return np.zeros(planes.shape, np.float64) if normalise_into is None else normalise_into
    acc = _accumulate3d_kernel(fsq, np.zeros((0, 1, 1), np.float32), planes, dys, dxs, es,
                               dt_first, tfac.astype(np.float32), np.ascontiguousarray(nbr),
                               active, th, va, ni, np.float64(gg), table, int(test_mode),
                               _num_bands(h), int(guide.radius))
    if normalise_into is None:
        return _merge_bands3d(acc, active, h)
    _merge_normalise3d(acc, planes, active, bins, normalise_into)
    return normalise_into


# ---------------------------------------------------------------------------------------------
# Fast path on PyTorch (CUDA when available); same maths, loop over the half window
# ---------------------------------------------------------------------------------------------

def accumulate_torch(guide: Guide, planes: np.ndarray, *, theta: np.ndarray | None = None,
                     var: np.ndarray | None = None, nint: np.ndarray | None = None,
                     g2: float | None = None, g2_table: np.ndarray | None = None,
                     device: Any = None, dtype: Any = None) -> np.ndarray:
    """PyTorch version of :func:`accumulate` for the JBF and the statistical test.

    Loops over the half window; per offset it works on whole shifted images (O(P·H·W) memory,
    no unfold). Weights in ``dtype`` (default float32; float64 for exact comparisons), the
    Welch test always in float64. ``device`` defaults to CUDA when available, else CPU.

    Returns:
        (P, H, W) float64 NumPy sums without the centre term.
    """
    import torch

    if device is None:
        device = "cuda" if torch.cuda.is_available() else "cpu"
    dtype = torch.float32 if dtype is None else dtype
    h, w = guide.shape
    tp = torch.as_tensor(np.asarray(planes), device=device).to(dtype)
    acc = torch.zeros_like(tp)
    # pre-scaled, centred features as in the Numba path: (F_i − F_j)² sums to the exponent
    scaled = [(f - float(np.mean(f))) * math.sqrt(0.5 * iv)
              for f, iv in zip(guide.features, guide.inv_var) if iv > 0]
    feats = torch.as_tensor(np.stack(scaled) if scaled else np.zeros((0, h, w)),
                            device=device).to(dtype)
    labels = torch.as_tensor(guide.labels, device=device)
    test = theta is not None
    if test:
        th = torch.as_tensor(np.asarray(theta, np.float64), device=device)
        va = torch.as_tensor(np.asarray(var, np.float64), device=device)
        if g2_table is not None:
            ni = torch.as_tensor(np.asarray(nint, np.int64), device=device)
            tab = torch.as_tensor(np.asarray(g2_table, np.float64), device=device)
    half = (guide.dy > 0) | ((guide.dy == 0) & (guide.dx > 0))
    order = np.lexsort((guide.dx[half], guide.dy[half]))
    dys, dxs, es64 = guide.dy[half][order], guide.dx[half][order], guide.spatial[half][order]
    for dy, dx, e in zip(dys.tolist(), dxs.tolist(), es64.tolist()):
        (ys, xs), (yn, xn) = shift_slices(dy, dx, h, w)
        if ys.start >= ys.stop or xs.start >= xs.stop:
            continue
        expo = ((feats[:, ys, xs] - feats[:, yn, xn]) ** 2).sum(0) + e
        wk = torch.exp(-expo) * (labels[ys, xs] == labels[yn, xn])
        if test:
            d = th[:, ys, xs] - th[:, yn, xn]
            s = va[:, ys, xs] + va[:, yn, xn]
            if g2_table is None:
                g = g2
            else:
                nu = (ni[:, ys, xs] + ni[:, yn, xn] - 2).clamp(0, tab.shape[0] - 1)
                g = tab[nu]
            ok = ((d * d < g * s) | (d == 0)).all(0)
            wk = wk * ok
        acc[:, ys, xs] += wk * tp[:, yn, xn]
        acc[:, yn, xn] += wk * tp[:, ys, xs]
    return acc.double().cpu().numpy()


def torch_cuda_available() -> bool:
    try:
        import torch
    except ImportError:  # pragma: no cover - torch is a dependency
        return False
    return bool(torch.cuda.is_available())


# ---------------------------------------------------------------------------------------------
# Public JBF
# ---------------------------------------------------------------------------------------------

def _finish(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    out = np.divide(num, den, out=np.zeros_like(num), where=den > 0)
    return out


def jbf_fast(color: Any, guide: Guide, *, backend: str = "numba") -> np.ndarray:
    """Fast JBF (Numba, or PyTorch with ``backend="torch"``): (H, W, 3) float32.

    Same result as :func:`jbf_reference` within float32 rounding (max relative difference
    ≈ 1e-6 measured; tests use 1e-5).
    """
    col, valid = _color_planes(color, guide.shape)
    v = valid.astype(np.float64)
    planes = np.concatenate([np.moveaxis(col, -1, 0), v[None]], axis=0)
    if backend == "torch":
        sums = accumulate_torch(guide, planes)
    else:
        sums = accumulate(guide, planes)
    sums += planes  # centre pixel: ρ_ii = 1, weight v_i
    out = _finish(sums[:3], sums[3:4])
    return np.ascontiguousarray(np.moveaxis(out, 0, -1), dtype=np.float32)


def resolve_backend(backend: str, *, allow_torch: bool = True) -> str:
    check_choice("backend", backend, BACKENDS)
    if backend == "auto":
        return "torch" if allow_torch and torch_cuda_available() else "numba"
    return backend


def joint_bilateral_filter(color: Any, albedo: Any, normal: Any, depth: Any = None,
                           position: Any = None, *, backend: str = "numba",
                           **options: Any) -> np.ndarray:
    """Joint bilateral filter of spec/jbf.md §1 on an (H, W, 3) image.

    Args:
        color: (H, W, 3) linear noisy radiance.
        albedo, normal: (H, W, 3) G-buffers; depth (H, W, 1) for the hit mask (None = all hit);
            position (H, W, 3) when ``features`` include ``"position"``.
        backend: ``"numba"`` (default), ``"torch"``, ``"auto"`` or ``"reference"`` (float64 NumPy).
        **options: :func:`make_guide` keywords (radius, sigma, sigma_convention, window,
            features, sigma_position, sigma_depth, hit_mask).

    Returns:
        (H, W, 3) float32.
    """
    backend = resolve_backend(backend, allow_torch=False)
    shape = _image_shape(color)
    guide = make_guide(albedo, normal, depth, position, shape=shape, **options)
    if backend == "reference":
        return jbf_reference(color, guide).astype(np.float32)
    return jbf_fast(color, guide, backend=backend)


# ---------------------------------------------------------------------------------------------
# Filtering effective illumination (seed 002, post-process form, spec/jbf.md §2.2)
# ---------------------------------------------------------------------------------------------

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
    """Check inputs and parameters of the illumination filter (spec/jbf.md §2.2)."""
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
    col, valid = _color_planes(color, setup.guide.shape)
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
    """Readable illumination filter (spec/jbf.md §2.2 steps 2-5, float64).

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
    """Seed-002 effective-illumination filter as a post-process (spec/jbf.md §2.2, simplified).

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
    setup = make_illumination_setup(albedo, normal, depth, position, shape=_image_shape(color),
                                    **options)
    if backend == "reference":
        return illumination_reference(color, setup).astype(np.float32)
    return illumination_fast(color, setup)
