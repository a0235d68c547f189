"""``oidn-bins``: OIDN on every time bin as an image, features shared."""
from __future__ import annotations

import numpy as np
import pytest

from dbench import registry
from dbench.data import Frame, TransientFrame
from dbench.errors import DbenchInputError
from dbench.methods.oidn import oidn_denoise


def _video(t=5, seed=0):
    rng = np.random.default_rng(seed)
    h = w = 16
    y, x = np.mgrid[0:h, 0:w]
    clean = (0.2 + 0.1 * np.sin(x / 3.0))[..., None] * np.ones(3)
    video = np.stack([clean * (k + 1) + 0.05 * rng.standard_normal((h, w, 3))
                      for k in range(t)], axis=2).clip(0).astype(np.float32)
    video[:, :, 1] = 0.0                                 # a bin without energy
    albedo = np.full((h, w, 3), 0.5, np.float32)
    normal = np.zeros((h, w, 3), np.float32)
    normal[..., 2] = 1.0
    return TransientFrame(color=video, albedo=albedo, normal=normal)


def test_registered_for_transient_only():
    m = registry.get("oidn-bins")
    assert m.kinds == {"transient"} and m.needs == {"color", "albedo", "normal"}


def test_each_bin_is_oidn_on_that_image():
    v = _video()
    out = registry.get("oidn-bins").denoise(v)
    assert out.shape == v.color.shape and out.dtype == np.float32 and np.isfinite(out).all()
    for t in (0, 3):
        np.testing.assert_allclose(out[:, :, t], oidn_denoise(v.color[:, :, t], v.albedo,
                                                              v.normal), rtol=1e-5, atol=1e-6)
    assert np.all(out[:, :, 1] == 0)


def test_empty_bins_are_skipped(monkeypatch):
    import dbench.methods.transient_baselines as tb
    calls = []
    real = tb.oidn_denoise
    monkeypatch.setattr(tb, "oidn_denoise", lambda *a, **k: calls.append(1) or real(*a, **k))
    v = _video(t=6)
    registry.get("oidn-bins").denoise(v)
    assert len(calls) == 5
    calls.clear()
    registry.get("oidn-bins", skip_empty=False).denoise(v)
    assert len(calls) == 6


def test_nan_and_bad_inputs():
    v = _video()
    c = v.color.copy()
    c[2, 3, 2] = np.nan
    out = registry.get("oidn-bins").denoise(v.with_buffers(color=c))
    assert np.isfinite(out).all()
    with pytest.raises(DbenchInputError, match="TransientFrame"):
        registry.get("oidn-bins").denoise(Frame(color=np.zeros((4, 4, 3))))
    with pytest.raises(DbenchInputError, match="normal"):
        registry.get("oidn-bins").denoise(v.with_buffers(normal=None))
    with pytest.raises(DbenchInputError, match="features"):
        registry.get("oidn-bins", features="depth")
    out = registry.get("oidn-bins", features="none").denoise(v.with_buffers(albedo=None,
                                                                           normal=None))
    assert out.shape == v.color.shape
