"""Tests of ``NAME+gate``: any steady method followed by ProDen's t-test gate
(docs/methods/statistical.md §12, check 17; dbench/methods/gate)."""
from __future__ import annotations

import numpy as np
import pytest

from dbench.data import Frame, SampleStats
from dbench.denoiser import _REGISTRY, Denoiser, register
from dbench.errors import DbenchInputError, UnknownNameError
from dbench.methods.kernels import gate as kg
from dbench.methods.kernels import gate_reference as kr
from dbench.methods.kernels.variance_floor import linear_variance
from dbench.registry import available, canonical, get, method_class

from test_statistical import synthetic_case  # pytest puts this folder on sys.path


def _frame(seed=0, h=14, w=15):
    color, stats, albedo, normal, depth = synthetic_case(h, w, seed=seed)
    return Frame(color=color.astype(np.float32), albedo=albedo.astype(np.float32),
                 normal=normal.astype(np.float32), depth=depth.astype(np.float32), stats=stats)


def test_gate_factor_and_check_17():
    np.testing.assert_allclose(kr.proden_gate_factor([4.2, 3.2, 5.2]),
                               [0.5, 0.97725, 0.02275], atol=1e-5)
    rng = np.random.default_rng(14)
    hdr = rng.random((16, 16, 3))
    den = hdr + 0.3
    for gate in (kr.proden_gate, kg.proden_gate_fast):
        np.testing.assert_allclose(gate(hdr, den, np.zeros_like(hdr)), hdr, atol=1e-6)
        np.testing.assert_allclose(gate(hdr, den, np.full_like(hdr, 100.0)), den, atol=1e-6)


@pytest.mark.parametrize("shape", [(1, 1), (3, 17), (23, 9), (40, 64)])
@pytest.mark.parametrize("alpha", [1.0, 0.35])
def test_fast_gate_equals_reference(shape, alpha):
    """The compiled gate (separable blurs, tabulated Φ) equals the SciPy reference within
    float32 rounding, over every regime of t (variance spread over four decades)."""
    rng = np.random.default_rng(hash(shape) % 2 ** 32)
    hdr = rng.gamma(1.0, 1.0, (*shape, 3)).astype(np.float32)
    den = (hdr * rng.uniform(0.7, 1.3, hdr.shape)).astype(np.float32)
    var = rng.gamma(1.0, 1.0, hdr.shape) * 10.0 ** rng.uniform(-6, -2, hdr.shape)
    ref = kr.proden_gate(hdr, den, var, alpha=alpha)
    fast = kg.proden_gate_fast(hdr, den, var, alpha=alpha)
    assert fast.dtype == np.float32 and fast.shape == hdr.shape
    np.testing.assert_allclose(fast, ref, rtol=1e-6, atol=1e-7)
    factor = (ref - hdr) / np.where(den == hdr, 1, den - hdr)
    assert 0.05 < np.mean(factor) < 0.95  # both the open and the closed gate are exercised


def test_gate_table_error_bound():
    t = np.linspace(0, 12, 100_003)
    table = kg.gate_table()
    u = np.minimum(t / kg.LUT_T_MAX * kg.LUT_SIZE, kg.LUT_SIZE - 1.0)
    m = u.astype(int)
    interp = table[m] + (u - m) * (table[m + 1] - table[m])
    assert np.max(np.abs(interp - kr.proden_gate_factor(t))) < 2e-7


def test_wrapper_equals_method_then_reference_gate():
    """Known composition: jbf+gate = proden_gate(noisy, jbf output, Var(linear mean) floored
    over 11x11 windows); gate_pool=0 is the spec's gate on the raw variance."""
    frame = _frame(seed=3)
    den = get("jbf", radius=3).denoise(frame)
    var = linear_variance(frame.stats, frame.color)
    for pool in (5, 0, 2):
        params = {} if pool == 5 else {"gate_pool": pool}
        out = get("jbf+gate", radius=3, **params).denoise(frame)
        expected = kr.proden_gate(frame.color, den, var, pool_radius=pool)
        np.testing.assert_allclose(out, expected, rtol=1e-6, atol=1e-7)
        ref = get("jbf+gate", radius=3, gate_backend="reference", **params).denoise(frame)
        np.testing.assert_allclose(out, ref, rtol=1e-6, atol=1e-7)



def test_class_shape_and_names():
    cls = method_class("oidn+gate")
    assert cls is method_class("oidn+gate") and cls.name == "oidn+gate"
    assert cls.needs == method_class("oidn").needs | {"stats"} and cls.kinds == {"steady"}
    assert set(cls.defaults) == set(method_class("oidn").defaults) | set(kg_defaults())
    assert "oidn+gate" not in available() and "statistical-gate" not in available()
    # the old name is an alias of statistical+gate, published under the new name
    assert canonical("statistical-gate") == "statistical+gate"
    assert method_class("statistical-gate") is method_class("statistical+gate")
    jbf_gate = get("jbf+gate")
    assert jbf_gate.optional_needs == method_class("jbf").optional_needs | {"emitter"}
    assert jbf_gate.per_frame("sequence")  # frame by frame on sequences, like its method


def kg_defaults():
    from dbench.methods.gate import GATE_DEFAULTS
    return GATE_DEFAULTS


def test_refusals_name_the_problem():
    with pytest.raises(DbenchInputError, match="steady"):
        method_class("svgf+gate")
    with pytest.raises(DbenchInputError, match="already gated"):
        method_class("jbf+gate+gate")
    with pytest.raises(UnknownNameError, match="nope"):
        method_class("nope+gate")
    with pytest.raises(DbenchInputError, match="gate_alpha"):
        get("jbf+gate", gate_alpha=1.5)
    with pytest.raises(DbenchInputError, match="gate_backend"):
        get("jbf+gate", gate_backend="gpu")
    with pytest.raises(DbenchInputError, match="gate_emitters"):
        get("jbf+gate", gate_emitters="yes")
    for bad in (-1, 2.5, True, 65):
        with pytest.raises(DbenchInputError, match="gate_pool"):
            get("jbf+gate", gate_pool=bad)
    with pytest.raises(DbenchInputError, match="radius"):
        get("jbf+gate", radius=-1)  # the method's own checks still run
    frame = _frame(seed=1)
    with pytest.raises(DbenchInputError, match="stats"):
        get("jbf+gate").denoise(frame.with_buffers(stats=None))
    assert not get("jbf+gate").applies_to("steady", {"color", "albedo", "normal"})[0]


def test_consistent_as_variance_vanishes():
    """Zero variance: every pixel the method changed returns to the noisy value (t = ∞)."""
    rng = np.random.default_rng(5)
    h, w = 10, 11
    color = rng.random((h, w, 3)) + 0.5
    stats = SampleStats(n=np.full((h, w, 3), 64.0), mean=color, var_mean=np.zeros((h, w, 3)),
                        m3=np.zeros((h, w, 3)), transform="identity")
    frame = Frame(color=color.astype(np.float32), albedo=np.full((h, w, 3), 0.5, np.float32),
                  normal=np.tile(np.float32([0, 0, 1]), (h, w, 1)),
                  depth=np.ones((h, w, 1), np.float32), stats=stats)
    for name in ("jbf+gate", "statistical+gate", "oidn+gate"):
        out = get(name).denoise(frame)
        np.testing.assert_allclose(out, frame.color, rtol=0, atol=1e-6)
    assert np.array_equal(get("jbf+gate", gate_alpha=0.0).denoise(_frame(2)), _frame(2).color)


def test_convergence_with_spp():
    """A biased method (a constant blur) is wrong by a fixed amount at every spp; its gated
    form's error falls with the noise, towards the noisy input's."""
    rng = np.random.default_rng(11)
    h, w = 48, 48
    y, x = np.mgrid[0:h, 0:w] / h
    truth = (0.5 + 0.4 * np.sin(6 * x) * np.cos(5 * y))[..., None] * np.ones(3)
    errs = {}
    for spp in (4, 64, 1024):
        sd = 0.3 * truth / np.sqrt(spp)
        noisy = truth + sd * rng.standard_normal(truth.shape)
        stats = SampleStats(n=np.full(truth.shape, float(spp)), mean=noisy, var_mean=sd ** 2,
                            m3=np.zeros(truth.shape), transform="identity")
        frame = Frame(color=noisy.astype(np.float32), albedo=np.full((h, w, 3), 0.5, np.float32),
                      normal=np.tile(np.float32([0, 0, 1]), (h, w, 1)),
                      depth=np.ones((h, w, 1), np.float32), stats=stats)
        plain = get("jbf", radius=6, sigma=(100.0, 100.0, 1e6, 1e6, 1e6, 1e6, 1e6, 1e6)).denoise(frame)
        gated = get("jbf+gate", radius=6,
                    sigma=(100.0, 100.0, 1e6, 1e6, 1e6, 1e6, 1e6, 1e6)).denoise(frame)
        errs[spp] = [float(np.sqrt(np.mean((a - truth) ** 2))) for a in (noisy, plain, gated)]
    assert errs[1024][1] > 3 * errs[1024][0]          # the blur alone does not converge
    assert errs[1024][2] < 1.5 * errs[1024][0]         # the gated blur does
    assert errs[4][2] < errs[64][2] * 10 and errs[1024][2] < errs[64][2] < errs[4][2]


def test_plugin_method_takes_the_gate():
    @register("test-gate-plugin-box")
    class Box(Denoiser):
        """A plugin-style method: a 3x3 box blur of the colour."""
        kinds = {"steady"}
        needs = {"color"}
        defaults = {"passes": 1}

        def denoise(self, data):
            from scipy.ndimage import uniform_filter
            out = data.color
            for _ in range(self.params["passes"]):
                out = uniform_filter(out, size=(3, 3, 1), mode="nearest")
            return out.astype(np.float32)

    try:
        frame = _frame(seed=4)
        m = get("test-gate-plugin-box+gate", passes=2)
        assert m.needs == {"color", "stats"}
        out = m.denoise(frame)
        plain = get("test-gate-plugin-box", passes=2).denoise(frame)
        var = linear_variance(frame.stats, frame.color)
        np.testing.assert_allclose(out, kr.proden_gate(frame.color, plain, var, pool_radius=5),
                                   rtol=1e-6, atol=1e-7)
    finally:  # leave the registry as the other tests expect it
        _REGISTRY.pop("test-gate-plugin-box", None)


@pytest.mark.parametrize("made", [lambda c: None, lambda c: c.mean(-1, keepdims=True),
                                  lambda c: c[1:]])
def test_a_wrong_output_of_the_gated_method_is_named(made):
    # it failed inside the gate: "ValueError: cannot reshape array of size 1 into shape ..."
    register("test-gate-wrong")(type("Wrong", (Denoiser,), {
        "denoise": lambda self, data: made(np.asarray(data.color, np.float32))}))
    try:
        with pytest.raises(DbenchInputError,
                           match=r"test-gate-wrong output: expected shape \(14, 15, 3\)"):
            get("test-gate-wrong+gate").denoise(_frame(seed=5))
    finally:
        _REGISTRY.pop("test-gate-wrong", None)


def test_nonfinite_noisy_pixels_keep_the_method_output():
    frame = _frame(seed=9)
    color = frame.color.copy()
    color[4, 5] = np.nan
    out = get("jbf+gate", radius=3).denoise(frame.with_buffers(color=color))
    assert np.isfinite(out).all()


def test_never_further_from_noisy_than_plain():
    """The gate only mixes towards the noisy value: |gated − noisy| <= |plain − noisy|."""
    frame = _frame(seed=8)
    plain = get("statistical", radius=4).denoise(frame).astype(np.float64)
    gated = get("statistical+gate", radius=4).denoise(frame).astype(np.float64)
    noisy = frame.color.astype(np.float64)
    assert np.all(np.abs(gated - noisy) <= np.abs(plain - noisy) + 1e-6)


def test_one_sample_leaves_the_gate_open():
    """n < 2: the variance of the mean is unknown (stored as 0); the gate passes the method's
    output instead of returning the noisy input, so at 1 spp NAME+gate equals NAME."""
    frame = _frame(seed=6)
    st = frame.stats
    one = frame.with_buffers(stats=SampleStats(n=np.ones_like(st.n), mean=st.mean,
                                               var_mean=np.zeros_like(st.var_mean), m3=st.m3,
                                               transform=st.transform, lam=st.lam))
    np.testing.assert_array_equal(get("jbf+gate", radius=3).denoise(one),
                                  get("jbf", radius=3).denoise(one))
    half = get("jbf+gate", radius=3, gate_alpha=0.5).denoise(one)
    plain = get("jbf", radius=3).denoise(one)
    np.testing.assert_allclose(half, 0.5 * (frame.color + plain), rtol=1e-6, atol=1e-7)


@pytest.mark.parametrize("transform,lam", [("identity", 0.5), ("box-cox", 0.5),
                                           ("yeo-johnson", 0.5)])
def test_pixels_with_one_sample_found_through_the_rows_of_zero_variance(transform, lam):
    """Above 1 spp the fast gate reads the sample counts only in the rows whose variance has a
    value ≤ 0 or NaN (SampleStats stores 0 where n < 2): a frame with a few 1-sample pixels,
    with zero-variance pixels of 8 samples elsewhere and with a NaN variance, gives the
    reference backend's output, the 1-sample pixels the open gate's; and the rows each pass
    reports are exactly those."""
    from dbench.methods.gate import gate_output

    rng = np.random.default_rng(5)
    shape = (21, 17, 3)
    color = rng.gamma(1.0, 1.0, shape).astype(np.float32)
    den = (color * rng.uniform(0.6, 1.4, shape)).astype(np.float32)
    var = rng.gamma(1.0, 1.0, shape) * 1e-3
    n = np.full(shape, 8.0)
    n[4, 6], var[4, 6] = 1.0, 0.0           # unknown: one sample
    n[13, 2, 1], var[13, 2, 1] = 1.0, 0.0
    var[9, 10] = 0.0                        # a constant pixel: known, zero variance
    var[17, 3, 2] = np.nan
    stats = SampleStats(n=n, mean=np.zeros(shape), var_mean=var, m3=np.zeros(shape),
                        transform=transform, lam=lam)
    for alpha in (1.0, 0.6):
        fast = gate_output(color, den, stats, alpha=alpha, pool=5, handback="wiener")
        ref = gate_output(color, den, stats, alpha=alpha, pool=5, handback="wiener",
                          backend="reference")
        np.testing.assert_allclose(fast, ref, rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(fast[4, 6], (color[4, 6] + alpha * (den[4, 6] - color[4, 6])),
                                   rtol=1e-6)
    positive = np.empty(shape[0], np.bool_)
    kg.proden_gate_stats(color, den, stats, rows_positive=positive)
    flagged = set(np.flatnonzero(~positive))
    if transform == "identity":
        assert flagged == {4, 9, 13, 17}
    else:  # the linear variance is also 0 where the colour is not > 0: a superset
        assert {4, 9, 13, 17} <= flagged


@pytest.mark.parametrize("transform,lam", [("identity", 0.5), ("box-cox", 0.5),
                                           ("box-cox", 0.25), ("yeo-johnson", 0.5)])
def test_gate_from_statistics_equals_the_composed_fast_gate(transform, lam):
    """proden_gate_stats forms the substitutions and the linear variance inside its first pass
    (identity, Box-Cox ½) or through linear_variance (other transforms): the same numbers as
    proden_gate_fast on the prepared arrays, non-finite values included."""
    rng = np.random.default_rng(31)
    color = rng.gamma(1.0, 1.0, (19, 23, 3)).astype(np.float32)
    den = (color * rng.uniform(0.7, 1.3, color.shape)).astype(np.float32)
    var = rng.gamma(1.0, 1.0, color.shape) * 10.0 ** rng.uniform(-6, -2, color.shape)
    color[2, 3, 1], color[5, 5, 0], den[7, 8, 2], var[9, 9, 1] = np.nan, np.inf, np.nan, np.inf
    stats = SampleStats(n=np.full(color.shape, 8.0), mean=np.zeros(color.shape), var_mean=var,
                        m3=np.zeros(color.shape), transform=transform, lam=lam)
    hdr = np.where(np.isfinite(color), color, den)
    den_fixed = np.where(np.isfinite(den), den, hdr)
    expected = kg.proden_gate_fast(hdr, den_fixed, linear_variance(stats, color))
    got = kg.proden_gate_stats(color, den, stats)
    assert got.dtype == np.float32 and np.isfinite(got[np.isfinite(expected)]).all()
    np.testing.assert_allclose(got, expected, rtol=1e-6, atol=1e-7)


def test_directly_seen_lights_keep_the_input_after_the_gate():
    """gate_emitters (default): pixels an emitter covers keep the input in proportion to the
    coverage, after the gate; without the buffer, or with gate_emitters=False, the gate alone."""
    from dbench.methods.kernels.emitters import keep_emitters

    frame = _frame(seed=4)
    h, w = frame.color.shape[:2]
    e = np.zeros((h, w, 1), np.float32)
    e[2:5, 3:7] = 1.0
    e[8, 9] = 0.4
    lit = frame.with_buffers(emitter=e)
    np.testing.assert_array_equal(get("jbf+gate", radius=3).denoise(frame),
                                  get("jbf+gate", radius=3, gate_emitters=False).denoise(frame))
    plain = get("jbf+gate", radius=3, gate_emitters=False).denoise(lit)
    out = get("jbf+gate", radius=3).denoise(lit)
    np.testing.assert_array_equal(out, keep_emitters(frame.color, plain, e))
    np.testing.assert_array_equal(out[2:5, 3:7], frame.color[2:5, 3:7])
    np.testing.assert_allclose(out[8, 9], plain[8, 9] + 0.4 * (frame.color[8, 9] - plain[8, 9]),
                               rtol=1e-6)


def test_a_method_that_keeps_emitters_gets_the_rule_once():
    """keeps_emitters: the wrapper does not hand a lamp's edge pixel back a second time (a
    coverage of 0.4 would become 1 − 0.6² = 0.64)."""
    from dbench.methods.kernels.emitters import keep_emitters
    from scipy.ndimage import uniform_filter

    @register("test-gate-keeps-emitters")
    class KeepsLights(Denoiser):
        """A 3x3 box blur that hands directly seen lights back to the input itself."""
        kinds = {"steady"}
        needs = {"color"}
        optional_needs = {"emitter"}
        keeps_emitters = True

        def denoise(self, data):
            out = uniform_filter(data.color, size=(3, 3, 1), mode="nearest").astype(np.float32)
            return keep_emitters(data.color, out, getattr(data, "emitter", None))

    try:
        frame = _frame(seed=4)
        e = np.zeros(frame.color.shape[:2] + (1,), np.float32)
        e[8, 9] = 0.4
        lit = frame.with_buffers(emitter=e)
        inner = KeepsLights().denoise(lit)
        expected = kr.proden_gate(frame.color, inner, linear_variance(frame.stats, frame.color),
                                  pool_radius=5)
        got = get("test-gate-keeps-emitters+gate").denoise(lit)
        np.testing.assert_allclose(got, expected, rtol=1e-6, atol=1e-7)
        twice = keep_emitters(frame.color, expected, e)
        assert not np.allclose(got[8, 9], twice[8, 9])  # the pixel differs from its input
    finally:
        _REGISTRY.pop("test-gate-keeps-emitters", None)


@pytest.mark.parametrize("transform", ["identity", "box-cox", "yeo-johnson"])
def test_pooled_gate_from_statistics_equals_the_reference(transform):
    """proden_gate_stats with pool_radius equals the readable gate on the floored linear
    variance, with non-finite colour and method values substituted as the wrapper does."""
    rng = np.random.default_rng(21)
    h, w = 19, 23
    color = rng.gamma(1.0, 1.0, (h, w, 3)).astype(np.float32)
    color[4, 5, 1] = np.nan
    den = (color * rng.uniform(0.8, 1.2, color.shape)).astype(np.float32)
    den[7, 8, 2] = np.inf
    var = rng.gamma(1.0, 1.0, color.shape) * 10.0 ** rng.uniform(-6, -2, color.shape)
    stats = SampleStats(n=np.full(color.shape, 8.0), mean=color, var_mean=var,
                        m3=np.zeros(color.shape), transform=transform, lam=0.5)
    hdr = np.where(np.isfinite(color), color, den)
    fixed = np.where(np.isfinite(den), den, hdr)
    expected = kr.proden_gate(hdr, fixed, linear_variance(stats, color), pool_radius=4)
    got = kg.proden_gate_stats(color, den, stats, pool_radius=4)
    ok = np.isfinite(expected)
    np.testing.assert_allclose(got[ok], expected[ok], rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(kg.proden_gate_fast(hdr, fixed, linear_variance(stats, color),
                                                   pool_radius=4), expected, rtol=1e-6, atol=1e-7)


def test_variance_floor_keeps_a_good_denoiser_at_few_samples():
    """Heavy-tailed pixels at 8 samples: most pixels never drew the rare bright sample, so their
    own variance is far below the true one. An exact denoiser (the true mean) is then handed
    back to the noise in many pixels by the per-pixel test, in few with the floor; with no
    noise at all (zero variance everywhere) both still return the input."""
    rng = np.random.default_rng(8)
    h, w, n, p, big = 48, 48, 8, 0.02, 50.0
    draws = 1.0 + big * (rng.random((n, h, w, 3)) < p)
    color = draws.mean(0)
    var_mean = draws.var(0, ddof=1) / n
    truth = np.full((h, w, 3), 1.0 + big * p)
    off = lambda out: np.mean(np.abs(out - truth) > 0.5 * np.abs(color - truth) + 1e-9)
    plain = kr.proden_gate(color, truth, var_mean)
    floored = kr.proden_gate(color, truth, var_mean, pool_radius=5)
    assert np.mean((truth - floored) ** 2) < 0.5 * np.mean((truth - plain) ** 2)
    assert off(floored) < off(plain)
    zero = np.zeros_like(color)
    np.testing.assert_allclose(kr.proden_gate(color, truth, zero, pool_radius=5), color)


@pytest.mark.parametrize("shape,pool", [((1, 1), 5), ((3, 17), 2), ((37, 29), 5), ((12, 40), 7)])
def test_pooled_fast_gate_equals_reference(shape, pool):
    """The floor fused into the compiled passes (column sums, then the row pass) equals the
    reference gate on the SciPy-floored variance, with variances over many decades."""
    rng = np.random.default_rng(sum(shape) + pool)
    hdr = rng.gamma(1.0, 1.0, (*shape, 3)).astype(np.float32)
    den = (hdr * rng.uniform(0.7, 1.3, hdr.shape)).astype(np.float32)
    var = rng.lognormal(0.0, 3.0, hdr.shape) * 1e-4
    ref = kr.proden_gate(hdr, den, var, pool_radius=pool)
    np.testing.assert_allclose(kg.proden_gate_fast(hdr, den, var, pool_radius=pool), ref,
                               rtol=1e-6, atol=1e-7)


@pytest.mark.parametrize("pool", [0, 5])
def test_fast_gate_does_not_depend_on_the_rows_per_task(pool):
    """The compiled gate works on bands of rows, one per task, and the floor's column sums
    slide down each band from fixed anchor rows: every band height gives the same bits, and
    the reference's numbers, on an image tall enough for many bands and several anchors."""
    rng = np.random.default_rng(33)
    hdr = rng.gamma(1.0, 1.0, (157, 21, 3)).astype(np.float32)
    den = (hdr * rng.uniform(0.7, 1.3, hdr.shape)).astype(np.float32)
    var = rng.lognormal(0.0, 3.0, hdr.shape) * 1e-4
    var[60:64] *= 1e6  # a burst of huge variances that the sliding sums carry, then drop
    outs = [kg._gate_passes(hdr, den, var, None, False, False, 1.0, kr.GATE_K, kr.GATE_T0,
                            pool, band) for band in (11, 12, 31, 64, 157)]
    for out in outs[1:]:
        np.testing.assert_array_equal(out, outs[0])
    ref = kr.proden_gate(hdr, den, var, pool_radius=pool)
    np.testing.assert_allclose(outs[0], ref, rtol=1e-6, atol=1e-7)


@pytest.mark.parametrize("shape,pool,alpha", [((1, 1), 5, 1.0), ((3, 17), 0, 1.0),
                                              ((23, 9), 5, 0.4), ((40, 64), 0, 0.7),
                                              ((157, 21), 5, 1.0), ((64, 40), 2, 1.0),
                                              ((45, 30), 7, 0.8)])
def test_wiener_handback_fast_equals_reference(shape, pool, alpha):
    """The Wiener hand-back fused into the compiled band pass equals the readable SciPy form
    within float32 rounding of the image's values, and gives the same bits whatever the rows
    per task (bands start at the sliding sums' anchor rows); with the floor's window equal to
    the hand-back's (pool 5) or not (pool 0, 2, 7: the hand-back sums the variance itself)."""
    rng = np.random.default_rng(sum(shape) + pool)
    hdr = rng.gamma(1.0, 1.0, (*shape, 3)).astype(np.float32)
    den = (hdr * rng.uniform(0.7, 1.3, hdr.shape)).astype(np.float32)
    var = rng.lognormal(0.0, 3.0, hdr.shape) * 1e-3
    ref = kr.proden_gate(hdr, den, var, alpha=alpha, pool_radius=pool, handback="wiener")
    outs = [kg._gate_passes(hdr, den, var, None, False, False, alpha, kr.GATE_K, kr.GATE_T0,
                            pool, band, handback="wiener") for band in (None, 11, 40, 157)]
    for out in outs[1:]:
        np.testing.assert_array_equal(out, outs[0])
    np.testing.assert_allclose(outs[0], ref, rtol=1e-6, atol=1e-6 * np.abs(ref).max())
    spec = kr.proden_gate(hdr, den, var, alpha=alpha, pool_radius=pool)
    if shape[0] > 3 and alpha == 1.0:
        assert np.abs(ref - spec).max() > 1e-3  # the two rules differ here


def test_wiener_handback_limits():
    """α = 0 and zero variance return the input, a huge variance the method's output, as the
    spec's gate does (check 17)."""
    rng = np.random.default_rng(14)
    hdr = rng.random((16, 16, 3))
    den = hdr + 0.3 * rng.random(hdr.shape)
    for gate in (kr.proden_gate, kg.proden_gate_fast):
        np.testing.assert_allclose(gate(hdr, den, np.zeros_like(hdr), handback="wiener"), hdr,
                                   atol=1e-6)
        np.testing.assert_allclose(gate(hdr, den, np.full_like(hdr, 100.0), handback="wiener"),
                                   den, atol=1e-6)
        np.testing.assert_allclose(gate(hdr, den, np.full_like(hdr, 1e-3), alpha=0.0,
                                        handback="wiener"), hdr, atol=1e-6)


def test_wiener_handback_returns_the_bias_without_the_noise():
    """Two cases at the same noise: a method off by a constant everywhere (a local bias), and
    one whose error is a sharp pattern far above the noise. The spec's hand-back returns the
    whole residual, noise included; the Wiener one returns the local mean of the residual in
    the first case (less noise: far nearer the truth) and, in the second, where the residual's
    energy exceeds the noise's, about all of it, like the spec's gate."""
    rng = np.random.default_rng(5)
    h, w, sd = 64, 64, 0.05
    truth = np.full((h, w, 3), 1.0)
    hdr = truth + sd * rng.standard_normal(truth.shape)
    var = np.full(truth.shape, sd * sd)
    off = truth + 0.5  # biased everywhere by 10 standard errors
    err = lambda out: float(np.sqrt(np.mean((out - truth) ** 2)))
    spec = kr.proden_gate(hdr, off, var)
    wiener = kr.proden_gate(hdr, off, var, handback="wiener")
    assert err(spec) > 0.9 * sd and err(wiener) < 0.5 * sd
    stripes = truth + 0.5 * (np.arange(w) % 2)[None, :, None]  # a 2-pixel pattern: no local mean
    truth_hdr = stripes + sd * rng.standard_normal(truth.shape)
    spec = kr.proden_gate(truth_hdr, truth, var)
    wiener = kr.proden_gate(truth_hdr, truth, var, handback="wiener")
    assert np.abs(wiener - spec).max() < 0.1 * 0.5


@pytest.mark.parametrize("big", [1e20, 3e38])
def test_wiener_handback_stays_finite_near_the_float32_limit(big):
    """Squares of values near float32's limit overflow float32: the hand-back keeps its
    residual energies in float64, so finite inputs give finite outputs."""
    rng = np.random.default_rng(2)
    hdr = rng.random((30, 40, 3)).astype(np.float32)
    hdr[10:13, 10:13] = big
    den = (hdr * 0.5).astype(np.float32)
    var = np.full(hdr.shape, 1e-3)
    out = kg.proden_gate_fast(hdr, den, var, pool_radius=5, handback="wiener")
    assert np.isfinite(out).all()
