"""Constants of ``bmfr`` with their sources (docs/methods/bmfr.md; [dbench] marks values chosen
here, [BMFR code] values of the authors' implementation), and the constants of the counter-based
hash behind the feature noise (splitmix64) that the reference, Numba and PyTorch paths share."""
from __future__ import annotations

import numpy as np

from ..svgf.params import ALBEDO_FLOOR


_P = ("px", "py", "pz")
_P2 = ("px2", "py2", "pz2")
#: Feature presets (docs/methods/bmfr.md §2): names of the columns, constant first. Normal columns name their
#: buffer by their first letter (NORMAL_SOURCES): n the shading normal, g the geometric normal,
#: r the glossy reflected normal (seed 001 §1.2.1's feature buffers; docs/temporal.md §10).
FEATURE_PRESETS = {
    "paper": ("1", "nx", "ny", "nz") + _P + _P2,
    "seed": ("1", "nx", "ny", "nz") + _P,
    "normals": ("1", "nx", "ny", "nz"),
    "positions": ("1",) + _P,
    "reflected": ("1", "rx", "ry", "rz") + _P + _P2,
    "paper+geo": ("1", "nx", "ny", "nz", "gx", "gy", "gz") + _P + _P2,
    "reflected+geo": ("1", "rx", "ry", "rz", "gx", "gy", "gz") + _P + _P2,
}
#: The normal buffers behind a column's first letter, in the order of the stacked normals the
#: fit reads (planar (3·k, H, W): the k sources a preset uses, in this order).
NORMAL_SOURCES = {"n": "normal", "g": "geo_normal", "r": "reflected_normal"}


def normal_sources(preset: str) -> tuple[str, ...]:
    """The letters of NORMAL_SOURCES a preset's columns read, in NORMAL_SOURCES' order."""
    used = {name[0] for name in FEATURE_PRESETS[preset] if name[0] in NORMAL_SOURCES}
    return tuple(k for k in NORMAL_SOURCES if k in used)


def normal_column(preset: str, name: str) -> int:
    """The channel of the stacked normals a normal column ``name`` ("nx", "gy", …) reads."""
    return 3 * normal_sources(preset).index(name[0]) + "xyz".index(name[1])
RCOND = 1e-10      # rank safeguard |R_kk| < rcond · max |R_jj| (docs/methods/bmfr.md §5) [dbench]
N_OFFSETS = 16     # per-frame grid offsets, cycling [BMFR code]
#: [dbench] BMFR fits the illumination without demodulating it (a_eff = clip(albedo, 1, 1) = 1):
#: on the 8 training sequences that chose the demodulation floor it was better than every
#: floor in RMSE, RMSE over surfaces and relMSE (ratios to accumulation 0.902 / 0.852 / 0.749
#: against 0.904 / 0.866 / 0.933 at SVGF's 0.2), and so on the 8 held-out ones (0.927 / 0.846 /
#: 0.722 against 0.935 / 0.873 / 0.754); on the catalogue it changes nothing measurable. The
#: residual hand-back returns the texture the block fit misses (docs/temporal.md §12).
ALBEDO_FLOOR_BMFR = 1.0
#: the seed's implementation [S001 §3.2]: 64×64 blocks fitted from 36 random pixels, feature set
#: 3; the paper's method: every default but the [dbench] residual hand-back (docs/temporal.md §9);
#: both demodulate as the paper does, with SVGF's bounded rule (ALBEDO_FLOOR)
PRESETS = {"seed": dict(block_size=64, features="seed", samples=36, handback="none",
                        albedo_floor=ALBEDO_FLOOR),
           "paper": dict(handback="none", albedo_floor=ALBEDO_FLOOR)}


#: splitmix64 (Steele, Lea, Flood 2014): increment, multipliers, shifts; 2⁻⁵³; a 16-bit mask.
_GOLD = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)
_INV53 = 1.0 / 9007199254740992.0
_MASK16 = np.uint64(0xFFFF)
