"""Transient datasets: TransientFrame, scenes, windows, energy, direct arrival, and the two
collectors of per-bin statistics (docs/transient.md §7, docs/methods/statistical.md §11, §13.14)."""
from __future__ import annotations

import json

import numpy as np
import pytest

from dbench.data import SampleStats, TransientFrame
from dbench.errors import DbenchInputError

SPP = 8


# ---------------------------------------------------------------------------------------------
# TransientFrame (no rendering)


def test_transient_frame_shapes_and_time_axis():
    v = TransientFrame(color=np.zeros((4, 5, 6, 3)), albedo=np.ones((4, 5, 3)),
                       normal=np.ones((4, 5, 3)), depth=np.ones((4, 5)),
                       reference=np.zeros((4, 5, 6, 3)),
                       meta={"start_opl": 3.5, "bin_width_opl": 0.5})
    assert v.kind == "transient" and v.shape == (4, 5) and v.bins == 6
    assert v.color.dtype == np.float32 and v.depth.shape == (4, 5, 1)
    assert v.end_opl == pytest.approx(6.5)
    np.testing.assert_allclose(v.time_axis, 3.5 + 0.5 * (np.arange(6) + 0.5))
    assert v.has("albedo") and not v.has("stats")


@pytest.mark.parametrize("kwargs, name", [
    (dict(color=np.zeros((4, 5, 3))), "color"),
    (dict(color=np.zeros((4, 5, 6, 3)), albedo=np.zeros((4, 4, 3))), "albedo"),
    (dict(color=np.zeros((4, 5, 6, 3)), reference=np.zeros((4, 5, 5, 3))), "reference"),
    (dict(color=np.zeros((4, 5, 6, 3)), non_zero=np.zeros((4, 5, 6))), "non_zero"),
    (dict(color=np.zeros((4, 5, 6, 3)), meta={"bins": 7}), "meta.bins"),
    (dict(color=np.zeros((4, 5, 6, 3)), meta={"bin_width_opl": 0.0}), "meta.bin_width_opl"),
    (dict(color=np.zeros((4, 5, 6, 3)),
          stats=SampleStats(n=4, mean=np.zeros((4, 5, 3)), var_mean=np.zeros((4, 5, 3)),
                            m3=np.zeros((4, 5, 3)))), "stats"),
])
def test_transient_frame_validation_names_the_buffer(kwargs, name):
    with pytest.raises(DbenchInputError, match=name.replace(".", r"\.")):
        TransientFrame(**kwargs)


# ---------------------------------------------------------------------------------------------
# rendering fixtures


def _corridor(mi, res):
    """A narrow corridor lit by its far end: along the corridor OPL + distance to the light is
    nearly constant, so next-event estimates of later vertices fall back into earlier bins."""
    from dbench.datasets.scenes.catalogue import camera_dict, diffuse_bsdf, rect_shape
    T = mi.ScalarTransform4f
    white = diffuse_bsdf((0.8, 0.8, 0.8))
    length, hw = 4.0, 0.4
    d = {"type": "scene",
         "sensor": camera_dict(mi, res, origin=[0, 0, 0.3], target=[0, 0, -length], fov=50)}
    half = [hw, length / 2, 1]
    d["floor"] = rect_shape(mi, T().translate([0, -hw, -length / 2]).rotate([1, 0, 0], -90)
                       .scale(half), white)
    d["ceiling"] = rect_shape(mi, T().translate([0, hw, -length / 2]).rotate([1, 0, 0], 90)
                         .scale(half), white)
    d["left"] = rect_shape(mi, T().translate([-hw, 0, -length / 2]).rotate([0, 1, 0], 90)
                      .scale([length / 2, hw, 1]), white)
    d["right"] = rect_shape(mi, T().translate([hw, 0, -length / 2]).rotate([0, 1, 0], -90)
                       .scale([length / 2, hw, 1]), white)
    d["light"] = rect_shape(mi, T().translate([0, 0, -length]).scale(hw), diffuse_bsdf((0, 0, 0)),
                       {"type": "area", "radiance": {"type": "rgb", "value": [5.0, 4.0, 3.0]}})
    return d


@pytest.fixture(scope="module")
def corridor(tr):
    return tr.TransientScene(name="test-corridor", kind="transient", description="test",
                             build=_corridor, max_depth=8, window_start=3.5, window_end=9.5,
                             default_bins=20)


# ---------------------------------------------------------------------------------------------
# catalogue, loader, cache


def test_transient_scenes_are_listed(tr):
    from dbench import datasets
    names = datasets.available_scenes()
    for name in ("cornell-transient", "caustic-transient", "fog-transient"):
        assert name in names
        sc = datasets.get_scene(name)
        assert sc.kind == "transient" and {"color", "stats", "reference"} <= set(sc.provides)
        w = sc.window()
        assert w.start_opl > 0 and w.end_opl > w.start_opl and w.bins >= 20
    assert datasets.get_scene("fog-transient").integrator == "transient_prbvolpath"


def test_load_returns_transient_frame_and_caches(tr, tmp_cache):
    from dbench import datasets
    kw = dict(spp=4, res=8, bins=24, ref_spp=64, cache=tmp_cache, progress=False)
    v = datasets.load("cornell-transient", **kw)
    assert isinstance(v, TransientFrame)
    assert v.color.shape == (8, 8, 24, 3) and v.reference.shape == (8, 8, 24, 3)
    assert v.stats.shape == (8, 8, 24, 3) and v.non_zero.shape == (8, 8, 24, 3)
    assert v.albedo.shape == (8, 8, 3) and v.normal.shape == (8, 8, 3)
    assert v.depth.shape == (8, 8, 1) and v.steady.shape == (8, 8, 3)
    m = v.meta
    assert m["bins"] == 24 and m["start_opl"] == pytest.approx(3.8)
    assert m["bin_width_opl"] == pytest.approx((11.5 - 3.8) / 24)
    assert m["collector"] == "b" and m["stats_diagnostics"]["n_overflow"] == 0
    assert 0.9 < m["energy_fraction"] <= 1.0 + 1e-6
    assert 0.9 < m["reference_energy_fraction"] <= 1.0 + 1e-6
    assert np.all(v.non_zero >= 0) and np.all(v.non_zero <= 4)
    # identity statistics: the mean of the samples is the color
    np.testing.assert_allclose(v.stats.mean, v.color, rtol=1e-6, atol=1e-7)
    again = datasets.load("cornell-transient", **kw)
    assert {"color", "stats", "features", "reference"} <= set(again.meta["cache_hits"])
    assert not again.meta["rendered"]
    np.testing.assert_array_equal(again.color, v.color)
    np.testing.assert_array_equal(again.stats.var_mean, v.stats.var_mean)
    np.testing.assert_array_equal(again.non_zero, v.non_zero)
    # the counts are stored in one byte (sparse_rows.narrowest), read back in their own type
    (stored,) = tmp_cache.root.glob("transient-stats/*/arrays")
    assert np.load(stored / "rows~non_zero.npy").dtype == np.uint8
    assert str(np.load(stored / "rows~dtype~non_zero.npy")) == "<i4"
    np.testing.assert_array_equal(again.stats.m3, v.stats.m3)
    np.testing.assert_array_equal(again.reference_var, v.reference_var)
    # the videos are stored by their non-empty (pixel, bin) rows (datasets/sparse_rows.py)
    # (uncompressed, as files of arrays/)
    from dbench.datasets.cache import CHECKSUM_FORMAT
    for kind in ("transient-noisy", "transient-stats", "transient-reference"):
        formats = [json.loads(p.read_text())["cache_format"]
                   for p in tmp_cache.root.glob(f"{kind}/*/meta.json")]
        assert formats and set(formats) == {CHECKSUM_FORMAT}, kind
        assert list(tmp_cache.root.glob(f"{kind}/*/arrays/rows~mask.npy")), kind


def test_load_errors(tr, tmp_cache):
    from dbench import datasets
    with pytest.raises(DbenchInputError, match="collector"):
        datasets.load("fog-transient", spp=2, res=8, bins=20, collector="c", cache=tmp_cache)
    with pytest.raises(DbenchInputError, match="bins"):
        datasets.load("cornell-transient", spp=2, res=8, bins=0, cache=tmp_cache)
    with pytest.raises(DbenchInputError, match="needs"):
        datasets.load("cornell-transient", spp=2, res=8, needs={"motion"}, cache=tmp_cache)


# ---------------------------------------------------------------------------------------------
# docs/transient.md §7: energy and direct arrival


def test_energy_sum_over_bins_equals_steady_with_a_covering_window(tr):
    """Check 1: Σ_t transient = steady per pixel (1e-5 rel) when the window covers all."""
    from dbench.datasets.scenes import catalogue as scenes
    base = scenes.get("cornell-transient")
    wide = tr.TransientScene(name="cornell-wide", kind="transient", description="",
                             build=base.build, max_depth=8, window_start=0.0,
                             window_end=40.0, default_bins=2000)
    out = tr.collect_passes(wide, 12, SPP, seed=3, stats=None)
    total = out.color.astype(np.float64).sum(axis=2)
    steady = out.steady.astype(np.float64)
    assert steady.max() > 0
    np.testing.assert_allclose(total, steady, rtol=1e-5, atol=1e-5 * steady.max())
    assert out.energy_fraction == pytest.approx(1.0, abs=1e-5)
    # the catalogue window truncates the tail: reported, below 1 but holding ≥ 98 %
    cat = tr.collect_passes(base, 12, SPP, seed=3, bins=40, stats=None)
    assert 0.98 < cat.energy_fraction < 1.0


@pytest.mark.parametrize("unwarp, centre, corner", [(False, {125}, {130, 131}),
                                                    (True, {25}, {28})])
def test_direct_arrival_bin(tr, unwarp, centre, corner):
    """Check 2-3: camera and point light at the origin, plane at z = 2, start 1.49, width 0.02:
    the centre pixel in bin 125 (warped, OPL 4.0) / 25 (unwarped, OPL 2.0), the corner in
    130-131 / 28, every pixel within its footprint's bin range, bins summing to steady."""
    mi = tr.mitsuba()
    window = tr.Window(1.49, 0.02, 200)
    scene = mi.load_dict(tr.direct_arrival_dict(mi, 33, window, unwarp=unwarp))
    steady, video = mi.render(scene, spp=16, seed=1)
    video, steady = np.array(video, np.float64), np.array(steady, np.float64)
    lit = video.sum(-1) > 0
    assert set(np.flatnonzero(lit[16, 16])) == centre
    assert set(np.flatnonzero(lit[0, 0])) <= corner and lit[0, 0].any()
    lo, hi = tr.expected_direct_bins(33, window, unwarp)
    t = np.arange(200)
    assert not np.any(lit & ((t < lo[..., None]) | (t > hi[..., None])))
    np.testing.assert_allclose(video.sum(axis=2), steady, rtol=1e-5, atol=1e-7)
    assert window.bin_of(2.0 if unwarp else 4.0) == min(centre)


def test_window_starts_at_the_first_direct_arrival(tr):
    """size_window: no energy before the chosen start; the catalogue start is not later."""
    from dbench.datasets.scenes import catalogue as scenes
    sc = scenes.get("cornell-transient")
    r = tr.size_window(sc, coverage=0.99, res=12, spp=32, horizon=20.0, bins=1000)
    assert r["fraction_before_start"] == 0.0
    assert r["start_opl"] <= r["first_arrival"]
    assert sc.window_start <= r["first_arrival"] + 0.05
    assert 0.98 <= r["fraction_inside"] <= 1.0


# ---------------------------------------------------------------------------------------------
# collector (a) against numpy


@pytest.mark.parametrize("transform", ["identity", "box-cox"])
def test_collector_a_equals_numpy_on_stacked_passes(tr, transform):
    from dbench.datasets.scenes import catalogue as scenes
    from dbench.datasets.stats import stats_from_samples, transform_of_zero, transform_samples
    sc = scenes.get("cornell-transient")
    res, bins = 8, 30
    samples = [v for v, _ in tr.pass_samples(sc, res, SPP, seed=5, bins=bins, copies=2)]
    stack = np.concatenate([np.moveaxis(v, 1, 0) for v in samples], axis=0)  # (spp, H, W, T, 3)
    assert stack.shape == (SPP, res, res, bins, 3)
    out = tr.collect_passes(sc, res, SPP, seed=5, bins=bins, stats=(transform, 0.5), copies=2)
    u = transform_samples(stack, transform, 0.5) - transform_of_zero(transform, 0.5)
    for k, p in (("s1", 1), ("s2", 2), ("s3", 3)):
        np.testing.assert_allclose(out.sums[k], (u ** p).sum(axis=0), rtol=1e-12, atol=1e-12)
    ref = stats_from_samples(stack, transform, 0.5, axis=0)
    scale = np.abs(ref.mean).max()
    np.testing.assert_allclose(out.stats.mean, ref.mean, rtol=1e-6, atol=1e-9 * scale)
    np.testing.assert_allclose(out.stats.var_mean, ref.var_mean, rtol=1e-6,
                               atol=1e-9 * ref.var_mean.max())
    np.testing.assert_allclose(out.stats.m3, ref.m3, rtol=1e-6, atol=1e-9 * np.abs(ref.m3).max())
    np.testing.assert_allclose(out.color, stack.mean(axis=0), rtol=1e-6, atol=1e-8)
    nz = (stack > 0 if transform == "box-cox" else stack != 0).sum(axis=0)
    np.testing.assert_array_equal(out.non_zero, nz)
    assert out.non_zero.max() <= SPP and out.non_zero.min() >= 0
    # bins no path reached: θ̂ = g(0), Var = 0 (docs/methods/statistical.md §13.14)
    empty = nz == 0
    assert empty.any()
    np.testing.assert_array_equal(out.stats.theta[empty], transform_of_zero(transform, 0.5))
    np.testing.assert_array_equal(out.stats.var_mean[empty], 0.0)


# ---------------------------------------------------------------------------------------------
# collector (b) against collector (a)


def _assert_same(a, b):
    for k in ("s1", "s2", "s3"):
        np.testing.assert_array_equal(a.sums[k], b.sums[k], err_msg=k)
    # the noisy total's variance: the same per-path window totals, summed over bins in another
    # order (float64); m2b = S2/n − a² cancels on nearly deterministic totals (a directly seen
    # light), which lifts that rounding to ~1e-7 relative
    assert a.total_var is not None and b.total_var is not None
    np.testing.assert_allclose(b.total_var, a.total_var, rtol=1e-6, atol=0)
    np.testing.assert_array_equal(a.non_zero, b.non_zero)
    np.testing.assert_array_equal(a.color, b.color)
    np.testing.assert_array_equal(a.stats.mean, b.stats.mean)
    np.testing.assert_array_equal(a.stats.var_mean, b.stats.var_mean)
    np.testing.assert_array_equal(a.stats.m3, b.stats.m3)
    np.testing.assert_allclose(a.steady, b.steady, rtol=1e-6)


def assert_rows_found(b):
    """The rows collector (b) finds on the device for the cache (packed rows) are those a host
    scan of the bit patterns finds (datasets/sparse_rows.py.layout)."""
    from dbench.datasets import sparse_rows
    for key, arrays in (("stats", {"mean": b.stats.mean, "var_mean": b.stats.var_mean,
                                   "m3": b.stats.m3, "non_zero": b.non_zero}),
                        ("color", {"color": b.color})):
        host = np.unpackbits(sparse_rows.layout(arrays, list(arrays))[sparse_rows.MASK],
                             count=b.rows[key].size).astype(bool)
        assert b.rows[key].dtype == bool and np.array_equal(b.rows[key].reshape(-1), host), key


@pytest.mark.parametrize("transform", ["identity", "box-cox"])
def test_collector_b_equals_a_exactly(tr, transform):
    """Same seeds and paths (1-spp passes): bit-identical power sums, counts and moments."""
    from dbench.datasets.scenes import catalogue as scenes
    sc = scenes.get("cornell-transient")
    a = tr.collect_passes(sc, 10, SPP, seed=2, bins=40, stats=(transform, 0.5), copies=1)
    b = tr.collect_in_integrator(sc, 10, SPP, seed=2, bins=40, transform=transform,
                                 per_pass=True)
    _assert_same(a, b)
    assert b.timing["n_overflow"] == 0 and b.timing["n_nonfinite"] == 0
    assert_rows_found(b)
    assert 0 < b.rows["color"].mean() < 1  # the test sees empty rows and full ones
    if transform == "identity":  # without a cache to fill, they are not looked for
        off = tr.collect_in_integrator(sc, 10, SPP, seed=2, bins=40, rows=False)
        assert off.rows == {"stats": None, "color": None}
    assert_colour_alone_is_the_same(tr, sc, b, 10, 40, SPP, transform)


def assert_colour_alone_is_the_same(tr, sc, b, res, bins, spp, transform):
    """Without statistics (a load that asked for none) the collector gives the same colour and
    colour rows bit for bit, and no statistics."""
    alone = tr.collect_in_integrator(sc, res, spp, seed=2, bins=bins, transform=transform,
                                     per_pass=True, stats=False)
    assert alone.stats is None and alone.non_zero is None and alone.rows["stats"] is None
    assert alone.sums is None
    assert alone.color.dtype == np.float32 and alone.color.tobytes() == b.color.tobytes()
    np.testing.assert_array_equal(alone.rows["color"], b.rows["color"])
    np.testing.assert_array_equal(alone.steady, b.steady)


def test_collector_b_exact_when_nee_reenters_bins(tr, corridor):
    """NEE makes the bin order non-monotone: paths leave a bin and come back. The slots merge
    the re-entries, so (b) still equals (a); flushing on every bin change (the seed's Alg. 4 as
    printed, slots = 1) double-counts those paths and differs."""
    spp = 16
    a = tr.collect_passes(corridor, 8, spp, seed=0, stats=("identity", 0.5), copies=1)
    b = tr.collect_in_integrator(corridor, 8, spp, seed=0, per_pass=True)
    assert b.timing["n_reentry"] > 0
    _assert_same(a, b)
    assert 0 <= b.non_zero.min() and b.non_zero.max() <= spp
    naive = tr.collect_in_integrator(corridor, 8, spp, seed=0, per_pass=True, slots=1)
    assert naive.timing["n_overflow"] > 0
    assert not np.array_equal(naive.sums["s2"], a.sums["s2"])
    # first moments agree (the same contributions are summed), second moments do not
    np.testing.assert_allclose(naive.sums["s1"], a.sums["s1"], rtol=1e-5, atol=1e-6)


def test_collector_b_single_call_and_memory_independent_of_spp(tr):
    """All spp in one render: consistent statistics, 0 ≤ non_zero ≤ spp, and a state whose size
    depends on the film only: (H·W·T·3) × (S1, S2, S3, N) float64 + 4 uint32 counters + the
    per-pixel window totals."""
    from dbench.datasets.scenes import catalogue as scenes
    sc = scenes.get("cornell-transient")
    res, bins = 8, 30
    sizes = {}
    for spp in (1, 4, 64):
        out = tr.collect_in_integrator(sc, res, spp, seed=1, bins=bins)
        sizes[spp] = out.timing["state_bytes"]
        assert out.non_zero.min() >= 0 and out.non_zero.max() <= spp
        assert out.timing["n_overflow"] == 0
        # identity transform: S1 / n is the color, S2 ≥ S1² / n (Cauchy-Schwarz)
        np.testing.assert_allclose(out.sums["s1"] / spp, out.color, rtol=1e-6, atol=1e-9)
        assert np.all(out.sums["s2"] * spp >= out.sums["s1"] ** 2 * (1 - 1e-9) - 1e-12)
        assert 0.95 < out.energy_fraction <= 1.0 + 1e-6
    voxels = res * res * bins * 3
    totals = 2 * res * res * 3 * 8       # Σ total, Σ total² per pixel and channel
    assert sizes[1] == sizes[4] == sizes[64] == state_bytes(voxels) + 4 * 4 + totals


def state_bytes(entries: int) -> int:
    """Bytes of the sums and counts of ``entries`` (voxel, channel) in the layout the collector
    picks on this machine under the current budget (dbench/datasets/transient/voxel_sums.py)."""
    from dbench.datasets.transient.voxel_sums import VoxelSums

    return entries * 32 if VoxelSums(3).packets else entries * 24 + entries // 3 * 8


@pytest.mark.parametrize("per_pass", [True, False])
def test_collector_b_expand_and_atomic_flushes_agree(tr, monkeypatch, per_pass):
    """The flushes' two strategies (docs/methods/statistical.md §11.2): per-thread copies summed
    after the render (Expand, LLVM, small states) and atomics into one copy. With 1-spp passes a
    voxel gets at most one flush per pass, so both are bit-identical; in one call of many spp
    the float64 additions only run in another order."""
    from dbench.datasets.scenes import catalogue as scenes
    from dbench.datasets.transient import voxel_sums

    sc = scenes.get("cornell-transient")
    out = {}
    for budget in (voxel_sums.EXPAND_BYTES, 0):
        monkeypatch.setattr(voxel_sums, "EXPAND_BYTES", budget)
        out[budget] = tr.collect_in_integrator(sc, 8, 6, seed=2, bins=30, per_pass=per_pass,
                                               transform="box-cox")
        # the layouts differ in size: the state measured is the one the budget chose
        entries = 8 * 8 * 30 * 3
        assert out[budget].timing["state_bytes"] == (
            state_bytes(entries) + 8 * entries + 4 * 4 + 2 * 8 * 8 * 3 * 8)  # + box-cox's
        # plain sums, the counters and the window totals
    expand, atomic = out[voxel_sums.EXPAND_BYTES], out[0]
    np.testing.assert_array_equal(expand.non_zero, atomic.non_zero)
    np.testing.assert_array_equal(expand.color, atomic.color)
    for k in ("s1", "s2", "s3"):
        if per_pass:
            np.testing.assert_array_equal(expand.sums[k], atomic.sums[k], err_msg=k)
        else:
            np.testing.assert_allclose(expand.sums[k], atomic.sums[k], rtol=1e-12, atol=1e-300,
                                       err_msg=k)


def test_collector_b_matches_the_plain_render_in_expectation(tr):
    """(b), (a) through a batch sensor and a plain transient_path render estimate the same
    video: the image-summed energy of every bin and channel agrees within the Monte Carlo
    noise, measured by the collectors' own variance estimates (pixels are independent: the
    variances add). Pixels that see the light are left out: their rare, huge samples make
    the variance estimate itself unreliable at 64 spp."""
    from dbench.datasets.scenes import catalogue as scenes
    sc = scenes.get("cornell-transient")
    plain, steady, _ = tr.render_plain(sc, 12, 64, seed=9, bins=20)
    keep = steady.max(axis=-1) < 1.0                              # not the light's pixels
    ep = plain.astype(np.float64)[keep].sum(axis=0)              # (T, 3)
    b = tr.collect_in_integrator(sc, 12, 64, seed=4, bins=20)
    # collector (a) through a batch sensor of 4 cameras: the same view as the single camera
    a = tr.collect_passes(sc, 12, 64, seed=4, bins=20, stats=("identity", 0.5), copies=4)
    for out in (a, b):
        e = out.color.astype(np.float64)[keep].sum(axis=0)
        var = out.stats.var_mean[keep].sum(axis=0)                # Var of e
        ok = var > 0
        z = (e - ep)[ok] / np.sqrt(2.0 * var[ok])
        assert ok.sum() > 30 and np.abs(z).max() < 6.0, (out.timing["collector"], z)


def test_fog_scene_collector_a(tr):
    """Collector (a) on the media scene; (b) there: tests/datasets/test_transient_media_collector.py."""
    from dbench.datasets.scenes import catalogue as scenes
    sc = scenes.get("fog-transient")
    out = tr.collect_passes(sc, 8, 4, seed=0, bins=20, stats=("identity", 0.5))
    assert out.color.shape == (8, 8, 20, 3) and np.isfinite(out.color).all()
    assert out.non_zero.max() <= 4 and out.energy_fraction > 0.9


@pytest.mark.parametrize("transform", ["identity", "box-cox", "yeo-johnson"])
def test_fused_moments_equal_stats_from_power_sums(transform):
    """The fused moment kernel of both collectors = the library's stats_from_power_sums."""
    from dbench.datasets.stats import PowerSums, stats_from_power_sums
    from dbench.datasets.stats import stats_from_sums
    rng = np.random.default_rng(0)
    x = np.where(rng.random((16, 5, 4, 7, 3)) < 0.7, 0.0,
                 rng.lognormal(0.0, 1.5, (16, 5, 4, 7, 3))).astype(np.float32)
    x[:, 0, 0, 0] = 0.3                                 # constant voxels: zero variance
    acc = PowerSums((5, 4, 7, 3), transform, 0.5)
    acc.add_batch(x, axis=0)
    ref = stats_from_power_sums(acc.n, acc.s1, acc.s2, acc.s3, acc.k, transform, 0.5)
    got = stats_from_sums(acc.n, acc.s1, acc.s2, acc.s3, transform, 0.5)
    for name in ("mean", "var_mean", "m3"):
        np.testing.assert_allclose(getattr(got, name), getattr(ref, name), rtol=1e-13,
                                   atol=1e-15, err_msg=name)
    assert np.all(got.var_mean[0, 0, 0] == 0) and np.all(got.m3[0, 0, 0] == 0)
    one = stats_from_sums(1, acc.s1, acc.s2, acc.s3, transform, 0.5)
    assert np.all(one.var_mean == 0) and np.all(one.m3 == 0)


def test_bench_metrics_and_figures(tmp_path):
    """Per-bin curves, whole-video figures and the three plots on a synthetic video."""
    from dbench.report import transient_figures as bt
    from dbench.studies import transient_report
    rng = np.random.default_rng(1)
    ref = rng.random((6, 7, 9, 3)).astype(np.float32)
    noisy = ref + 0.1 * rng.standard_normal(ref.shape).astype(np.float32)
    frame = TransientFrame(color=noisy, reference=ref,
                           meta={"start_opl": 3.0, "bin_width_opl": 0.1, "scene": "synthetic"})
    table = bt.per_bin_table({"noisy": noisy}, ref, frame.time_axis)
    assert list(table.columns) == ["bin", "opl", "noisy"] and len(table) == 9
    expect = np.sqrt(((noisy.astype(np.float64) - ref) ** 2).mean(axis=(0, 1, 3)))
    np.testing.assert_allclose(table["noisy"], expect, rtol=1e-6)
    m = transient_report.video_metrics(noisy, ref)
    assert m["rmse"] == pytest.approx(float(np.sqrt(((noisy.astype(np.float64) - ref) ** 2)
                                                    .mean())), rel=1e-6)
    assert 0 < m["ssim_integrated"] <= 1
    assert bt.streak(noisy, 2).shape == (9, 7, 3)
    np.testing.assert_array_equal(bt.streak(noisy, 2)[:, 4], noisy[2, 4])
    shown = bt.write_figures(tmp_path, frame, {"noisy": noisy}, prefix="s_")
    assert all(0 <= t < 9 for t in shown)
    for name in ("s_rmse_per_bin.png", "s_bins.png", "s_streak.png", "s_rmse_per_bin.csv"):
        assert (tmp_path / name).stat().st_size > 0


@pytest.mark.parametrize("transform", ["identity", "box-cox"])
def test_device_moments_equal_host_formulas_bit_for_bit(tr, transform):
    """Collector (b) computes the moments, colour and counts on the device; with a sample
    count that is not a power of two (a division by a constant would be rounded differently if
    it became a multiplication by the reciprocal) they equal the host formulas exactly."""
    from dbench.datasets.scenes import catalogue as scenes
    from dbench.datasets.stats import stats_from_sums
    sc = scenes.get("cornell-transient")
    spp = 7
    b = tr.collect_in_integrator(sc, 8, spp, seed=4, bins=30, transform=transform, lam=0.5)
    host = stats_from_sums(spp, b.sums["s1"], b.sums["s2"], b.sums["s3"], transform, 0.5)
    np.testing.assert_array_equal(b.stats.mean, host.mean)
    np.testing.assert_array_equal(b.stats.var_mean, host.var_mean)
    np.testing.assert_array_equal(b.stats.m3, host.m3)
    assert np.all(b.stats.n == spp) and b.non_zero.dtype == np.int32
    assert b.non_zero.min() >= 0 and b.non_zero.max() <= spp
    if transform == "identity":  # the colour is the plain mean, here the first power sum / n
        np.testing.assert_array_equal(b.color, (b.sums["s1"] / spp).astype(np.float32))
