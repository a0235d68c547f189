"""The variance floor of the gate (dbench/methods/kernels/variance_floor.py); its compiled
form runs inside the gate's passes and is tested there (test_gate.py, pooled fast gate against
the reference)."""
from __future__ import annotations

import numpy as np
import pytest

from dbench.methods.kernels.variance_floor import floored_variance


def test_floor_is_the_window_mean_inside_the_image():
    v = np.zeros((6, 7, 2))
    v[0, 0, 1] = 12.0
    out = floored_variance(v, 1)
    assert out[0, 0, 1] == 12.0  # its own value is larger than the mean
    assert out[1, 1, 1] == pytest.approx(12.0 / 9)  # a full 3x3 window
    assert out[0, 1, 1] == pytest.approx(12.0 / 6)  # the 2x3 part inside the image
    assert out[3, 3, 1] == 0.0 and not out[..., 0].any()
    np.testing.assert_array_equal(floored_variance(v, 0), v)


def test_refuses_a_bad_radius():
    for bad in (-1, 1.5, True):
        with pytest.raises(ValueError, match="radius"):
            floored_variance(np.zeros((2, 2, 1)), bad)
