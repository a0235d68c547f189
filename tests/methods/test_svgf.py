"""svgf (docs/methods/svgf.md §9 checks, fast path vs reference, policies)."""
import numpy as np
import pytest

from dbench import registry
from dbench.run.sequence_run import run_sequence
from dbench.synthetic import synthetic_sequence
from dbench.data import Frame
from dbench.errors import DbenchInputError
from dbench.methods import svgf as C


def _planes(h, w, rng=None):
    """Two planes at depths 1 and 2 (a depth step at the middle column)."""
    z = np.where(np.arange(w)[None, :] < w // 2, 1.0, 2.0) * np.ones((h, 1))
    n = np.zeros((3, h, w))
    n[2] = 1
    hit = np.ones((h, w), bool)
    return z.astype(np.float32), n.astype(np.float32), hit


def _rand_inputs(rng, h, w):
    c = rng.random((3, h, w)).astype(np.float32)
    var = (0.1 * rng.random((h, w))).astype(np.float32)
    z = (1 + 0.1 * rng.random((h, w))).astype(np.float32)
    n = rng.normal(size=(3, h, w))
    n[2] += 8
    n /= np.linalg.norm(n, axis=0)
    hit = rng.random((h, w)) > 0.05
    z[~hit] = 0
    n[:, ~hit] = 0
    gx, gy = C.depth_gradient(z, hit)
    tap = hit & (rng.random((h, w)) > 0.02)
    centre = rng.random((h, w)) > 0.02
    return c, var, z, gx, gy, n.astype(np.float32), tap, centre, hit


def test_b3_kernel_sums():
    assert abs(C.H1.sum() - 1) < 1e-15
    h = np.outer(C.H1, C.H1)
    assert abs(h.sum() - 1) < 1e-15
    assert abs((h ** 2).sum() - 0.0747681) < 1e-7
    assert abs((h ** 2).sum() - (70 / 256) ** 2) < 1e-15


def test_unit_weights_give_the_b3_convolution_and_variance_factor():
    rng = np.random.default_rng(0)
    h, w = 12, 13
    c = rng.random((3, h, w))
    var = np.full((h, w), 2.0)
    z, n, hit = np.ones((h, w)), np.zeros((3, h, w)), np.ones((h, w), bool)
    n[2] = 1
    g0 = np.zeros((h, w))
    out, v = C.atrous_reference(c, var, z, g0, g0, n, hit, hit, hit, 1, sigma_z=1e30,
                                sigma_n=1.0, use_lum=False)
    k = np.outer(C.H1, C.H1)
    expect = sum(k[dy + 2, dx + 2] * c[:, 2 + dy:h - 2 + dy, 2 + dx:w - 2 + dx]
                 for dy in range(-2, 3) for dx in range(-2, 3))
    np.testing.assert_allclose(out[:, 2:-2, 2:-2], expect, rtol=0, atol=1e-12)
    np.testing.assert_allclose(v[2:-2, 2:-2], 0.0747681 * 2.0, rtol=1e-6)


@pytest.mark.parametrize("backend", ["reference", "numba"])
def test_constant_image_stays_constant(backend):
    rng = np.random.default_rng(1)
    args = list(_rand_inputs(rng, 17, 19))
    args[0] = np.full_like(args[0], 0.37)
    cur, var = args[0], args[1]
    for i in range(5):
        cur, var = C.atrous(backend, cur, var, *args[2:], 2 ** i)
        tol = 1e-12 if backend == "reference" else 1e-6
        assert np.abs(cur[:, args[7]] - 0.37).max() < tol
        assert (var >= 0).all()


def test_normal_weight_values():
    assert C.normal_weight(np.array(1.0), 128) == 1.0
    assert C.normal_weight(np.array(0.0), 128) == 0.0
    assert C.normal_weight(np.array(-1.0), 128) == 0.0
    assert abs(C.normal_weight(np.array(0.99), 128) - 0.2762) < 1e-4


@pytest.mark.parametrize("backend", ["reference", "numba"])
def test_depth_step_is_preserved(backend):
    h, w = 10, 16
    z, n, hit = _planes(h, w)
    gx, gy = C.depth_gradient(z, hit)
    c = np.where(z == 1.0, 0.2, 0.9)[None].repeat(3, 0).astype(np.float32)
    var = np.full((h, w), 0.5, np.float32)
    cur = c
    for i in range(5):
        cur, var = C.atrous(backend, cur, var, z, gx, gy, n, hit, hit, hit, 2 ** i)
    np.testing.assert_allclose(cur, c, atol=1e-6)


def test_fast_paths_equal_references():
    rng = np.random.default_rng(2)
    args = _rand_inputs(rng, 29, 41)
    for step in (1, 2, 8):
        for use_lum, kernel in ((True, "laplacian"), (True, "gaussian"), (False, "laplacian")):
            r = C.atrous_reference(*args, step, use_lum=use_lum, lum_kernel=kernel)
            f = C.atrous_fast(*args, step, use_lum=use_lum, lum_kernel=kernel)
            np.testing.assert_allclose(f[0], r[0], rtol=1e-4, atol=1e-5)
            np.testing.assert_allclose(f[1], r[1], rtol=1e-4, atol=1e-6)
    r = C.atrous_reference(*args, 1, sigma_n=100.0)
    f = C.atrous_fast(*args, 1, sigma_n=100.0)
    np.testing.assert_allclose(f[0], r[0], rtol=1e-4, atol=1e-5)
    c, _, z, gx, gy, n, tap, _, hit = args
    mom = np.stack([c[0], c[0] ** 2])
    np.testing.assert_allclose(C.spatial_variance_fast(mom, z, gx, gy, n, tap, hit),
                               C.spatial_variance_reference(mom, z, gx, gy, n, tap, hit),
                               rtol=1e-4, atol=1e-6)
    gr = C.depth_gradient(z, hit)
    gf = C.depth_gradient(z, hit, backend="numba")
    np.testing.assert_allclose(gf, gr, atol=1e-6)
    col = rng.random((29, 41, 3)).astype(np.float32) * 2
    col[3, 4] = np.nan
    alb = rng.random((29, 41, 3)).astype(np.float32)
    alb[0, 0] = (0, 5e-4, 3.0)
    emi = np.where(rng.random((29, 41, 1)) > 0.9, 4.0, 0.0) * np.ones(3, np.float32)
    pr, pf = C.prepare_reference(col, alb, emi, hit), C.prepare_fast(col, alb, emi, hit)
    for key in pr:
        np.testing.assert_allclose(pf[key], pr[key], rtol=1e-6, atol=1e-6, err_msg=key)


@pytest.mark.parametrize("kernel", ["laplacian", "gaussian"])
def test_a_pixel_whose_taps_all_have_subnormal_weights_stays_finite(kernel):
    """A pixel without its own sample (centre False) gathers only neighbours at 60° to its
    normal: w_n = 0.5^128 ≈ 3e-39 is subnormal in float32 and 1 / Σw overflowed to +Inf
    (output NaN on a black neighbourhood, Inf on a lit one). The reference gives their mean."""
    h = w = 9
    z, n, hit = _planes(h, w)
    z[:] = 1.0
    n[:, 4, 4] = (np.sin(np.pi / 3), 0.0, np.cos(np.pi / 3))
    tap = np.ones((h, w), bool)
    tap[4, 4] = False
    centre = tap.copy()
    gx = gy = np.zeros((h, w), np.float32)
    for value in (0.0, 1.0):
        c = np.full((3, h, w), value, np.float32)
        var = np.full((h, w), value, np.float32)
        args = (c, var, z, gx, gy, n, tap, centre, hit, 1)
        fast_c, fast_v = C.atrous_fast(*args, lum_kernel=kernel)
        ref_c, _ = C.atrous_reference(*args, lum_kernel=kernel)
        assert np.isfinite(fast_c).all() and np.isfinite(fast_v).all()
        np.testing.assert_allclose(fast_c[:, 4, 4], ref_c[:, 4, 4], rtol=1e-6)
        # the weights' squares underflow in float32, so its variance is 0 (the reference's
        # is the weighted mean's, 0.074 here): stated in atrous_fast's docstring
        assert 0.0 <= fast_v[4, 4] <= 1.0


def test_fast_exp_accuracy():
    from numba import njit

    @njit
    def ev(x):
        o = np.empty_like(x)
        for i in range(x.size):
            o[i] = C.fast_exp_neg(x[i])
        return o

    x = np.linspace(0, 30, 20001).astype(np.float32)
    rel = np.abs(ev(x) - np.exp(-x.astype(np.float64))) / np.exp(-x.astype(np.float64))
    assert rel.max() < 2e-5


def test_whole_method_fast_equals_reference():
    seq = synthetic_sequence(20, 26, frames=5)
    a, b = registry.get("svgf"), registry.get("svgf", backend="reference")
    a.reset()
    b.reset()
    for f in seq:
        oa, ob = a.denoise(f), b.denoise(f)
        np.testing.assert_allclose(oa, ob, rtol=2e-3, atol=2e-4)


def test_demodulation_keeps_texture_edges():
    seq = synthetic_sequence(40, 48, frames=10)
    flat = [f.with_buffers(albedo=np.ones_like(f.albedo)) for f in seq]
    from dbench.data import Sequence

    with_d = run_sequence("svgf", seq, warmup=4, keep_outputs=True)
    without = run_sequence("svgf", Sequence(flat), warmup=4, keep_outputs=True)
    alb = seq[-1].albedo[..., 0]
    edge = np.zeros(alb.shape, bool)
    edge[:, 1:] |= alb[:, 1:] != alb[:, :-1]
    edge[1:, :] |= alb[1:, :] != alb[:-1, :]
    from scipy.ndimage import binary_dilation
    band = binary_dilation(edge, iterations=2)
    ref = seq[-1].reference
    e1 = np.sqrt(((with_d.outputs[-1] - ref) ** 2)[band].mean())
    e2 = np.sqrt(((without.outputs[-1] - ref) ** 2)[band].mean())
    assert e1 <= e2


def test_svgf_beats_accumulate_and_noisy_on_a_synthetic_sequence():
    seq = synthetic_sequence(32, 40, frames=12)
    r = {n: run_sequence(n, seq, warmup=4).summary["mean_rmse"] for n in ("noisy", "accumulate",
                                                                         "svgf")}
    assert r["svgf"] < r["accumulate"] < r["noisy"]


def test_non_finite_colour_does_not_spread():
    seq = synthetic_sequence(16, 16, frames=3)
    m = registry.get("svgf")
    m.reset()
    for i, f in enumerate(seq):
        c = f.color.copy()
        c[5, 6] = np.nan
        c[9, 2, 1] = np.inf
        out = m.denoise(f.with_buffers(color=c))
        assert np.isfinite(out).all()


def test_emitters_are_not_filtered():
    h, w = 8, 8
    seq = synthetic_sequence(h, w, frames=2)
    f = seq[0]
    emi = np.zeros((h, w, 3), np.float32)
    emi[3:5, 3:5] = 50.0
    col = f.color.copy()
    col[3:5, 3:5] = 50.0
    m = registry.get("svgf")
    m.reset()
    out = m.denoise(f.with_buffers(color=col, emission=emi))
    np.testing.assert_allclose(out[3:5, 3:5], 50.0, rtol=1e-5)
    assert out[np.ones((h, w), bool) & (emi[..., 0] == 0)].max() < 10


@pytest.mark.parametrize("buffer,bad", [("albedo", np.zeros((4, 4))), ("motion", np.zeros((4, 4, 3))),
                                        ("emission", np.zeros((3, 4, 3)))])
def test_bad_shapes_name_the_buffer(buffer, bad):
    f = synthetic_sequence(4, 4, frames=1)[0]
    object.__setattr__(f, buffer, bad)
    with pytest.raises(DbenchInputError, match=buffer):
        registry.get("svgf").denoise(f)


def test_parameters_and_presets():
    m = registry.get("svgf", preset="falcor")
    assert m.params["sigma_l"] == 10 and m.params["iterations"] == 4
    assert registry.get("svgf", preset="falcor", sigma_l=3).params["sigma_l"] == 3
    for bad in (dict(preset="nope"), dict(sigma_l=-1), dict(iterations=1.5),
                dict(alpha_min=3), dict(backend="gpu")):
        with pytest.raises(DbenchInputError, match=list(bad)[0]):
            registry.get("svgf", **bad)


def test_single_image_runs_without_motion():
    f = synthetic_sequence(12, 12, frames=1)[0]
    f = f.with_buffers(motion=None)
    m = registry.get("svgf")
    m.reset()
    for _ in range(2):
        out = m.denoise(f)
    assert out.dtype == np.float32 and out.shape == f.color.shape and np.isfinite(out).all()
    assert (m.last["n"] == 1).all()


# -- the PyTorch backend (CPU tensors here; CUDA when present) ---------------------------------
# Kernel tolerances as for the Numba path: rtol 1e-4, atol 1e-5 (colour) / 1e-6 (variance).

def test_torch_kernels_equal_references():
    rng = np.random.default_rng(2)
    args = _rand_inputs(rng, 29, 41)
    for step in (1, 2, 8):
        for use_lum, kernel in ((True, "laplacian"), (True, "gaussian"), (False, "laplacian")):
            r = C.atrous_reference(*args, step, use_lum=use_lum, lum_kernel=kernel)
            t = C.atrous("torch", *args, step, use_lum=use_lum, lum_kernel=kernel)
            assert t[0].dtype == np.float32 and t[1].dtype == np.float32
            np.testing.assert_allclose(t[0], r[0], rtol=1e-4, atol=1e-5)
            np.testing.assert_allclose(t[1], r[1], rtol=1e-4, atol=1e-6)
    c, _, z, gx, gy, n, tap, _, hit = args
    mom = np.stack([c[0], c[0] ** 2])
    sel = rng.random(hit.shape) > 0.5
    np.testing.assert_allclose(C.spatial_variance("torch", mom, z, gx, gy, n, tap, hit, sel),
                               np.where(sel, C.spatial_variance_reference(mom, z, gx, gy, n, tap,
                                                                          hit), 0.0),
                               rtol=1e-4, atol=1e-6)
    np.testing.assert_allclose(C.depth_gradient(z, hit, backend="torch"), C.depth_gradient(z, hit),
                               atol=1e-6)
    col = rng.random((29, 41, 3)).astype(np.float32) * 2
    col[3, 4] = np.nan
    alb = rng.random((29, 41, 3)).astype(np.float32)
    alb[0, 0] = (0, 5e-4, 3.0)
    emi = np.where(rng.random((29, 41, 1)) > 0.9, 4.0, 0.0) * np.ones(3, np.float32)
    pr, pt = C.prepare_reference(col, alb, emi, hit), C.prepare("torch", col, alb, emi, hit)
    for key in pr:
        np.testing.assert_allclose(pt[key], pr[key], rtol=1e-6, atol=1e-6, err_msg=key)
    np.testing.assert_allclose(C.remodulate(pr["illum"], pr["a_eff"], pr["emission"], "torch"),
                               C.remodulate(pr["illum"], pr["a_eff"], pr["emission"], "reference"),
                               rtol=1e-6)


def test_whole_method_torch_equals_reference_over_a_hard_sequence():
    from test_accumulate import hard_sequence

    a, b = registry.get("svgf", backend="torch"), registry.get("svgf", backend="reference")
    a.reset()
    b.reset()
    seen = set()
    for f in hard_sequence(frames=6, fractional=False):  # disocclusion, NaN/Inf colour and motion
        oa, ob = a.denoise(f), b.denoise(f)
        assert oa.dtype == np.float32 and np.isfinite(oa).all()
        np.testing.assert_allclose(oa, ob, rtol=1e-4, atol=1e-5)
        np.testing.assert_allclose(a.last["variance"], b.last["variance"], rtol=1e-4, atol=1e-6)
        np.testing.assert_array_equal(a.last["status"], b.last["status"])
        seen |= set(np.unique(a.last["status"]).tolist())
    assert seen == {0, 1, 2}


def test_torch_backend_validation_and_auto(monkeypatch):
    import torch

    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    assert registry.get("svgf").backend == "numba"
    assert registry.get("svgf").params["backend"] == "numba"  # recorded resolved
    assert registry.get("svgf", backend="auto").backend == "numba"
    assert registry.get("svgf", backend="torch").backend == "torch"
    with pytest.raises(DbenchInputError, match="backend"):
        registry.get("svgf", backend="cuda")


# -- dbench preset: variance of the mean, no filtered feedback, footprint, emission (issue 16) --

def test_dbench_preset_and_auto_iterations():
    from dbench.methods.svgf.params import auto_iterations

    p = registry.get("svgf").params
    assert (p["preset"], p["variance_of"], p["feedback_tap"], p["iterations"]) == (
        "dbench", "mean", None, "auto")
    paper = registry.get("svgf", preset="paper").params
    assert (paper["variance_of"], paper["feedback_tap"], paper["iterations"]) == ("sample", 0, 5)
    assert [auto_iterations(s, s) for s in (16, 32, 64, 128, 256, 720)] == [1, 2, 3, 4, 5, 5]
    assert auto_iterations(64, 1280) == 3
    for bad in (dict(variance_of="pixel"), dict(feedback_tap=-1), dict(iterations="many")):
        with pytest.raises(DbenchInputError, match=list(bad)[0]):
            registry.get("svgf", **bad)


def test_variance_of_the_mean_follows_the_blend_weights():
    """Σw² of the accumulation: 1/N for the running mean up to 1/α_min = 5 frames, then the
    EMA recursion w² = α² + (1 − α)² w²← towards α/(2 − α) = 1/9."""
    seq = synthetic_sequence(8, 8, frames=30, shift=0)
    m = registry.get("svgf")
    m.reset()
    expected = None
    for i, f in enumerate(seq):
        m.denoise(f)
        a = max(0.2, 1.0 / (i + 1))
        expected = 1.0 if i == 0 else a * a + (1 - a) ** 2 * expected
        np.testing.assert_allclose(m.last["weight_sq"], expected, rtol=1e-5)
    assert abs(expected - 0.2 / 1.8) < 1e-3
    np.testing.assert_allclose(registry.get("svgf").params["alpha_min"], 0.2)


@pytest.mark.parametrize("name,boost", [("svgf", "svgf"), ("asvgf", "svgf"), ("asvgf", "asvgf"),
                                        ("asvgf", "gradient"), ("svgf", "gradient")])
def test_variance_boost_scales_the_estimate_of_short_histories(name, boost):
    """docs/temporal.md §15. "svgf" (Falcor's SVGFFilterMoments pass): a history of N < 4 frames
    takes the spatial estimate times 4/N (4, 2, 4/3 for N = 1, 2, 3), from N = 4 on the temporal
    estimate is untouched. "asvgf" (Schied's A-SVGF code): the standard deviation times
    max(1, 8/N), the variance times 64/N² up to N = 8, temporal estimates included.
    "gradient" (§18) on a new surface that no gradient shortens: Falcor's."""
    seq = synthetic_sequence(12, 12, frames=10, shift=0)
    var = {}
    for b in (False, boost):
        m = registry.get(name, variance_boost=b, iterations=0)
        m.reset()
        var[b] = []
        for f in seq:
            m.denoise(f)
            var[b].append(m.last["variance"].copy())
    n = np.arange(1, 11, dtype=np.float64)  # a static scene: N = 1, 2, … (A-SVGF: G = 0)
    factors = (np.maximum(1.0, 64.0 / n ** 2) if boost == "asvgf"
               else np.where(n < 4, 4.0 / n, 1.0))
    for i, factor in enumerate(factors):
        lit = var[False][i] > 1e-6
        assert lit.mean() > 0.5
        np.testing.assert_allclose(var[boost][i][lit], factor * var[False][i][lit], rtol=1e-5)


def test_variance_boost_defaults_and_values():
    boost = lambda name, **p: registry.get(name, **p).params["variance_boost"]  # noqa: E731
    assert boost("svgf") == boost("svgf", preset="falcor") == "svgf"
    assert boost("asvgf") == "gradient" and boost("asvgf", preset="falcor") == "svgf"
    assert boost("svgf", preset="paper") is False and boost("asvgf", preset="paper") is False
    assert boost("svgf", variance_boost=True) == "svgf"
    for bad in ("falcor", 0, None, 1.0):
        with pytest.raises(DbenchInputError, match="variance_boost"):
            registry.get("svgf", variance_boost=bad)


def test_variance_of_the_mean_blurs_less_once_converged():
    """On a converged history the luminance weights of the mean's variance keep a step that the
    per-sample variance lets the à-trous filter blur (the bias measured on orbit)."""
    h, w, n = 16, 16, 25
    rng = np.random.default_rng(3)
    clean = np.full((h, w, 3), 0.2, np.float32)
    clean[:, w // 2:] = 0.6
    g = dict(albedo=np.ones((h, w, 3), np.float32), depth=np.ones((h, w, 1)),
             normal=np.tile([0, 0, 1.0], (h, w, 1)), position=np.zeros((h, w, 3)),
             motion=np.zeros((h, w, 2)))
    frames = [Frame(color=clean * rng.exponential(1.0, (h, w, 1)).astype(np.float32),
                    reference=clean, **g) for _ in range(n)]
    err = {}
    for v in ("sample", "mean"):
        m = registry.get("svgf", variance_of=v, iterations=5)
        m.reset()
        outs = [m.denoise(f) for f in frames]
        err[v] = np.sqrt(np.mean([(o - clean) ** 2 for o in outs[-5:]]))
    assert err["mean"] < err["sample"]


