"""Tests of the spatio-temporal statistical denoiser (docs/methods/statistical.md §11.3, §13 checks 14-16).

Synthetic (H, W, T, 3) videos with statistics built from NumPy samples as the renderer's
accumulation would (mean, var_mean = var(ddof=1)/n, m3 = mean((y − μ)³)), with zero-variance
voxels, bins no path reaches, background pixels, missing colour and bad statistics.
Fast-path tolerance: max relative difference 1e-5 against the float64 reference (the Welch
decisions are bit-identical: both evaluate the same float64 predicate).
"""
from __future__ import annotations

import numpy as np
import pytest

from dbench.data import Frame, SampleStats, TransientFrame
from dbench.datasets.stats import PowerSums, transform_of_zero
from dbench.errors import DbenchInputError
from dbench.methods.kernels import bilateral as jc
from dbench.methods.statistical import transient as st
from dbench.registry import get

FAST_RTOL = 1e-5


def rel_err(a, b):
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return float(np.max(np.abs(a - b) / np.maximum(np.abs(b), 1e-3)))


def stats_from_samples(y, transform="identity"):
    """SampleStats of samples y with shape (H, W, T, 3, n)."""
    n = y.shape[-1]
    mu = y.mean(-1)
    return SampleStats(n=np.full(mu.shape, float(n)), mean=mu, var_mean=y.var(-1, ddof=1) / n,
                       m3=((y - mu[..., None]) ** 3).mean(-1), transform=transform)


def synthetic_video(h=12, w=12, t=10, n=16, seed=0, empty=(0, 6), nonuniform=False):
    """Sparse 'path' samples: most samples reach a voxel with probability 0.5; 15 % of the
    voxels are deterministic (zero variance), the ``empty`` bins are reached by no path."""
    rng = np.random.default_rng(seed)
    level = np.where(rng.random((h, w, 1, 1)) < 0.5, 1.0, 1.6) * np.array([1.0, 0.8, 1.2])
    level = level * (1.0 + 0.5 * np.sin(np.arange(t) / 2.0))[None, None, :, None]
    y = rng.gamma(3.0, level[..., None] / 3.0, size=(h, w, t, 3, n))
    y *= rng.random((h, w, t, 1, n)) < 0.5
    const = rng.random((h, w, t)) < 0.15
    y[const] = np.round(level[const], 1)[..., None]
    y[:, :, list(empty)] = 0.0
    stats = stats_from_samples(y)
    if nonuniform:
        stats = SampleStats(n=rng.integers(2, 40, size=(h, w, t, 1)).repeat(3, -1).astype(float),
                            mean=stats.mean, var_mean=stats.var_mean, m3=stats.m3,
                            transform="identity")
    albedo = np.where(rng.random((h, w, 1)) < 0.6, 0.5, rng.random((h, w, 3)))
    normal = np.zeros((h, w, 3))
    normal[..., 2] = 1.0
    normal[: h // 3] = [0.0, 0.6, 0.8]
    depth = np.where(rng.random((h, w, 1)) < 0.15, 0.0, 1.0)
    return y.mean(-1), stats, albedo, normal, depth


def run(case, backend, **kw):
    color, stats, albedo, normal, depth = case
    return st.statistical_filter_video(color, stats, albedo, normal, depth, backend=backend, **kw)


# ------------------------------------------------------------------ fast path == reference

@pytest.mark.parametrize("base", ["jbf", "gauss3d"])
@pytest.mark.parametrize("shape,radius,radius_t", [
    ((12, 12, 10), 3, 1), ((12, 12, 10), 0, 2), ((12, 12, 10), 5, 1), ((1, 9, 7), 2, 1),
    ((9, 1, 7), 2, 3), ((7, 8, 1), 3, 1), ((11, 10, 4), 1, 0)])
def test_fast_equals_reference(base, shape, radius, radius_t):
    case = synthetic_video(*shape, seed=radius * 7 + shape[1] + radius_t,
                           empty=(0,) if shape[2] > 1 else ())
    kw = dict(base=base, radius=radius, radius_t=radius_t)
    ref = run(case, "reference", **kw)
    fast = run(case, "numba", **kw)
    assert fast.dtype == np.float32 and fast.shape == case[0].shape
    assert np.all(np.isfinite(fast))
    assert rel_err(fast, ref) < FAST_RTOL


@pytest.mark.parametrize("options", [
    dict(nonuniform=True, alpha=0.005), dict(alpha=0.2), dict(gamma=0.01),
    dict(temporal_profile="gaussian", sigma_t=0.7), dict(sigma_convention="sd", window="disk"),
    dict(hit_mask=False), dict(membership_on=False), dict(skip_empty=False),
    dict(base="gauss3d", temporal_profile="box"), dict(base="gauss3d", sigma_t=2.5)])
def test_fast_equals_reference_options(options):
    nonuniform = options.pop("nonuniform", False)
    case = synthetic_video(11, 13, 9, seed=3, nonuniform=nonuniform, empty=(0, 4, 5))
    ref = run(case, "reference", radius=3, radius_t=2, **options)
    fast = run(case, "numba", radius=3, radius_t=2, **options)
    assert rel_err(fast, ref) < FAST_RTOL


def test_nonfinite_colour_and_bad_statistics():
    color, stats, albedo, normal, depth = synthetic_video(10, 11, 8, seed=4)
    color = color.copy()
    color[3, 4, 2, 1] = np.nan                           # missing colour voxel
    color[6, 6, 5] = np.inf
    mean = stats.mean.copy()
    mean[2, 2, 3, 0] = np.nan                            # bad statistics voxel
    var = stats.var_mean.copy()
    var[7, 1, 4, 2] = np.inf
    bad_stats = SampleStats(n=stats.n, mean=mean, var_mean=var, m3=stats.m3,
                            transform="identity")
    case = (color, bad_stats, albedo, normal, depth)
    for membership_on in (True, False):
        ref = run(case, "reference", radius=2, membership_on=membership_on)
        fast = run(case, "numba", radius=2, membership_on=membership_on)
        assert np.all(np.isfinite(fast)) and rel_err(fast, ref) < FAST_RTOL
        # a voxel with bad statistics is nobody's neighbour: its output is its own colour
        np.testing.assert_allclose(fast[2, 2, 3], color[2, 2, 3], rtol=1e-6)
        np.testing.assert_allclose(fast[7, 1, 4], color[7, 1, 4], rtol=1e-6)
    _, info = run(case, "numba", radius=2, return_info=True)
    assert info["n_bad_stats"] == 2


@pytest.mark.parametrize("shrink", [True, False])
@pytest.mark.parametrize("membership_on", [True, False])
def test_bright_block_is_finite_and_equals_reference(shrink, membership_on):
    """A block of colours near the float32 maximum (statistics unchanged, so it passes the test
    against its neighbours): float32 sums of several 3e38 terms would overflow to Inf; the
    planes are scaled by a power of two for the kernel and the sums multiplied back."""
    color, stats, albedo, normal, depth = synthetic_video(10, 11, 8, seed=6)
    color = color.copy()
    color[2:6, 2:6, 2:5] = 3e38
    case = (color, stats, albedo, normal, depth)
    kw = dict(radius=2, radius_t=1, shrink=shrink, membership_on=membership_on)
    ref = run(case, "reference", **kw)
    fast = run(case, "numba", **kw)
    assert np.all(np.isfinite(ref)) and np.all(np.isfinite(fast))
    assert np.max(fast) > 1e38
    assert rel_err(fast, ref) < FAST_RTOL


def test_ordinary_planes_are_not_scaled():
    """Planes up to PLANE_MAX enter the kernel unchanged (same array, no factors), so every
    ordinary output is bit for bit what it was without the scaling."""
    from dbench.methods.kernels.bilateral.numba2d import _scaled_planes

    planes = np.random.default_rng(1).random((3, 4, 5, 6)).astype(np.float32)
    planes[1, 2, 3, 4] = np.nextafter(np.float32(jc.PLANE_MAX), np.float32(0))  # unscaled
    planes[0, 1, 0, 0] = np.inf                           # non-finite values do not count
    for axis in (0, 1):
        same, scale = _scaled_planes(planes, axis=axis)
        assert scale is None and same is planes
    planes[2, 1, 1, 1] = 3e38
    scaled, scale = _scaled_planes(planes, axis=1)
    assert scale.tolist() == [1.0, 2.0 ** 29, 1.0, 1.0]   # only the bright plane
    np.testing.assert_array_equal(scaled * scale[:, None, None].astype(np.float32), planes)


def test_huge_planes_are_summed_scaled_exactly():
    """Sums of a plane above PLANE_MAX are the kernel's sums of the plane divided by 2^k, times
    2^k, bit for bit, in all three outputs (plain sums, normalised video, band accumulators)."""
    rng = np.random.default_rng(5)
    h, w, k = 9, 8, 3
    guide = jc.make_guide(rng.random((h, w, 3)), rng.normal(size=(h, w, 3)),
                          rng.random((h, w, 1)), radius=2)
    small = rng.random((k, 4, h, w)).astype(np.float32)
    small[:, 3] = 1.0
    small[:, 0] *= np.float32(jc.PLANE_MAX)               # peak in (PLANE_MAX / 2, PLANE_MAX]
    big = small.copy()
    big[:, 0] *= np.float32(2.0 ** 20)                    # above: scaled back by 2^20
    tfac, bins = np.ones(3), np.arange(k)
    s_small = jc.accumulate3d(guide, small, tfac, bins)
    s_big = jc.accumulate3d(guide, big, tfac, bins)
    np.testing.assert_array_equal(s_big[:, 0], s_small[:, 0] * 2.0 ** 20)
    np.testing.assert_array_equal(s_big[:, 1:], s_small[:, 1:])
    v_small, v_big = (np.zeros((h, w, k, 3), np.float32) for _ in range(2))
    jc.accumulate3d(guide, small, tfac, bins, normalise_into=v_small)
    jc.accumulate3d(guide, big, tfac, bins, normalise_into=v_big)
    assert np.all(np.isfinite(v_big))
    np.testing.assert_array_equal(v_big[..., 0], (v_small[..., 0].astype(np.float64)
                                                  * 2.0 ** 20).astype(np.float32))
    acc_small, rows, f_small = jc.accumulate3d(guide, small, tfac, bins, bands=True)
    acc_big, rows_big, f_big = jc.accumulate3d(guide, big, tfac, bins, bands=True)
    assert rows == rows_big and f_small.tolist() == [1.0] * 4
    assert f_big.tolist() == [2.0 ** 20, 1.0, 1.0, 1.0]
    np.testing.assert_array_equal(acc_big, acc_small)


# ------------------------------------------------------------------ spec §13 checks 14-16

@pytest.mark.parametrize("transform,lam", [("identity", 0.5), ("yeo-johnson", 0.5),
                                           ("box-cox", 0.5)])
def test_check14_unreached_bin(transform, lam):
    """A bin reached by no path: θ̂ = g(0), Var 0 (Box-Cox 0.5: −2); it is empty, skipped and
    returns 0, and it does not change the other bins' output beyond being a neighbour."""
    rng = np.random.default_rng(5)
    h, w, t, n = 6, 7, 5, 32
    ps = PowerSums((h, w, t, 3), transform, lam)
    plain = np.zeros((h, w, t, 3))
    for _ in range(n):                                   # one 1-spp pass per sample
        x = rng.gamma(2.0, 0.5, size=(h, w, t, 3)) * (rng.random((h, w, t, 1)) < 0.6)
        x[:, :, 2] = 0.0                                 # bin 2: no path ever reaches it
        ps.add(x)
        plain += x
    stats = ps.finalize()
    g0 = transform_of_zero(transform, lam)
    np.testing.assert_array_equal(stats.theta[:, :, 2], g0)
    np.testing.assert_array_equal(stats.var_mean[:, :, 2], 0.0)
    if transform == "box-cox":
        assert g0 == -2.0
    color = (plain / n).astype(np.float32)
    alb, nrm = np.full((h, w, 3), 0.5), np.tile([0.0, 0.0, 1.0], (h, w, 1))
    out, info = st.statistical_filter_video(color, stats, alb, nrm, radius=2, return_info=True)
    assert info["nonempty_bins"] == 4 and info["bins_in_play"] == 5
    np.testing.assert_array_equal(out[:, :, 2], 0.0)
    ref = st.statistical_filter_video(color, stats, alb, nrm, radius=2, backend="reference")
    assert rel_err(out, ref) < FAST_RTOL


def test_check15_window_size_363():
    assert st.window_size(5, 1) == 363
    assert st.window_size(20, 1) == 5043
    assert st.window_size(0, 1) == 3
    # count the voxels that actually carry weight for an interior voxel of a constant video
    h, w, t = 13, 13, 5
    y = np.full((h, w, t, 3, 4), 0.7)
    stats = stats_from_samples(y)
    guide = st.make_video_guide("gauss3d", (h, w), radius=5)
    vs = st.video_stats(stats, (h, w, t), channel_first=False)
    thr = st.resolve_threshold(vs.nint, None, 0.05)
    out, weights, members = st.statistical_video_reference(
        y.mean(-1), vs, guide, jc.temporal_factors(1), thr, return_weights=True)
    assert weights.shape[0] == 363
    assert int(np.count_nonzero(weights[:, 6, 6, 2])) == 363
    np.testing.assert_allclose(weights[:, 6, 6, 2].sum(), 1.0, atol=1e-12)
    np.testing.assert_allclose(out, 0.7, atol=1e-12)


@pytest.mark.parametrize("backend", ["reference", "numba"])
@pytest.mark.parametrize("base", ["jbf", "gauss3d"])
def test_check15_identical_copies_return_the_image(backend, base):
    rng = np.random.default_rng(6)
    h, w, t, n = 9, 10, 6, 16
    img = rng.gamma(2.0, 0.5, size=(h, w, 3, n))
    y = np.repeat(img[:, :, None], t, axis=2)              # T identical copies
    stats = stats_from_samples(y)
    color = y.mean(-1).astype(np.float32)
    alb, nrm, _ = rng.random((h, w, 3)), rng.normal(size=(h, w, 3)), None
    out = st.statistical_filter_video(color, stats, alb, nrm, radius=0, radius_t=1, base=base,
                                      backend=backend)
    for k in range(t):
        np.testing.assert_allclose(out[:, :, k], color[:, :, 0], rtol=1e-12, atol=0)


def moving_edge_video(h=16, w=16, t=12, n=64, seed=7):
    """A bright front moving one pixel per bin over a dim background (a transient wavefront),
    flat G-buffers: only the test can keep the front sharp."""
    rng = np.random.default_rng(seed)
    xx = np.arange(w)[None, :, None]
    tt = np.arange(t)[None, None, :]
    truth = np.where(np.abs(xx - tt - 2) <= 1, 1.0, 0.05).repeat(h, 0)[..., None] * np.ones(3)
    y = rng.exponential(1.0, size=truth.shape + (n,)) * truth[..., None]
    alb, nrm = np.full((h, w, 3), 0.5), np.tile([0.0, 0.0, 1.0], (h, w, 1))
    return truth, y.mean(-1), stats_from_samples(y), alb, nrm


def test_statistical_beats_noisy_and_plain_3d_filter():
    """spec §13 check 16 in miniature (the rendered version is in results/transient_statistical.md)."""
    truth, color, stats, alb, nrm = moving_edge_video()
    rmse = lambda a: float(np.sqrt(np.mean((np.asarray(a, np.float64) - truth) ** 2)))  # noqa: E731
    den = st.statistical_filter_video(color, stats, alb, nrm, radius=5, radius_t=1)
    plain = st.statistical_filter_video(color, stats, alb, nrm, radius=5, radius_t=1,
                                        membership_on=False)
    assert rmse(den) < 0.7 * rmse(color)
    assert rmse(den) < 0.7 * rmse(plain)


# ------------------------------------------------------------------ empty bins cost nothing

def test_skipping_empty_bins_keeps_the_other_bins_exact():
    case = synthetic_video(10, 9, 12, seed=8, empty=(0, 1, 2, 3, 7, 11))
    full, info_full = run(case, "numba", radius=3, skip_empty=False, return_info=True)
    skip, info = run(case, "numba", radius=3, return_info=True)
    keep = st.nonempty_bins(case[0])
    assert list(np.flatnonzero(~keep)) == [0, 1, 2, 3, 7, 11]
    assert info["bins_in_play"] == 9 and info_full["bins_in_play"] == 12
    np.testing.assert_allclose(skip[:, :, keep], full[:, :, keep], rtol=1e-6, atol=0)
    np.testing.assert_array_equal(skip[:, :, ~keep], 0.0)
    # the full filter leaks energy into the empty bins next to non-empty ones
    assert np.abs(full[:, :, [3, 7, 11]]).max() > 0
    ref = run(case, "reference", radius=3)
    assert rel_err(skip, ref) < FAST_RTOL


def test_bins_in_play():
    keep = np.zeros(10, bool)
    keep[[3, 4, 9]] = True
    np.testing.assert_array_equal(np.flatnonzero(st.bins_in_play(keep, 1)), [2, 3, 4, 5, 8, 9])
    np.testing.assert_array_equal(np.flatnonzero(st.bins_in_play(keep, 0)), [3, 4, 9])
    assert not st.bins_in_play(np.zeros(5, bool), 2).any()
    video = np.zeros((3, 3, 6, 3), np.float32)
    out = st.statistical_filter_video(video, stats_from_samples(np.zeros((3, 3, 6, 3, 2))),
                                      base="gauss3d")
    assert out.shape == video.shape and not out.any()


def test_accumulate3d_equals_2d_kernel_per_bin():
    """With r_t = 0 the 3D kernel is the 2D JBF kernel on every bin (shared code paths)."""
    rng = np.random.default_rng(9)
    h, w, k = 13, 11, 4
    alb, nrm, depth = rng.random((h, w, 3)), rng.normal(size=(h, w, 3)), rng.random((h, w, 1))
    guide = jc.make_guide(alb, nrm, depth, radius=3)
    planes = rng.random((k, 4, h, w)).astype(np.float32)
    sums = jc.accumulate3d(guide, planes, np.ones(1), np.arange(k))
    for i in range(k):
        np.testing.assert_allclose(sums[i], jc.accumulate(guide, planes[i]), rtol=1e-6)


# ------------------------------------------------------------------ registered method

def transient_frame(meta=None, with_gbuffers=True, seed=10):
    color, stats, albedo, normal, depth = synthetic_video(10, 12, 7, seed=seed, empty=(0,))
    kw = dict(albedo=albedo.astype(np.float32), normal=normal.astype(np.float32),
              depth=depth.astype(np.float32)) if with_gbuffers else {}
    return TransientFrame(color=color.astype(np.float32), stats=stats, meta=meta or {}, **kw)


@pytest.mark.parametrize("width,expected", [(0.0385, 0), (0.02, 1), (0.0077, 2), (0.0025, 3),
                                            (None, 1)])
def test_auto_radius_t_follows_the_bin_width(width, expected):
    assert st.auto_radius_t(width) == expected
    frame = transient_frame(meta=None if width is None else {"bin_width_opl": width,
                                                             "units": "m (optical path length)"})
    m = get("statistical", radius=1)
    m.denoise(frame)
    assert m.last_settings["radius_t"] == expected
    assert m.last_settings["radius_t_source"] == "auto"
    m = get("statistical", radius=1, radius_t=2)
    m.denoise(frame)
    assert m.last_settings["radius_t"] == 2 and m.last_settings["radius_t_source"] == "given"


def test_auto_radius_t_ignores_widths_that_are_not_metres():
    assert st.auto_radius_t(float("nan")) == 1 and st.auto_radius_t(0.0) == 1
    m = get("statistical", radius=1)
    m.denoise(transient_frame(meta={"bin_width_opl": 0.001, "units": "bins"}))
    assert m.last_settings["radius_t"] == 1 and m.last_settings["bin_width_m"] is None


@pytest.mark.parametrize("bad", ["automatic", -1, 1.5, True])
def test_bad_radius_t_is_refused_with_the_choices(bad):
    with pytest.raises(DbenchInputError, match="radius_t: expected 'auto' or an integer"):
        get("statistical", radius_t=bad)


def test_registered_method_on_transient_frame():
    m = get("statistical", backend="numba")
    assert {"steady", "transient"} <= m.kinds
    assert m.applies_to("transient", {"color", "albedo", "normal", "depth", "stats"})[0]
    frame = transient_frame()
    out = m.denoise(frame)
    assert out.dtype == np.float32 and out.shape == frame.color.shape
    s = m.last_settings
    # no bin width in the frame's meta: the automatic r_t falls back to the spec's 1
    assert s["radius"] == 5 and s["radius_t"] == 1 and s["window_voxels"] == 363
    assert s["radius_t_source"] == "auto"
    assert s["gamma"] == 0.1 and s["gamma_t"] == 2.0 and s["threshold_source"] == "gamma"
    assert s["base"] == "jbf" and s["temporal_profile"] == "box" and s["transform"] == "identity"
    assert s["nonempty_bins"] == 6 and s["kind"] == "transient"
    ref = get("statistical", backend="reference").denoise(frame)
    assert rel_err(out, ref) < FAST_RTOL
    # alpha alone switches to the Student-t threshold, ν = 2n − 2 = 30
    m2 = get("statistical", alpha=0.005, radius=2, radius_t=2)
    m2.denoise(frame)
    assert m2.last_settings["nu"] == 30 and m2.last_settings["threshold_source"] == "alpha"
    assert m2.last_settings["radius"] == 2 and m2.last_settings["window_voxels"] == 125


def test_base_filter_choice():
    m = get("statistical", radius=2)
    # media with G-buffers of the surfaces behind them use the JBF (measured better)
    m.denoise(transient_frame(meta={"medium": {"type": "homogeneous"}}))
    assert m.last_settings["base"] == "jbf"
    m.denoise(transient_frame(meta={"integrator": "transient_prbvolpath"}))
    assert m.last_settings["base"] == "jbf"
    m.denoise(transient_frame(with_gbuffers=False))
    assert m.last_settings["temporal_profile"] == "gaussian"
    assert m.last_settings["base"] == "gauss3d" and m.last_settings["features"] == ("xy",)
    m.denoise(transient_frame(meta={"medium": None, "integrator": "transient_path"}))
    assert m.last_settings["base"] == "jbf"
    with pytest.raises(DbenchInputError, match="albedo"):
        get("statistical", base="jbf").denoise(transient_frame(with_gbuffers=False))


def test_steady_defaults_unchanged():
    rng = np.random.default_rng(11)
    h, w, n = 12, 13, 16
    y = rng.gamma(4.0, 0.25, size=(h, w, 3, n))
    frame = Frame(color=y.mean(-1).astype(np.float32), albedo=np.full((h, w, 3), 0.5, np.float32),
                  normal=np.tile(np.float32([0, 0, 1]), (h, w, 1)),
                  depth=np.ones((h, w, 1), np.float32), stats=stats_from_samples(y))
    m = get("statistical", backend="numba")
    m.denoise(frame)
    s = m.last_settings
    assert s["radius"] == 20 and s["alpha"] == 0.005 and s["nu"] == 30
    assert s["threshold_source"] == "alpha"


@pytest.mark.parametrize("params,name", [
    (dict(radius_t=-1), "radius_t"), (dict(radius_t=1.5), "radius_t"), (dict(base="x"), "base"),
    (dict(temporal_profile="tri"), "temporal_profile"), (dict(sigma_t=0.0), "sigma_t"),
    (dict(skip_empty="yes"), "skip_empty"), (dict(radius=-1), "radius"),
    (dict(gamma=0.9), "gamma")])
def test_bad_parameters_name_the_parameter(params, name):
    with pytest.raises(DbenchInputError, match=name):
        get("statistical", **params)


def test_steady_only_options_refused_on_video():
    frame = transient_frame()
    with pytest.raises(DbenchInputError, match="steady"):
        get("statistical+gate").denoise(frame)
    with pytest.raises(DbenchInputError, match="backend"):
        get("statistical", backend="torch").denoise(frame)
    bad = TransientFrame(color=frame.color, albedo=frame.albedo, normal=frame.normal)
    with pytest.raises(DbenchInputError, match="stats"):
        get("statistical").denoise(bad)
