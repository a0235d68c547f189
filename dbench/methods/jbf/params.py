"""Constants of the ``jbf`` method with their sources: the seed's Σ and the guide's choices
(docs/methods/jbf.md §1.1-1.2, defined with the shared kernel), the named presets, the modes and the
backends."""
from __future__ import annotations

from typing import Any

from ..kernels.bilateral.params import FEATURES, SEED_SIGMA, SIGMA_CONVENTIONS, WINDOWS

#: Named parameter sets (docs/methods/jbf.md §1.2).
PRESETS: dict[str, dict[str, Any]] = {
    "seed": dict(sigma_convention="variance", window="square", radius=20),
    "statmc": dict(sigma_convention="sd", window="disk", radius=20),
}
BACKENDS = ("auto", "numba", "torch", "reference")
MODES = ("jbf", "illumination")
#: The options of ``make_guide`` the method passes through (host and device paths).
GUIDE_OPTIONS = ("radius", "sigma", "sigma_convention", "window", "features", "sigma_position",
                 "sigma_depth", "hit_mask")

__all__ = ["BACKENDS", "FEATURES", "GUIDE_OPTIONS", "MODES", "PRESETS", "SEED_SIGMA",
           "SIGMA_CONVENTIONS", "WINDOWS"]
