"""``jbf-bins``: the JBF on every time bin with shared G-buffers, and its 3D variant."""
from __future__ import annotations

import re

import numpy as np
import pytest

from dbench import registry
from dbench.data import Frame, TransientFrame
from dbench.errors import DbenchInputError
from dbench.methods.jbf import jbf_reference, make_guide
from dbench.methods.transient_baselines import jbf_bins


def _video(h=10, w=12, t=7, seed=0):
    rng = np.random.default_rng(seed)
    video = rng.random((h, w, t, 3)).astype(np.float32)
    video[:, :, [0, 4]] = 0.0                           # two bins without energy anywhere
    albedo = np.where(rng.random((h, w, 1)) > 0.5, 0.8, 0.2) * np.ones(3)
    normal = np.zeros((h, w, 3))
    normal[..., 2] = 1.0
    normal[h // 2:] = (0.0, 1.0, 0.0)
    depth = np.ones((h, w, 1))
    depth[0, 0] = 0.0                                   # one background pixel
    return TransientFrame(color=video, albedo=albedo, normal=normal, depth=depth,
                          meta={"start_opl": 3.0, "bin_width_opl": 0.1})


def test_registered_for_transient_only():
    m = registry.get("jbf-bins")
    assert m.kinds == {"transient"}
    assert m.applies_to("transient", {"color", "albedo", "normal", "depth"})[0]
    assert not m.applies_to("steady", {"color", "albedo", "normal", "depth"})[0]


def test_equals_the_jbf_reference_bin_by_bin():
    v = _video()
    out = registry.get("jbf-bins", radius=3).denoise(v)
    assert out.shape == v.color.shape and out.dtype == np.float32
    guide = make_guide(v.albedo, v.normal, v.depth, shape=v.shape, radius=3)
    for t in range(v.bins):
        ref = jbf_reference(v.color[:, :, t], guide)
        np.testing.assert_allclose(out[:, :, t], ref, rtol=1e-5, atol=1e-6)


def test_temporal_radius_box_and_gaussian():
    v = _video()
    guide = make_guide(v.albedo, v.normal, v.depth, shape=v.shape, radius=2)
    # numerators and denominators of the per-bin JBF: ref_t · W_t and W_t
    ones = np.ones(v.shape + (3,))
    den = jbf_reference(ones, guide)  # = 1 everywhere: recover W from a weighted constant
    assert np.allclose(den, 1.0)
    w = np.zeros(v.shape)
    for k in range(len(guide.dy)):
        from dbench.methods.jbf import reference_weights
        w += reference_weights(guide, k)
    num = np.stack([jbf_reference(v.color[:, :, t], guide) * w[..., None]
                    for t in range(v.bins)], axis=2)
    for profile, wt in (("box", [1.0, 1.0, 1.0]), ("gaussian", [np.exp(-0.5 / 0.49), 1.0,
                                                               np.exp(-0.5 / 0.49)])):
        out = jbf_bins(v.color, v.albedo, v.normal, v.depth, radius=2, temporal_radius=1,
                       temporal_profile=profile, sigma_t=0.7)
        for t in range(v.bins):
            if t in (0, 4):
                assert np.all(out[:, :, t] == 0)
                continue
            n = sum(wt[k + 1] * num[:, :, t + k] for k in (-1, 0, 1) if 0 <= t + k < v.bins)
            d = sum(wt[k + 1] * w for k in (-1, 0, 1) if 0 <= t + k < v.bins)
            np.testing.assert_allclose(out[:, :, t], n / d[..., None], rtol=1e-5, atol=1e-6)


def test_empty_bins_cost_nothing(monkeypatch):
    import dbench.methods.transient_baselines as tb
    seen = []
    real = tb.accumulate

    def spy(guide, planes, **kw):
        seen.append(planes.shape[0])
        return real(guide, planes, **kw)

    monkeypatch.setattr(tb, "accumulate", spy)
    v = _video(t=9)
    out = registry.get("jbf-bins", radius=2).denoise(v)
    assert seen == [4 * 7]                       # 7 non-empty bins, 4 planes each
    assert np.all(out[:, :, [0, 4]] == 0)
    seen.clear()
    empty = v.with_buffers(color=np.zeros_like(v.color))
    assert np.all(registry.get("jbf-bins").denoise(empty) == 0) and seen == []


def test_nan_voxels_do_not_spread():
    v = _video()
    c = v.color.copy()
    c[3, 4, 2, 1] = np.nan
    c[5, 5, 3] = np.inf
    out = registry.get("jbf-bins", radius=2).denoise(v.with_buffers(color=c))
    assert np.isfinite(out).all()
    clean = registry.get("jbf-bins", radius=2).denoise(v)
    np.testing.assert_allclose(out[:, :, [1, 5, 6]], clean[:, :, [1, 5, 6]], rtol=1e-6)


def test_bad_inputs_name_the_buffer():
    v = _video()
    with pytest.raises(DbenchInputError, match="TransientFrame"):
        registry.get("jbf-bins").denoise(Frame(color=np.zeros((4, 4, 3))))
    with pytest.raises(DbenchInputError, match="albedo"):
        registry.get("jbf-bins").denoise(v.with_buffers(albedo=None))
    with pytest.raises(DbenchInputError, match="temporal_radius"):
        registry.get("jbf-bins", temporal_radius=-1)
    with pytest.raises(DbenchInputError, match="temporal_profile"):
        registry.get("jbf-bins", temporal_profile="tent")


@pytest.mark.parametrize("features, said", [
    (1, "a name or a sequence of names"), (None, "a name or a sequence of names"),
    ("foo", "got 'foo'"), (("xy", "position"), "got 'position'")])  # no position buffer
def test_features_are_checked_when_built(features, said):
    """docs/methods/jbf-bins.md: every value is checked at construction, before rendering."""
    with pytest.raises(DbenchInputError, match=rf"^jbf-bins: features: .*{re.escape(said)}"):
        registry.get("jbf-bins", features=features)
