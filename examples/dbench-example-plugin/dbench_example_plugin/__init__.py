"""A 3×3 box filter as a dbench method, registered through the ``dbench.methods`` entry point
``box3 = "dbench_example_plugin:Box3"`` (see ../pyproject.toml).

No ``@register`` here: dbench registers the class under the entry point's name when it starts
(``pip install -e examples/dbench-example-plugin``, then ``dbench list``).
"""
from __future__ import annotations

import numpy as np

from dbench.registry import Denoiser


class Box3(Denoiser):
    """Mean of the finite values in each pixel's 3×3 neighbourhood (edges replicated).

    Works on images (H, W, 3), sequence frames (stateless) and transient videos (H, W, T, 3:
    the filter is spatial, per time bin). Non-finite input pixels are left out of the mean and
    kept where no neighbour is finite, so finite input gives finite output (sums in float64, so
    values up to 3e38 do not overflow)."""

    kinds = {"steady", "sequence", "transient"}
    needs = {"color"}
    defaults = {"passes": 1}

    def denoise(self, data) -> np.ndarray:
        x = np.asarray(data.color, dtype=np.float64)
        for _ in range(int(self.params["passes"])):
            x = _box3(x)
        return x.astype(np.float32)


def _box3(x: np.ndarray) -> np.ndarray:
    finite = np.isfinite(x)
    values = np.where(finite, x, 0.0)
    pad = [(1, 1), (1, 1)] + [(0, 0)] * (x.ndim - 2)
    vp = np.pad(values, pad, mode="edge")
    wp = np.pad(finite.astype(np.float64), pad, mode="edge")
    h, w = x.shape[:2]
    total = sum(vp[i:i + h, j:j + w] for i in range(3) for j in range(3))
    count = sum(wp[i:i + h, j:j + w] for i in range(3) for j in range(3))
    return np.where(count > 0, total / np.maximum(count, 1.0), x)
