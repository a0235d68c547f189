"""Tests of dbench.metrics: spec docs/metrics.md §6 checks 1-6, hand-computed values, agreement with
scikit-image, input errors, the non-finite policy, transient shapes, tiny images, HDR-FLIP exposures.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from skimage.metrics import peak_signal_noise_ratio, structural_similarity

import dbench.metrics as M
from dbench.errors import DbenchInputError, UnknownNameError
from dbench.metrics import hdr as image_mod

ALL = ["mse", "rmse", "relmse", "smape", "rmae", "psnr", "ssim", "flip", "hdrflip"]


def _hdr(shape, seed=0, scale=1.5):
    rng = np.random.default_rng(seed)
    return rng.random(shape) ** 2 * scale


def _ldr_pair_with_offset(shape, offset, seed=1):
    """Linear images whose tone-mapped versions are a and a + offset (inside [0, 1])."""
    rng = np.random.default_rng(seed)
    a = rng.uniform(0.1, 0.8, size=shape)
    return M.srgb_decode(a + offset), M.srgb_decode(a), a


# --------------------------------------------------------------------------------- API


def test_available_and_definitions():
    names = M.available()
    for n in ALL:
        assert n in names
    assert set(M.DEFINITIONS) == set(names)
    assert all(isinstance(v, str) and v and "\n" not in v for v in M.DEFINITIONS.values())
    assert "1e-2" in M.DEFINITIONS["relmse"] and "1e-2" in M.DEFINITIONS["smape"]
    assert "100" in M.DEFINITIONS["psnr"] and "2^EV" in M.DEFINITIONS["psnr"]
    for const in ("σ = 1.5", "K1 = 0.01", "K2 = 0.03", "data range 1", "population"):
        assert const in M.DEFINITIONS["ssim"]
    assert "ppd 67" in M.DEFINITIONS["flip"] and "sRGB" in M.DEFINITIONS["flip"]
    assert "ppd 67" in M.DEFINITIONS["hdrflip"] and "exposure" in M.DEFINITIONS["hdrflip"]
    assert "0.0031308" in M.TONEMAP_DEFINITION


def test_unknown_metric_lists_valid_names():
    r = _hdr((4, 4, 3))
    with pytest.raises(UnknownNameError) as e:
        M.compute("lpips", r, r)
    msg = str(e.value)
    assert "lpips" in msg and all(n in msg for n in ALL)
    with pytest.raises(UnknownNameError):
        M.compute_all(r, r, names=["rmse", "nope"])
    with pytest.raises(UnknownNameError) as e:
        M.compute("relmse", r, r, epsilon=1e-4)
    assert "eps" in str(e.value)
    assert M.compute("RMSE", r, r) == 0.0


# --------------------------------------------------------------------------------- §6 checks


def test_check1_identity():
    r = _hdr((24, 20, 3))
    vals = M.compute_all(r.copy(), r)
    for n in ("mse", "rmse", "relmse", "smape", "rmae"):
        assert vals[n] == 0.0, n
    assert vals["psnr"] == 100.0
    assert vals["ssim"] == pytest.approx(1.0, abs=1e-12)
    assert vals["flip"] == 0.0
    assert vals["hdrflip"] == 0.0


def test_check2_constant_offset():
    r = np.ones((5, 6, 3))
    x = np.full((5, 6, 3), 1.1)
    assert M.compute("rmse", x, r) == pytest.approx(0.1, rel=1e-12)
    assert M.compute("mse", x, r) == pytest.approx(0.01, rel=1e-12)
    assert M.compute("relmse", x, r) == pytest.approx(0.01 / 1.01, rel=1e-12)
    assert M.compute("relmse", x, r) == pytest.approx(0.00990099, abs=5e-9)
    assert M.compute("smape", x, r) == pytest.approx(0.1 / 2.11, rel=1e-12)
    assert M.compute("smape", x, r) == pytest.approx(0.04739336, abs=5e-9)


def test_check3_zero_reference():
    r = np.zeros((5, 6, 3))
    x = np.full((5, 6, 3), 0.1)
    assert M.compute("relmse", x, r) == pytest.approx(1.0, rel=1e-12)
    assert M.compute("smape", x, r) == pytest.approx(0.1 / 0.11, rel=1e-12)
    assert M.compute("smape", x, r) == pytest.approx(0.9090909, abs=5e-8)


def test_check4_srgb_and_ldr_psnr():
    enc = M.srgb_encode(np.array([0.5, 0.002, 1.0]))
    assert enc[0] == pytest.approx(0.7353570, abs=5e-8)
    assert enc[1] == pytest.approx(0.02584, abs=1e-12)
    assert enc[2] == pytest.approx(1.0, abs=1e-15)
    assert M.tonemap(np.array([0.5]))[0] == pytest.approx(0.7353570, abs=5e-8)
    x, r, _ = _ldr_pair_with_offset((16, 16, 3), 0.01)
    assert M.compute("psnr", x, r) == pytest.approx(40.0, abs=1e-9)
    a = np.full((3, 3, 3), 0.5)
    assert M.psnr_ldr(a + 0.01, a) == pytest.approx(40.0, abs=1e-9)


def test_check5_ssim_offset_matches_skimage():
    x, r, a = _ldr_pair_with_offset((40, 36, 3), 0.1)
    ours = M.compute("ssim", x, r)
    ref = structural_similarity(a + 0.1, a, gaussian_weights=True, sigma=1.5,
                                use_sample_covariance=False, data_range=1, channel_axis=-1)
    assert ours < 1.0
    assert ours == pytest.approx(ref, abs=1e-6)


def test_check6_hdrflip_same_exposures_per_reference(monkeypatch):
    import flip_evaluator

    M.clear_exposure_cache()
    r = _hdr((32, 32, 3), seed=3, scale=8.0)
    t1 = r * 1.2
    t2 = np.abs(r + np.random.default_rng(4).normal(0, 0.3, r.shape))
    _, _, auto = flip_evaluator.evaluate(r.astype(np.float32), t1.astype(np.float32), "HDR",
                                         inputsRGB=True, applyMagma=False,
                                         computeMeanError=True, parameters={})
    calls = []
    real = flip_evaluator.evaluate

    def spy(ref, test, mode, **kw):
        calls.append(dict(kw["parameters"]))
        return real(ref, test, mode, **kw)

    monkeypatch.setattr(flip_evaluator, "evaluate", spy)
    v1, p1 = M.hdrflip(t1, r, return_params=True)
    v2, p2 = M.hdrflip(t2, r, return_params=True)
    v3 = M.compute("hdrflip", t2, r)
    for key in ("startExposure", "stopExposure", "numExposures"):
        assert p1[key] == p2[key] == auto[key]
    assert calls[0] == {}  # first call: FLIP chooses from the reference
    assert calls[1] == calls[2] == {"startExposure": p1["startExposure"],
                                    "stopExposure": p1["stopExposure"],
                                    "numExposures": p1["numExposures"]}
    assert 0 < v1 < 1 and 0 < v2 < 1 and v3 == v2
    assert M.hdrflip_exposures(r) == calls[1]
    # A different reference gets its own exposures.
    _, p4 = M.hdrflip(t1, r * 16.0, return_params=True)
    assert p4["startExposure"] != p1["startExposure"]


def test_hdrflip_cache_is_bounded(monkeypatch):
    M.clear_exposure_cache()
    monkeypatch.setattr(image_mod, "HDRFLIP_CACHE_SIZE", 2)
    for k in range(4):
        r = _hdr((12, 12, 3), seed=10 + k)
        M.compute("hdrflip", r, r)
    assert len(image_mod._EXPOSURES) == 2
    M.clear_exposure_cache()


def test_hdrflip_black_reference_and_negatives():
    M.clear_exposure_cache()
    for level in (0.0, 1e-30, 1e-7):
        r = np.full((8, 8, 3), level)
        v, p = M.hdrflip(np.full((8, 8, 3), 0.2), r, return_params=True)
        assert math.isfinite(v) and v > 0
        assert p["startExposure"] == p["stopExposure"] == 0.0
        assert M.compute("hdrflip", r.copy(), r) == 0.0
    r = _hdr((16, 16, 3), seed=5)
    x = r - 0.2
    assert M.compute("hdrflip", x, r) == M.compute("hdrflip", np.clip(x, 0, None), r)


# --------------------------------------------------------------------------------- hand values


def test_hand_computed_pixel_metrics():
    r = np.array([0.0, 1.0, 2.0, 4.0]).reshape(2, 2, 1)
    x = np.array([0.5, 1.0, 1.0, 4.0]).reshape(2, 2, 1)
    assert M.compute("mse", x, r) == pytest.approx((0.25 + 1.0) / 4, rel=1e-14)
    assert M.compute("rmse", x, r) == pytest.approx(math.sqrt(1.25 / 4), rel=1e-14)
    assert M.compute("relmse", x, r) == pytest.approx((0.25 / 0.01 + 1.0 / 4.01) / 4, rel=1e-14)
    assert M.compute("smape", x, r) == pytest.approx((0.5 / 0.51 + 1.0 / 3.01) / 4, rel=1e-14)
    assert M.compute("rmae", x, r) == pytest.approx((0.5 / 0.01 + 1.0 / 2.01) / 4, rel=1e-14)
    assert M.compute("relmse", x, r, eps=1e-4) == pytest.approx((0.25 / 1e-4 + 1 / 4.0001) / 4)
    # PSNR by hand on tone-mapped values: T(0.5) = 0.735357, T(0) = 0, T(>=1) = 1.
    t = M.srgb_encode(np.array([0.5]))[0]
    mse_ldr = (t ** 2 + 0 + (1.0 - 1.0) ** 2 + 0) / 4
    assert M.compute("psnr", x, r) == pytest.approx(10 * math.log10(1 / mse_ldr), rel=1e-12)


def test_tonemap():
    x = np.array([-1.0, 0.0, 0.25, 0.5, 2.0, np.nan])
    y = M.tonemap(x)
    assert y[0] == 0.0 and y[1] == 0.0 and y[4] == 1.0 and np.isnan(y[5])
    assert M.tonemap(np.array([0.25]), ev=1.0)[0] == pytest.approx(M.tonemap(np.array([0.5]))[0])
    s = np.linspace(0, 1, 101)
    assert np.allclose(M.srgb_encode(M.srgb_decode(s)), s, atol=1e-12)
    with pytest.raises(DbenchInputError):
        M.tonemap(x, ev=float("inf"))


# --------------------------------------------------------------------------------- skimage


def test_psnr_and_ssim_match_skimage():
    r = _hdr((48, 40, 3), seed=7)
    x = np.abs(r + np.random.default_rng(8).normal(0, 0.1, r.shape))
    tx, tr = M.tonemap(x), M.tonemap(r)
    assert M.compute("psnr", x, r) == pytest.approx(
        peak_signal_noise_ratio(tr, tx, data_range=1.0), abs=1e-9)
    assert M.compute("ssim", x, r) == pytest.approx(
        structural_similarity(tx, tr, gaussian_weights=True, sigma=1.5,
                              use_sample_covariance=False, data_range=1, channel_axis=-1),
        abs=1e-9)
    # With an exposure.
    assert M.compute("psnr", x, r, ev=-1.0) == pytest.approx(
        peak_signal_noise_ratio(M.tonemap(r, -1.0), M.tonemap(x, -1.0), data_range=1.0), abs=1e-9)


def test_small_image_ssim_is_the_single_window_formula():
    rng = np.random.default_rng(9)
    a, b = rng.random((3, 3, 3)), rng.random((3, 3, 3))
    # A 3x3 uniform window at the centre pixel covers the whole 3x3 image.
    ref = structural_similarity(a, b, gaussian_weights=False, win_size=3,
                                use_sample_covariance=False, data_range=1, channel_axis=-1)
    assert M.ssim_ldr(a, b) == pytest.approx(ref, abs=1e-12)
    assert M.ssim_ldr(a, a) == pytest.approx(1.0, abs=1e-12)


# --------------------------------------------------------------------------------- errors


def test_shape_errors_name_the_buffer():
    r = _hdr((4, 5, 3))
    with pytest.raises(DbenchInputError) as e:
        M.compute("rmse", r[..., :1], r)
    assert "output" in str(e.value) and "(4, 5, 3)" in str(e.value)
    with pytest.raises(DbenchInputError) as e:
        M.compute_all(r[:, :4], r)
    assert "output" in str(e.value) and "(4, 5, 3)" in str(e.value)
    with pytest.raises(DbenchInputError) as e:
        M.compute("ssim", r[..., 0], r[..., 0])
    assert "reference" in str(e.value) and "(H, W, C)" in str(e.value)
    with pytest.raises(DbenchInputError) as e:
        M.compute("rmse", r, None)
    assert "reference" in str(e.value)
    with pytest.raises(DbenchInputError) as e:
        M.compute("rmse", np.zeros((0, 5, 3)), np.zeros((0, 5, 3)))
    assert "reference" in str(e.value)
    with pytest.raises(DbenchInputError) as e:
        M.compute("flip", np.zeros((4, 5, 2)), np.zeros((4, 5, 2)))
    assert "C = 1 or 3" in str(e.value)
    assert M.compute("rmse", np.zeros((4, 5, 2)), np.zeros((4, 5, 2))) == 0.0


def test_reference_must_be_finite():
    r = _hdr((4, 5, 3))
    bad = r.copy()
    bad[1, 1, 1] = np.inf
    for name in ALL:
        with pytest.raises(DbenchInputError) as e:
            M.compute(name, r, bad)
        assert "reference" in str(e.value)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_nonfinite_output_gives_nan(bad):
    r = _hdr((12, 12, 3))
    x = r.copy()
    x[3, 4, 2] = bad
    for name in ALL:
        assert math.isnan(M.compute(name, x, r)), name
    assert all(math.isnan(v) for v in M.compute_all(x, r).values())
    assert math.isnan(M.rmse(x, r)) and math.isnan(M.hdrflip(x, r))


# --------------------------------------------------------------------------------- transient


def test_transient_shapes():
    ref = _hdr((12, 13, 5, 3), seed=11, scale=0.3)
    out = np.abs(ref + np.random.default_rng(12).normal(0, 0.05, ref.shape))
    vals = M.compute_all(out, ref)
    flat_o, flat_r = out.reshape(12, 13 * 5, 3), ref.reshape(12, 13 * 5, 3)
    for n in ("mse", "rmse", "relmse", "smape", "rmae"):
        assert vals[n] == pytest.approx(M.compute(n, flat_o, flat_r), rel=1e-12)
    so, sr = out.sum(axis=2), ref.sum(axis=2)
    for n in ("psnr", "ssim", "flip", "hdrflip"):
        assert vals[n] == pytest.approx(M.compute(n, so, sr), rel=1e-12), n

    for n in M.PER_BIN_METRICS:
        curve = M.per_bin(n, out, ref)
        assert curve.shape == (5,)
        expect = [M.compute(n, out[:, :, t], ref[:, :, t]) for t in range(5)]
        assert np.allclose(curve, expect, rtol=1e-12)
    assert M.per_bin("mse", out, ref).mean() == pytest.approx(vals["mse"], rel=1e-12)

    bad = out.copy()
    bad[0, 0, 2, 0] = np.nan
    curve = M.per_bin("rmse", bad, ref)
    assert np.isnan(curve[2]) and np.all(np.isfinite(np.delete(curve, 2)))
    assert math.isnan(M.compute("rmse", bad, ref))

    with pytest.raises(DbenchInputError):
        M.per_bin("rmse", so, sr)
    with pytest.raises(UnknownNameError) as e:
        M.per_bin("ssim", out, ref)
    assert "rmse" in str(e.value)


# --------------------------------------------------------------------------------- robustness


@pytest.mark.parametrize("shape", [(1, 1, 3), (1, 5, 3), (5, 1, 3), (3, 3, 3), (3, 3, 1),
                                   (1, 1, 1), (2, 3, 2, 3)])
def test_tiny_images_give_finite_results(shape):
    r = _hdr(shape, seed=13)
    x = _hdr(shape, seed=14)
    vals = M.compute_all(x, r)
    assert set(vals) == set(M.available())
    assert all(math.isfinite(v) for v in vals.values()), vals
    same = M.compute_all(r.copy(), r)
    assert same["ssim"] == pytest.approx(1.0, abs=1e-12)
    assert same["flip"] == 0.0 and same["psnr"] == 100.0


def test_dtypes_and_single_channel():
    r = _hdr((16, 16, 3), seed=15)
    x = _hdr((16, 16, 3), seed=16)
    v64 = M.compute_all(x, r)
    v32 = M.compute_all(x.astype(np.float32), r.astype(np.float32))
    for n in M.available():
        assert v32[n] == pytest.approx(v64[n], rel=1e-4, abs=1e-6), n
    g_r, g_x = r[..., :1], x[..., :1]
    assert M.compute("flip", g_x, g_r) == pytest.approx(
        M.compute("flip", np.repeat(g_x, 3, -1), np.repeat(g_r, 3, -1)), abs=1e-7)
    assert M.compute("hdrflip", g_x, g_r) == pytest.approx(
        M.compute("hdrflip", np.repeat(g_x, 3, -1), np.repeat(g_r, 3, -1)), abs=1e-7)


def test_compute_all_matches_compute():
    r = _hdr((20, 22, 3), seed=17)
    x = np.abs(r + np.random.default_rng(18).normal(0, 0.05, r.shape))
    vals = M.compute_all(x, r, names=["ssim", "rmse", "flip", "psnr"], ev=0.5)
    assert list(vals) == ["ssim", "rmse", "flip", "psnr"]
    for n, v in vals.items():
        opts = {"ev": 0.5} if n != "rmse" else {}
        assert v == M.compute(n, x, r, **opts)
    # Better outputs score better.
    worse = np.abs(r + np.random.default_rng(19).normal(0, 0.2, r.shape))
    good, bad = M.compute_all(x, r), M.compute_all(worse, r)
    for n in M.available():
        if n in M.HIGHER_IS_BETTER:
            assert good[n] > bad[n], n
        else:
            assert good[n] < bad[n], n
