"""Sample transforms and moments: docs/methods/statistical.md §3, §4 and §13 checks 1-4."""
import numpy as np
import pytest
from scipy import stats as sps

from dbench.datasets.stats import (PowerSums, stats_from_power_sums, stats_from_samples,
                                   transform_of_zero, transform_samples, variance_of_mean)
from dbench.data import SampleStats
from dbench.errors import DbenchInputError


def test_transform_reference_values():
    assert transform_samples(np.array([0.0]), "box-cox", 0.5)[0] == pytest.approx(-2, abs=1e-12)
    assert transform_samples(np.array([1.0]), "box-cox", 0.5)[0] == pytest.approx(0, abs=1e-12)
    assert transform_samples(np.array([4.0]), "box-cox", 0.5)[0] == pytest.approx(2, abs=1e-12)
    assert transform_samples(np.array([0.0]), "yeo-johnson", 0.7)[0] == 0
    assert transform_samples(np.array([1.0]), "yeo-johnson", 0.5)[0] == pytest.approx(
        0.8284271, abs=1e-7)
    assert transform_of_zero("box-cox", 0.5) == -2.0
    assert transform_of_zero("identity", 0.5) == 0.0


def test_yeo_johnson_matches_scipy_both_branches():
    x = np.linspace(-3, 3, 61)
    for lam in (0.0, 0.5, 1.5, 2.0):
        np.testing.assert_allclose(transform_samples(x, "yeo-johnson", lam),
                                   sps.yeojohnson(x, lmbda=lam), rtol=1e-12, atol=1e-12)


def test_bad_transform_arguments():
    with pytest.raises(DbenchInputError, match="transform"):
        transform_samples(np.zeros(2), "log", 0.5)
    with pytest.raises(DbenchInputError, match="lam"):
        PowerSums((2,), "box-cox", 0.0)


EXPECTED = {  # spec §13 check 2, samples [0, 0, 1, 4]
    "identity": (1.25, 3.5833333, 4.21875, 1.2990552, 0.8958333),
    "box-cox": (-0.5, 3.6666667, 2.25, -0.4744318, 0.9166667),
    "yeo-johnson": (0.8251408, 1.3581062, 0.8360054, 0.8507894, 0.3395265),
}


@pytest.mark.parametrize("transform", sorted(EXPECTED))
def test_moments_of_known_samples(transform):
    mu, s2, m3, theta, var = EXPECTED[transform]
    acc = PowerSums((1,), transform, 0.5)
    for v in (0.0, 0.0, 1.0, 4.0):
        acc.add(np.array([v]))
    for st in (acc.finalize(), stats_from_samples(np.array([[0.0], [0.0], [1.0], [4.0]]),
                                                  transform, 0.5)):
        assert st.mean[0] == pytest.approx(mu, abs=5e-8)
        assert st.var_mean[0] * 4 == pytest.approx(s2, abs=5e-8)
        assert st.m3[0] == pytest.approx(m3, abs=5e-8)
        assert st.theta[0] == pytest.approx(theta, abs=5e-8)
        assert st.var_mean[0] == pytest.approx(var, abs=5e-8)


@pytest.mark.parametrize("transform", ["identity", "box-cox", "yeo-johnson"])
def test_power_sums_match_two_pass_on_rendering_like_data(transform):
    rng = np.random.default_rng(1)
    x = rng.lognormal(0, 1.5, (1024, 200)) * (rng.random((1024, 200)) < 0.2)
    acc = PowerSums((200,), transform, 0.5)
    acc.add_batch(x.astype(np.float32), axis=0)
    fast = acc.finalize()
    ref = stats_from_samples(x.astype(np.float32), transform, 0.5)
    np.testing.assert_allclose(fast.var_mean, ref.var_mean, rtol=1e-9)
    np.testing.assert_allclose(fast.m3, ref.m3, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(fast.mean, ref.mean, rtol=1e-12, atol=1e-12)


def test_batches_merge_by_addition():
    rng = np.random.default_rng(2)
    x = rng.random((64, 5, 3)).astype(np.float32)
    one = PowerSums((5, 3), "box-cox", 0.5)
    one.add_batch(x, axis=0)
    many = PowerSums((5, 3), "box-cox", 0.5)
    for k in range(64):
        part = PowerSums((5, 3), "box-cox", 0.5)
        part.add(x[k])
        many.merge(part)
    for name in ("s1", "s2", "s3"):
        np.testing.assert_allclose(getattr(one, name), getattr(many, name), rtol=1e-12)


@pytest.mark.parametrize("transform", ["identity", "box-cox", "yeo-johnson"])
def test_compiled_batch_equals_per_sample_reference(transform):
    rng = np.random.default_rng(3)
    x = (rng.lognormal(0, 1, (7, 16, 9, 3)) * (rng.random((7, 16, 9, 3)) < 0.5)).astype(
        np.float32)
    x[0, 0, 0, 0] = np.nan
    x[1, 2, 3, 1] = -0.25
    ref, fast = PowerSums((7, 9, 3), transform, 0.5), PowerSums((7, 9, 3), transform, 0.5)
    for k in range(16):
        ref.add(x[:, k])
    plain = fast.add_batch(x, axis=1)
    for name in ("s1", "s2", "s3"):
        np.testing.assert_allclose(getattr(fast, name), getattr(ref, name), rtol=1e-12,
                                   atol=1e-12)
    assert (fast.n_nonfinite, fast.n_clamped) == (ref.n_nonfinite, ref.n_clamped)
    assert fast.n_nonfinite == 1
    np.testing.assert_allclose(plain, np.nan_to_num(x.astype(np.float64)).sum(axis=1))


def test_constant_samples_have_exactly_zero_variance():
    acc = PowerSums((4,), "box-cox", 0.5)
    acc.add_batch(np.full((256, 4), 0.3, np.float32), axis=0)
    st = acc.finalize()
    assert np.all(st.var_mean == 0) and np.all(st.m3 == 0)
    np.testing.assert_allclose(st.mean, transform_samples(np.float32(0.3), "box-cox", 0.5))
    assert np.all(np.isfinite(st.theta))


def test_single_sample_is_deterministic_not_nan():
    st = stats_from_power_sums(1, np.array([1.0]), np.array([1.0]), np.array([1.0]), 0.0,
                               "identity", 0.5)
    assert st.var_mean[0] == 0 and np.isfinite(st.theta[0])


def test_shape_mismatch_names_the_buffer():
    acc = PowerSums((2, 3), "identity")
    with pytest.raises(DbenchInputError, match="samples: expected shape"):
        acc.add(np.zeros((3, 2)))


def test_variance_of_mean_from_plain_sums():
    """The transient totals' variance (both collectors) follows spec §4.1: σ²/n with the
    n/(n−1) factor, 0 for constant samples, unknown (None) below 2 samples."""
    rng = np.random.default_rng(5)
    x = rng.exponential(2.0, size=(40, 4, 3))
    x[:, 0, 0] = 0.7                                          # constant samples
    got = variance_of_mean(40, x.sum(0), (x * x).sum(0))
    np.testing.assert_allclose(got, x.var(0, ddof=1) / 40, rtol=1e-10, atol=1e-15)
    assert got[0, 0] == 0.0
    assert variance_of_mean(1, x[0], x[0] ** 2) is None


def test_variance_of_mean_needs_no_compiled_code(monkeypatch):
    """A per-pixel image's variance is NumPy's work: the fused kernel's first call in a process
    loads Numba's compiled code (about 0.5 s), which a transient load would then pay."""
    from dbench.datasets import stats

    def compiled(*args):
        raise AssertionError("the fused kernel was called")

    monkeypatch.setattr(stats, "_moments", compiled)
    x = np.random.default_rng(6).exponential(2.0, size=(8, 4, 3))
    got = variance_of_mean(8, x.sum(0), (x * x).sum(0))
    np.testing.assert_allclose(got, x.var(0, ddof=1) / 8, rtol=1e-10, atol=1e-15)


def test_one_count_for_every_pixel_stays_one_number():
    """SampleStats given n as one number keeps it as a read-only broadcast (dbench/data.py):
    the count reads as the (H, W, T, C) array, costs 8 bytes, not 8 a value, and cannot be
    written through; a count that is not a number is refused naming stats.n."""
    from dbench.data import SampleStats

    mean = np.zeros((4, 5, 6, 3))
    st = SampleStats(n=64.0, mean=mean, var_mean=mean, m3=mean, transform="identity")
    assert st.n.shape == mean.shape and st.n.dtype == np.float64 and np.all(st.n == 64)
    assert st.n.strides == (0, 0, 0, 0) and not st.n.flags.writeable
    assert st.n.base is not None and st.n.base.nbytes == 8
    np.testing.assert_array_equal(st.theta, mean)
    with pytest.raises(ValueError, match="read-only"):
        st.n[0, 0, 0, 0] = 1
    full = SampleStats(n=np.full(mean.shape, 64.0), mean=mean, var_mean=mean, m3=mean)
    assert full.n.flags.writeable and full.n.strides != (0, 0, 0, 0)
    with pytest.raises(DbenchInputError, match="stats.n"):
        SampleStats(n="many", mean=mean, var_mean=mean, m3=mean)


@pytest.mark.parametrize("n, stored", [(np.full((4, 5, 3), 64.0), "value and shape"),
                                       (np.arange(60.0).reshape(4, 5, 3), "array"),
                                       (np.full((4, 5, 3), 7, np.int32), "value and shape"),
                                       (16.0, "value")])
def test_stats_through_the_cache_keep_their_count_bit_for_bit(tmp_path, n, stored):
    # a uniform count is stored as one value (stats.stats_to_arrays): with its shape where
    # SampleStats held a full array, alone where it held a broadcast of one number
    from dbench.datasets.cache import Cache
    from dbench.datasets.stats import stats_from_arrays, stats_to_arrays
    rng = np.random.default_rng(3)
    stats = SampleStats(n=n, mean=rng.random((4, 5, 3)), var_mean=rng.random((4, 5, 3)),
                        m3=rng.random((4, 5, 3)), transform="identity", lam=0.5)
    arrays = stats_to_arrays(stats)
    assert {"value and shape": np.ndim(arrays["n"]) == 0 and "n_shape" in arrays,
            "array": np.shape(arrays["n"]) == (4, 5, 3) and "n_shape" not in arrays,
            "value": np.ndim(arrays["n"]) == 0 and "n_shape" not in arrays}[stored]
    Cache(tmp_path).put("stats", {"n": repr(n)}, arrays=arrays)
    back = stats_from_arrays(Cache(tmp_path).get("stats", {"n": repr(n)}).arrays(),
                             "identity", 0.5)
    assert back.n.dtype == stats.n.dtype and back.n.shape == stats.n.shape
    assert back.n.tobytes() == stats.n.tobytes()
    assert back.n.flags.writeable == stats.n.flags.writeable
