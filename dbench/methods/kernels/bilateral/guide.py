"""The guide of the base filter ρ: G-buffers checked and turned into feature planes, the
diagonal Σ⁻¹, the window offsets with their spatial exponent and the mask labels (hit /
background / emitter / isolated, docs/methods/jbf.md §1.3), computed once per frame; also the colour
as float64 planes with its validity, shared by every filter on this guide.

Shapes: images are (H, W, 3), ``depth`` is (H, W, 1) or (H, W)."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from ....data import check_buffer
from ....errors import DbenchInputError
from ...checks import check_choice, check_positive, check_radius
from .params import (FEATURES, LABEL_BACKGROUND, LABEL_EMITTER, LABEL_FIRST_ISOLATED, LABEL_HIT,
                     SEED_SIGMA, SIGMA_CONVENTIONS, TEMPORAL_PROFILES, WINDOWS)


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
    """Σ⁻¹ entry for one Σ entry: 1/σ for ``"variance"``, 1/σ² for ``"sd"`` (docs/methods/jbf.md §1.2)."""
    var = sigma if convention == "variance" else sigma * sigma
    return 0.0 if math.isinf(var) else 1.0 / var


def window_offsets(radius: int, window: str = "square") -> tuple[np.ndarray, np.ndarray]:
    """Offsets (dy, dx) of the window, row-major, including (0, 0).

    ``square``: |dx|, |dy| ≤ r, (2r+1)² taps; ``disk``: dx² + dy² ≤ r² (docs/methods/jbf.md §1.2).
    """
    radius = check_radius(radius)
    check_choice("window", window, WINDOWS)
    oy, ox = np.mgrid[-radius:radius + 1, -radius:radius + 1]
    keep = np.ones_like(oy, bool) if window == "square" else (oy * oy + ox * ox <= radius * radius)
    return oy[keep].astype(np.int64), ox[keep].astype(np.int64)


@dataclass(frozen=True)
class Guide:
    """Noise-free guide data of the base filter ρ (docs/methods/jbf.md §1, docs/methods/statistical.md §7).

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


def image_shape(color: Any, name: str = "color") -> tuple[int, int]:
    arr = np.asarray(color) if color is not None else None
    if arr is None or arr.ndim != 3 or arr.shape[2] != 3 or 0 in arr.shape:
        raise DbenchInputError(f"{name}: expected shape (H, W, 3), got "
                               f"{None if arr is None else tuple(arr.shape)}")
    return arr.shape[0], arr.shape[1]


def depth_buffer(depth: Any, h: int, w: int) -> np.ndarray:
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
    """Check the G-buffers and build the :class:`Guide` of the JBF (docs/methods/jbf.md §1).

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
        hit_mask: h_ij = 0 when exactly one of i, j is a hit (depth > 0) (docs/methods/jbf.md §1.3).
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
                shape = image_shape(buffers[name], name)
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
    depth_arr = None if depth is None else depth_buffer(depth, h, w)
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


def color_planes(color: Any, shape: tuple[int, int] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(H, W, 3) colour as float64 with missing pixels zeroed, and the (H, W) validity mask."""
    h, w = image_shape(color) if shape is None else shape
    col = check_buffer("color", color, (h, w, 3), dtype=np.float64)
    valid = np.all(np.isfinite(col), axis=-1)
    return np.where(valid[..., None], col, 0.0), valid


def temporal_factors(radius_t: int, profile: str = "box", sigma_t: float = 1.0) -> np.ndarray:
    """(2r_t+1,) float64 temporal factor of the offsets τ = −r_t..r_t (docs/methods/jbf.md §1.4):
    1 for ``"box"``, exp(−½τ²/σ_t²) for ``"gaussian"`` (σ_t in bins; ∞ gives the box)."""
    radius_t = check_radius(radius_t, "radius_t")
    check_choice("temporal_profile", profile, TEMPORAL_PROFILES)
    sigma_t = check_positive("sigma_t", sigma_t, allow_inf=True)
    tau = np.arange(-radius_t, radius_t + 1, dtype=np.float64)
    if profile == "box" or math.isinf(sigma_t):
        return np.ones_like(tau)
    return np.exp(-0.5 * tau * tau / (sigma_t * sigma_t))
