"""``noisy``: the identity, the row every report compares against."""
from __future__ import annotations

import numpy as np

from ...denoiser import Denoiser, register


@register("noisy")
class Noisy(Denoiser):
    """Returns the noisy input unchanged (float32 copy); non-finite pixels stay as they are,
    since the point of this row is to show the input exactly as the renderer produced it."""

    kinds = {"steady", "sequence", "transient"}
    needs = {"color"}
    defaults: dict = {}

    def denoise(self, data) -> np.ndarray:
        self.check_input(data)
        return np.array(data.color, dtype=np.float32, copy=True)
