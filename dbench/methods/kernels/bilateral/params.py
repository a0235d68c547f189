"""Constants of the joint bilateral base filter, with their sources (docs/methods/jbf.md)."""
from __future__ import annotations

#: Σ of the seed (docs/methods/jbf.md §1.1): (x, y, albedo r, g, b, normal x, y, z), a covariance.
SEED_SIGMA: tuple[float, ...] = (10.0, 10.0, 0.02, 0.02, 0.02, 0.1, 0.1, 0.1)
FEATURES = ("xy", "albedo", "normal", "position", "depth")
SIGMA_CONVENTIONS = ("variance", "sd")
WINDOWS = ("square", "disk")
#: Temporal profiles of the 3D base filter (docs/methods/jbf.md §1.4).
TEMPORAL_PROFILES = ("box", "gaussian")

#: Mask labels: pixels mix only with pixels of the same label. 0 = background (depth ≤ 0),
#: 1 = hit, ≥ 2 = isolated pixels (one label each).
# Pixels of different labels never weigh each other: background (nothing hit), surfaces,
# emitters seen directly (from the ``emitter`` buffer), and one label per isolated pixel.
LABEL_BACKGROUND, LABEL_HIT, LABEL_EMITTER, LABEL_FIRST_ISOLATED = 0, 1, 2, 3
#: In the Numba kernel the label becomes a feature plane 16·label; distinct labels differ by
#: ≥ 16, i.e. add ≥ 256 to the exponent, and exp(−s) is exactly 0 for s ≥ 87
#: (:func:`~dbench.methods.kernels.bilateral.vexp.exp32`).
LABEL_SCALE = 16.0
EXP_CUTOFF = 87.0

#: Largest |value| a plane may hold in the float32 band sums of
#: :func:`~dbench.methods.kernels.bilateral.numba2d.accumulate` (and ``numba3d.accumulate3d``,
#: the Triton window kernels): a window of (2·20 + 1)² = 1681 taps of weight ≤ 1 then sums to
#: ≤ 1.7e33, far below the float32 maximum (a 3-D window of 1681 × 7 bins to ≤ 1.2e34).
PLANE_MAX = 1e30
