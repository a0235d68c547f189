"""Speed of the JBF fast path against the reference (prints; not a test).

    python -m dbench.speed.jbf            # 1280×720, radius 20

Times are medians of ``repeats`` runs after one warm-up call (which also compiles Numba).
The reference is timed on a crop when the full frame would take too long and scaled per pixel
(its cost is linear in the pixel count).
"""
from __future__ import annotations

import argparse
from typing import Any

from ..methods.jbf.fast import jbf_fast
from ..methods.jbf.illumination import illumination_fast, make_illumination_setup
from ..methods.jbf.reference import jbf_reference
from ..methods.kernels.bilateral.guide import make_guide
from ..synthetic import synthetic_frame
from .timing import median_time, reference_crop


def benchmark(height: int = 720, width: int = 1280, radius: int = 20, repeats: int = 3,
              reference_max_pixels: int = 160 * 90) -> dict[str, Any]:
    """Median seconds per frame of the Numba JBF, the illumination mode and the reference.

    Returns:
        dict with ``fast_s``, ``illumination_s``, ``reference_s`` (per frame, scaled from a crop
        of at most ``reference_max_pixels`` pixels when smaller than the frame),
        ``reference_crop``, ``speedup`` and the sizes.
    """
    f = synthetic_frame(height, width)
    guide = make_guide(f["albedo"], f["normal"], f["depth"], radius=radius)
    fast_s = median_time(lambda: jbf_fast(f["color"], guide), repeats)
    setup = make_illumination_setup(f["albedo"], f["normal"], f["depth"], radius=radius)
    illum_s = median_time(lambda: illumination_fast(f["color"], setup), repeats)

    ch, cw = reference_crop(height, width, reference_max_pixels)
    crop = {k: v[:ch, :cw] for k, v in f.items()}
    cguide = make_guide(crop["albedo"], crop["normal"], crop["depth"], radius=radius)
    ref_crop_s = median_time(lambda: jbf_reference(crop["color"], cguide), max(1, repeats // 3))
    ref_s = ref_crop_s * (height * width) / (ch * cw)
    return dict(height=height, width=width, radius=radius, fast_s=fast_s,
                illumination_s=illum_s, reference_s=ref_s, reference_crop=(ch, cw),
                speedup=ref_s / fast_s)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--height", type=int, default=720)
    ap.add_argument("--width", type=int, default=1280)
    ap.add_argument("--radius", type=int, default=20)
    ap.add_argument("--repeats", type=int, default=3)
    a = ap.parse_args(argv)
    r = benchmark(a.height, a.width, a.radius, a.repeats)
    print(f"jbf {r['width']}x{r['height']} r={r['radius']}: fast {r['fast_s']:.3f} s, "
          f"illumination {r['illumination_s']:.3f} s, reference {r['reference_s']:.1f} s "
          f"(crop {r['reference_crop'][1]}x{r['reference_crop'][0]}, scaled), "
          f"speedup {r['speedup']:.0f}x")


if __name__ == "__main__":
    main()
