"""Steady renders: exact per-pixel statistics, box-filter samples, features, determinism
(docs/mitsuba.md §10, issue checks for the foundation)."""
import numpy as np
import pytest
from scipy import stats as sps

from dbench.datasets import render
from dbench.datasets.scenes import catalogue as scenes
from dbench.datasets.stats import transform_samples

pytestmark = pytest.mark.mitsuba


def _stacked_samples(scene, res, spp, seed=0):
    batches = list(render.sample_batches(scene, res, spp, seed))
    # (res, copies, res, 3) per batch -> (spp, res, res, 3)
    return np.concatenate([np.moveaxis(b, 1, 0) for b in batches], axis=0).astype(np.float64)


@pytest.mark.parametrize("transform,lam", [("identity", 1.0), ("box-cox", 0.5),
                                           ("yeo-johnson", 0.5), ("box-cox", 0.25)])
def test_renderer_statistics_equal_numpy_on_the_same_samples(renderer, transform, lam):
    sc = scenes.get("cornell")
    color, st, _ = render.render_passes(sc, 12, 16, seed=3, stats=(transform, lam),
                                        progress=False)
    x = _stacked_samples(sc, 12, 16, seed=3)
    y = transform_samples(x, transform, lam)
    n = x.shape[0]
    assert np.all(st.n == n)
    np.testing.assert_allclose(color, x.mean(axis=0), rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(st.mean, y.mean(axis=0), rtol=1e-6, atol=1e-9)
    var = np.var(y, axis=0, ddof=1) / n
    nonzero = var > 1e-12
    np.testing.assert_allclose(st.var_mean[nonzero], var[nonzero], rtol=1e-6)
    assert np.all(st.var_mean[~nonzero] < 1e-12)
    m3 = sps.moment(y, moment=3, axis=0)
    scale = np.maximum(np.abs(m3), (var * n) ** 1.5)
    assert np.all(np.abs(st.m3 - m3) <= 1e-6 * scale + 1e-12)


def test_each_sample_lands_in_exactly_one_pixel(renderer):
    # An emitter seen directly with max_depth 1: every sample is 0 or the emitter radiance,
    # never a filtered mixture of the two (docs/mitsuba.md §10 check 3).
    from dbench.datasets.scenes.catalogue import Scene

    def build(mi, res):
        return {"type": "scene",
                "sensor": scenes.camera_dict(mi, res, origin=[0, 0, 4], target=[0, 0, 0]),
                "lamp": {"type": "sphere", "radius": 0.8,
                         "emitter": {"type": "area", "radiance": {"type": "rgb",
                                                                  "value": [2.0, 2.0, 2.0]}}}}
    lamp = Scene("lamp", "steady", "test", build, max_depth=1)
    x = _stacked_samples(lamp, 16, 8)
    assert set(np.unique(x)) <= {0.0, 2.0}
    assert 0 < (x == 2.0).mean() < 1


def test_sample_mean_agrees_with_a_plain_render(renderer):
    sc = scenes.get("cornell")
    color, _, _ = render.render_passes(sc, 32, 64, seed=0, progress=False)
    plain, _ = render.render_plain(sc, 32, 64, seed=0)
    x = _stacked_samples(sc, 32, 64)
    se = x.mean(axis=(1, 2, 3)).std(ddof=1) / np.sqrt(64)
    assert abs(color.mean() - plain.mean()) < 3 * np.sqrt(2) * se


def test_color_is_identical_with_and_without_statistics(renderer):
    sc = scenes.get("textured")
    a, st, _ = render.render_passes(sc, 16, 8, stats=("box-cox", 0.5), progress=False)
    b, none, _ = render.render_passes(sc, 16, 8, progress=False)
    assert none is None and st is not None
    np.testing.assert_array_equal(a, b)


def test_renders_are_deterministic_per_seed(renderer):
    sc = scenes.get("cornell")
    a, _, _ = render.render_passes(sc, 16, 4, seed=7, progress=False)
    b, _, _ = render.render_passes(sc, 16, 4, seed=7, progress=False)
    c, _, _ = render.render_passes(sc, 16, 4, seed=8, progress=False)
    np.testing.assert_array_equal(a, b)
    assert (a != c).any(axis=-1).mean() > 0.5


def test_features_have_expected_layout(renderer):
    feats, _ = render.render_features(scenes.get("cornell"), 16, spp=8)
    assert feats["albedo"].shape == (16, 16, 3) and feats["depth"].shape == (16, 16, 1)
    norms = np.linalg.norm(feats["normal"], axis=-1)
    hit = feats["depth"][..., 0] > 0
    assert hit.mean() > 0.9
    assert np.median(norms[hit]) == pytest.approx(1.0, abs=1e-3)
    assert np.all((feats["albedo"] >= 0) & (feats["albedo"] <= 1))


def test_batch_size_divides_spp_and_bounds_memory():
    for res, spp in [(8, 7), (256, 64), (1280, 1024), (64, 1)]:
        m = render.batch_size(res, spp)
        assert spp % m == 0 and m * res * res <= max(render.MAX_BATCH_PIXELS, res * res)


@pytest.mark.parametrize("name", scenes.available())
def test_every_catalogue_scene_renders_finite_images(renderer, name):
    color, st, _ = render.render_passes(scenes.get(name), 8, 2, stats=("box-cox", 0.5),
                                        progress=False)
    assert color.shape == (8, 8, 3) and np.all(np.isfinite(color))
    assert np.all(np.isfinite(st.theta)) and color.max() > 0
