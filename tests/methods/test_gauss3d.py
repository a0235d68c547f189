"""``gauss3d``: the plain 3D Gaussian of docs/methods/jbf.md §1.4 (participating media baseline)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from dbench import registry
from dbench.data import Frame, TransientFrame
from dbench.errors import DbenchInputError
from dbench.methods.transient_baselines import gauss3d, gauss3d_reference


def _video(h=9, w=11, t=8, seed=0):
    rng = np.random.default_rng(seed)
    v = rng.random((h, w, t, 3)).astype(np.float32)
    v[:, :, [0, 6]] = 0.0
    return v


def test_defaults_follow_the_spec():
    m = registry.get("gauss3d")
    assert m.kinds == {"transient"} and m.needs == {"color"}
    assert (m.params["radius"], m.params["temporal_radius"], m.params["sigma_s2"],
            m.params["sigma_t"]) == (5, 1, 10.0, 1.0)


@pytest.mark.parametrize("kw", [{}, dict(radius=2, temporal_radius=2, sigma_s2=3.0,
                                         sigma_t=0.8), dict(radius=0, temporal_radius=0)])
def test_separable_fast_path_equals_the_direct_sum(kw):
    v = _video()
    ref = gauss3d_reference(v, **kw)
    np.testing.assert_allclose(gauss3d(v, skip_empty=False, **kw), ref, rtol=1e-6, atol=1e-7)
    ref[:, :, [0, 6]] = 0.0
    np.testing.assert_allclose(gauss3d(v, **kw), ref, rtol=1e-6, atol=1e-7)


def test_impulse_weights_and_borders():
    """An impulse in a zero video: out at offset (dy, dx, dt) = ρ / Σ_window ρ (all voxels
    valid, windows inside the video); constants survive at every border (neighbours outside
    the video get no weight)."""
    v = np.zeros((21, 21, 7, 3), np.float32)
    v[7, 7, 3] = 1.0
    out = gauss3d(v, skip_empty=False)
    z = sum(math.exp(-0.5 * (dx * dx + dy * dy) / 10.0 - 0.5 * dt * dt)
            for dy in range(-5, 6) for dx in range(-5, 6) for dt in (-1, 0, 1))
    rho = math.exp(-0.5 * (4 + 9) / 10.0 - 0.5)
    assert out[9, 10, 4, 0] == pytest.approx(rho / z, rel=1e-5)
    assert out[7, 7, 3, 1] == pytest.approx(1.0 / z, rel=1e-5)
    c = np.ones((6, 6, 4, 3), np.float32)               # constants survive at every border
    np.testing.assert_allclose(gauss3d(c), 1.0, rtol=1e-6)


def test_empty_bins_and_nan():
    v = _video()
    out = registry.get("gauss3d").denoise(TransientFrame(color=v))
    assert out.dtype == np.float32 and np.all(out[:, :, [0, 6]] == 0)
    assert np.all(gauss3d(np.zeros((4, 4, 5, 3))) == 0)
    v2 = v.copy()
    v2[4, 4, 3, 0] = np.nan
    v2[1, 1, 2] = -np.inf
    out2 = gauss3d(v2)
    assert np.isfinite(out2).all()
    np.testing.assert_allclose(out2, np.where(np.isfinite(gauss3d_reference(v2)),
                                              gauss3d_reference(v2), 0) * (out2 != 0),
                               rtol=1e-6, atol=1e-7)


def test_bad_inputs():
    with pytest.raises(DbenchInputError, match="TransientFrame"):
        registry.get("gauss3d").denoise(Frame(color=np.zeros((4, 4, 3))))
    with pytest.raises(DbenchInputError, match="radius"):
        registry.get("gauss3d", radius=-2)
    with pytest.raises(DbenchInputError, match="sigma_t"):
        registry.get("gauss3d", sigma_t=0.0)
