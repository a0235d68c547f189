"""Constants of ``svgf`` / ``asvgf`` with their sources (spec/svgf.md; [dbench] marks values
chosen here, [Falcor] values taken from Falcor's SVGF pass), and the named presets."""
from __future__ import annotations

import numpy as np

#: B3-spline taps h1 (spec §5).
H1 = np.array([1 / 16, 1 / 4, 3 / 8, 1 / 4, 1 / 16])
#: 3×3 Gaussian (1,2,1)ᵀ(1,2,1)/16 that blurs the variance before each iteration (spec §3).
G3 = np.array([0.25, 0.5, 0.25])
EPS_Z = 1e-6       # [dbench]
EPS_VAR = 1e-4     # [Falcor varianceEpsilon]
ALBEDO_EPS = np.float32(1e-3)  # spec §2
N_SPATIAL = 4      # history below this: spatial variance (spec §4)
SPATIAL_RADIUS = 3  # 7×7 window

PRESETS = {
    "paper": dict(sigma_z=1.0, sigma_n=128.0, sigma_l=4.0, iterations=5, feedback_tap=0,
                  alpha_min=0.2, alpha_min_moments=0.2),
    "falcor": dict(sigma_z=1.0, sigma_n=128.0, sigma_l=10.0, iterations=4, feedback_tap=1,
                   alpha_min=0.05, alpha_min_moments=0.2),
}
GRADIENT_MODES = ("seed", "paper")
ALPHA0_PAPER = 0.2
