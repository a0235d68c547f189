"""bmfr's residual hand-back [dbench] (docs/temporal.md §9, §17; kernels/residual_handback.py)."""
import numpy as np
import pytest

from dbench import registry
from dbench.synthetic import synthetic_sequence
from dbench.data import Frame
from dbench.errors import DbenchInputError
from dbench.methods.bmfr import handback as HB
from dbench.methods.kernels import residual_handback as RH


def _images(seed, h=37, w=53):
    rng = np.random.default_rng(seed)
    z = rng.gamma(1.0, 1.0, (3, h, w)).astype(np.float32)
    y = (z + rng.normal(0, 0.3, z.shape)).astype(np.float32)
    var = rng.uniform(0, 0.2, z.shape).astype(np.float32)
    mask = rng.uniform(size=(h, w)) > 0.15
    return z, y, var, mask


@pytest.mark.parametrize("signed", [False, True])
@pytest.mark.parametrize("seed", [0, 1])
def test_fast_equals_reference(seed, signed):
    z, y, var, mask = _images(seed)
    var[:, ::7, ::5] = 0.0  # pixels without a variance of their own
    var[:, 2:7, 2:9] = 0.0  # and without one around them (V3 = 0: they count as noise)
    ref = RH.residual_handback_reference(z, y, var, mask, signed=signed)
    first = None
    for band in (1, 5, 16, 64):  # any band height: the same values to float32 rounding
        fast = RH.residual_handback_fast(z, y, var, mask, band=band, signed=signed)
        np.testing.assert_allclose(fast, ref, rtol=1e-5, atol=1e-5 * np.abs(ref).max())
        first = fast if first is None else first
        np.testing.assert_allclose(fast, first, rtol=1e-6, atol=1e-7)
    np.testing.assert_array_equal(ref[:, ~mask], y[:, ~mask])  # outside the mask: y


def test_clamp_is_the_unclamped_result_at_least_zero_on_both_paths():
    z, y, var, mask = _images(4)
    y -= np.float32(1.5)  # the fit and its hand-back below 0 in many pixels
    np.testing.assert_allclose(HB.handback(z, y, var, mask, True, clamp=True),
                               HB.handback(z, y, var, mask, False, clamp=True),
                               rtol=1e-5, atol=1e-5 * np.abs(z).max())
    y[1, 3, 4] = np.nan  # NaN stays NaN (and spreads over its window), as np.maximum leaves it
    for fast in (True, False):
        plain = HB.handback(z, y, var, mask, fast)
        clamped = HB.handback(z, y, var, mask, fast, clamp=True)
        assert (plain < 0).any() and np.isnan(plain[1, 3, 4])
        np.testing.assert_array_equal(clamped, np.maximum(plain, np.float32(0.0)))


def test_subnormal_variances_give_the_reference_not_nan():
    """Dark regions: residuals near 1e-19 and variances near 1e-38 (subnormal in float32,
    exact zeros among them). The compiled λ = excess / total divided as excess · (1 / total),
    and 1 / a subnormal total overflowed to +Inf: 0 · Inf = NaN on about a third of the
    pixels, where the reference gives 0."""
    rng = np.random.default_rng(0)
    z = (rng.random((3, 32, 32)) * 1e-19).astype(np.float32)
    y = np.zeros_like(z)
    var = (rng.random((3, 32, 32)) * 1e-38).astype(np.float32)
    var[rng.random(var.shape) < 0.3] = 0.0
    z[:, 10:20, 10:20] = 0.0
    mask = np.ones((32, 32), bool)
    for signed in (False, True):  # the signed rule's ratios: up to 1e-38 / 1e-45, capped
        fast = RH.residual_handback_fast(z, y - np.float32(2e-19), var, mask, signed=signed)
        ref = RH.residual_handback_reference(z, y - np.float32(2e-19), var, mask,
                                             signed=signed)
        assert np.isfinite(fast).all()
        np.testing.assert_allclose(fast, ref, rtol=1e-5, atol=1e-25)


def test_pixel_window_variance_equals_the_reference():
    z, _, _, mask = _images(2)
    need = np.random.default_rng(3).uniform(size=mask.shape) > 0.5
    ref = RH.window_variance_reference(z, mask)
    for yy, xx in zip(*np.nonzero(need)):
        for c in range(3):
            assert RH.pixel_window_variance(z, c, yy, xx, RH.HANDBACK_RADIUS, mask, mask) \
                == pytest.approx(ref[c, yy, xx], rel=1e-5, abs=1e-6)
    # a window with one valid sample has variance 0
    lone = np.zeros(mask.shape, bool)
    lone[10, 10] = True
    np.testing.assert_allclose(RH.window_variance_reference(z, lone)[:, 10, 10], 0.0, atol=1e-12)
    assert RH.pixel_window_variance(z, 0, 10, 10, RH.HANDBACK_RADIUS, lone, lone) == 0.0


@pytest.mark.parametrize("signed", [False, True])
def test_limits_zero_variance_gives_z_and_zero_residual_gives_y(signed):
    z, y, var, mask = _images(4)
    for rule in (RH.residual_handback_reference, RH.residual_handback_fast):
        out = rule(z, y, np.zeros_like(var), mask, signed=signed)  # a converged history
        np.testing.assert_allclose(out[:, mask], z[:, mask], rtol=1e-5, atol=1e-5)
        out = rule(z, z, var, mask, signed=signed)
        np.testing.assert_allclose(out, z, rtol=1e-6, atol=1e-6)


def test_signed_gain_of_a_known_window():
    """var = 1 and high = ∓2 everywhere: the pooled λ = (4 − 1) / (3 + 1) = 0.75 on both sides;
    below the fit m = 4 and λ_neg = 1 − 1 / (2 · 4) = 0.875. Where every negative part is
    within its noise (m ≤ ½) λ_neg is 0 and the pooled λ stays. A pixel whose own variance
    collapsed (var = 0) is weighed against its neighbours' (V3 = 8/9), so it cannot outvote its
    window: far below the fit it gives the same λ as far above it."""
    mask = np.ones((21, 21), bool)
    var = np.ones((3, 21, 21))
    np.testing.assert_allclose(RH.signed_gain(np.full((3, 21, 21), 2.0), var, mask), 0.75)
    np.testing.assert_allclose(RH.signed_gain(np.full((3, 21, 21), -2.0), var, mask), 0.875)
    high = np.full((3, 21, 21), 0.5)
    high[:, 10, 10] = -0.9  # the only negative part: m = 0.81 / 49
    lam = RH.signed_gain(high, var, mask)
    assert lam[0, 10, 10] == pytest.approx(0.0)  # pooled: 0.25·48/49 + 0.81/49 − 1 < 0
    var[:, 10, 11] = 0.0
    high[:, 10, 11] = 3.0
    above = RH.signed_gain(high, var, mask)[:, 10, 10]
    high[:, 10, 11] = -3.0  # m = (9 / (8/9) + 0.81 / (8/9)) / 49 < ½
    np.testing.assert_allclose(RH.signed_gain(high, var, mask)[:, 10, 10], above)


def test_signed_rule_returns_a_dark_shadow_beside_a_noisy_floor():
    """The case of docs/temporal.md §16-17: a 3-px shadow (truth 0.04, sd 0.03) beside a lit
    floor (truth 0.4, sd 0.4) that the fit misses (y = 0.4 there too). The pooled test weighs the
    shadow's residual against the floor's noise and returns little of it; the signed rule
    returns most. Where the fit is right, with noise skewed like 1-spp radiance and a firefly,
    it hands back no more noise than the pooled test (within 5 %)."""
    rng = np.random.default_rng(7)
    h, w = 48, 48
    truth = np.full((3, h, w), 0.4, np.float32)
    sd = np.full(truth.shape, 0.4, np.float32)
    truth[:, :, 20:23], sd[:, :, 20:23] = 0.04, 0.03
    z = (truth + rng.normal(0, 1, truth.shape) * sd).astype(np.float32)
    var = (sd * sd).astype(np.float32)
    mask = np.ones((h, w), bool)
    fit = np.full_like(truth, 0.4)
    shadow = (lambda a: float(np.abs(a[:, :, 20:23] - truth[:, :, 20:23]).mean()))
    pooled = RH.residual_handback_fast(z, fit, var, mask)
    signed = RH.residual_handback_fast(z, fit, var, mask, signed=True)
    assert shadow(signed) < 0.5 * shadow(pooled)  # 0.024 against 0.066
    assert shadow(pooled) > 2.5 * shadow(z) and shadow(signed) < 1.05 * shadow(z)
    # the fit right, the noise a gamma of shape 0.5 (mean 1, long bright tail) and a firefly
    z = rng.gamma(0.5, 2.0, truth.shape).astype(np.float32)
    z[:, 10, 10] = 50.0
    var = np.full(truth.shape, 2.0, np.float32)
    rmse = (lambda a: float(np.sqrt(((a - 1.0) ** 2).mean())))
    pooled = RH.residual_handback_fast(z, np.ones_like(z), var, mask)
    signed = RH.residual_handback_fast(z, np.ones_like(z), var, mask, signed=True)
    assert rmse(signed) < 1.05 * rmse(pooled) and rmse(pooled) < 0.7 * rmse(z)
    assert signed[0, 10, 10] == pytest.approx(pooled[0, 10, 10], rel=1e-6)


def test_noise_stays_out_and_bias_goes_back():
    """y the truth and z = truth + noise of known variance: the hand-back keeps most of the
    noise out. y biased by a 2-px stripe (a fit across a contact shadow): most of the bias goes
    back."""
    rng = np.random.default_rng(5)
    h, w = 64, 64
    truth = np.ones((3, h, w), np.float32)
    truth[:, :, 30:32] = 0.1  # the stripe
    sd = 0.05
    z = (truth + rng.normal(0, sd, truth.shape)).astype(np.float32)
    var = np.full(truth.shape, sd * sd, np.float32)
    mask = np.ones((h, w), bool)
    rmse = (lambda a: float(np.sqrt(((a - truth) ** 2).mean())))
    out = RH.residual_handback_fast(z, truth, var, mask)
    assert rmse(out) < 0.35 * rmse(z)
    biased = np.ones_like(truth)  # the fit missed the stripe
    out = RH.residual_handback_fast(z, biased, var, mask)
    assert rmse(out) < 0.25 * rmse(biased)
    assert rmse(out) < rmse(z)


def test_weight_sq_is_the_variance_factor_of_the_mean():
    ok = np.ones((1, 1), bool)
    s = np.ones((1, 1), np.float32)
    for n in range(2, 9):  # running mean: α = 1/N gives S = 1/N
        s = HB.weight_sq(np.full((1, 1), 1.0 / n, np.float32), s, ok)
        assert s[0, 0] == pytest.approx(1.0 / n, rel=1e-5)
    for _ in range(200):  # EMA limit α/(2 − α)
        s = HB.weight_sq(np.full((1, 1), 0.2, np.float32), s, ok)
    assert s[0, 0] == pytest.approx(0.2 / 1.8, rel=1e-5)
    # a missing sample (α = 0) keeps S; a reset (α = 1, no history) gives 1
    assert HB.weight_sq(np.zeros((1, 1), np.float32), s, ok)[0, 0] == s[0, 0]
    assert HB.weight_sq(np.ones((1, 1), np.float32), s, ~ok)[0, 0] == 1.0


def test_short_histories_take_the_spatial_variance():
    rng = np.random.default_rng(6)
    illum = rng.gamma(1.0, 1.0, (3, 20, 20)).astype(np.float32)
    z, zz = illum.copy(), illum * illum  # one sample: the temporal moments give 0
    fit = np.ones((20, 20), bool)
    s = np.ones((20, 20), np.float32)
    var = HB.illumination_variance(illum, z, zz, s, fit, fit)
    np.testing.assert_allclose(var, RH.window_variance_reference(illum, fit), rtol=1e-5,
                               atol=1e-6)
    s_long = np.full((20, 20), 0.1, np.float32)  # 10 effective samples: the temporal moments
    var = HB.illumination_variance(illum, z, zz + 1.0, s_long, fit, fit)
    np.testing.assert_allclose(var, 0.1, rtol=1e-5)


@pytest.mark.parametrize("seed", [7, 8])
def test_fused_moments_equal_the_readable_chain(seed):
    """moments_fast (one compiled pass) against accumulate + weight_sq + illumination_variance,
    with resets, missing samples, short and long histories."""
    rng = np.random.default_rng(seed)
    h, w = 23, 31
    illum = rng.gamma(1.0, 1.0, (3, h, w)).astype(np.float32)
    hist = np.concatenate([rng.gamma(1.0, 2.0, (3, h, w)),
                           rng.uniform(0.01, 1.0, (1, h, w))]).astype(np.float32)
    z_acc = rng.gamma(1.0, 1.0, (3, h, w)).astype(np.float32)
    ok = rng.uniform(size=(h, w)) > 0.2
    present = rng.uniform(size=(h, w)) > 0.1
    fit = rng.uniform(size=(h, w)) > 0.1
    n_hist = np.where(ok, rng.integers(0, 30, (h, w)), 0).astype(np.float32)
    from dbench.methods import temporal as T

    _, _, alpha = T.accumulate_any("reference", illum, z_acc, n_hist, ok, 0.2, T.N_MAX, None,
                                   present)
    ref = HB.moments_reference("reference", illum, z_acc, alpha, hist, n_hist, ok, present, fit,
                               0.2, T.N_MAX, None)
    out_hist = np.empty((4, h, w), np.float32)
    var = np.empty((3, h, w), np.float32)
    fast = HB.moments_fast(illum, z_acc, alpha, hist, ok, present, fit, out_hist, var)
    for a, b in zip(fast, ref):
        np.testing.assert_allclose(a, b, rtol=2e-5, atol=1e-6)
    assert (ref[1] * HB.MIN_TEMPORAL_SAMPLES > 1).any() and (ref[1] < 0.25).any()


def _shadow_sequence(frames, noisy, seed=0):
    """A static 64² wall with a 2-px contact shadow the block fit cannot follow."""
    h = w = 64
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    clean = np.full((h, w, 3), 0.6)
    clean[:, 40:42] = 0.05
    g = dict(albedo=np.ones((h, w, 3)), depth=np.ones((h, w, 1)),
             normal=np.tile([0, 0, 1.0], (h, w, 1)),
             position=np.dstack([x / w, y / h, np.zeros((h, w))]), motion=np.zeros((h, w, 2)))
    out = []
    for _ in range(frames):
        color = clean * rng.exponential(1.0, (h, w, 1)) if noisy else clean
        out.append(Frame(color=color, reference=clean, **g))
    return out


def _late_rmse(method, frames=24, skip=12):
    """Mean RMSE of ``method`` over the noisy shadow sequence's frames from ``skip`` on."""
    method.reset()
    errors = []
    for i, f in enumerate(_shadow_sequence(frames, noisy=True, seed=1)):
        out = method.denoise(f)
        if i >= skip:
            errors.append(float(np.sqrt(((out - f.reference) ** 2).mean())))
    return float(np.mean(errors))


def test_bmfr_converges_to_its_accumulation_where_the_fit_is_biased():
    """Fed a clean image, the paper's BMFR keeps its block fit's bias; with the hand-back the
    output converges to the input (from the 4th frame its fit is handed back whole; the second
    accumulation forgets the first frames at 0.9 a frame). With noise, the hand-back is below
    the paper's output and below the first accumulation."""
    err = {}
    for rule in ("none", "wiener", "signed"):
        m = registry.get("bmfr", handback=rule)
        m.reset()
        for f in _shadow_sequence(48, noisy=False):
            out = m.denoise(f)
        err[rule] = float(np.sqrt(((out - f.reference) ** 2).mean()))
    assert err["none"] > 0.05 and err["wiener"] < 0.01 * err["none"]
    assert err["signed"] < 0.01 * err["none"]
    late = {rule: _late_rmse(registry.get("bmfr", handback=rule))
            for rule in ("none", "wiener", "signed")}
    accumulated = _late_rmse(registry.get("accumulate", alpha_min=0.2))
    # with this wall's exponential noise a pixel whose recent samples were low has a low z and
    # a low variance estimate at once; the signed rule's 3×3 noise does not share that streak
    # (docs/temporal.md §17: with each pixel's own variance the lit part's error rose by half)
    for rule in ("wiener", "signed"):
        assert late[rule] < 0.8 * late["none"]
        assert late[rule] < accumulated
    assert late["signed"] < 1.05 * late["wiener"]


def test_backends_agree_with_the_hand_back_and_history_planes():
    from test_accumulate import hard_sequence

    ms = {b: registry.get("bmfr", backend=b) for b in ("numba", "reference", "torch")}
    for m in ms.values():
        m.reset()
    for f in hard_sequence(24, 40, frames=5):  # disocclusion, NaN/Inf colour and motion
        outs = {b: m.denoise(f) for b, m in ms.items()}
        for b in ("reference", "torch"):
            np.testing.assert_allclose(outs["numba"], outs[b], rtol=1e-4, atol=1e-5)
        assert np.isfinite(outs["numba"]).all() and (outs["numba"] >= 0).all()
    emissive = getattr(f, "emission", None) is not None
    # Z (3), N, the fit (3), Z² (3) and S; the emission (3) only with an emission buffer
    assert ms["numba"].history.buffers.shape[0] == 7 + HB.EXTRA_PLANES + 3 * emissive
    frame = synthetic_sequence(8, 8, frames=1)[0]
    for emission, planes in ((None, 7), (np.zeros((8, 8, 3), np.float32), 10)):
        plain = registry.get("bmfr", handback="none")
        plain.reset()
        plain.denoise(frame.with_buffers(emission=emission) if emission is not None else frame)
        assert plain.history.buffers.shape[0] == planes


def test_handback_parameter_is_checked():
    with pytest.raises(DbenchInputError, match="handback"):
        registry.get("bmfr", handback="pixel")
    assert registry.get("bmfr").params["handback"] == "signed"
