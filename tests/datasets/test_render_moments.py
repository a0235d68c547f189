"""The one-pass render kernel (dbench/datasets/render_moments.py; README.md, "How renders work"):
its in-kernel power sums equal a per-sample float64 computation on the very samples it summed,
for every transform; each sample stays in its own pixel; its colour and its references agree
with the host path within their Monte Carlo error (against Mitsuba's own render:
tests/datasets/test_render.py)."""
import numpy as np
import pytest

from dbench.datasets import render, render_moments
from dbench.datasets.scenes import catalogue as scenes
from dbench.datasets.scenes.record import Scene
from dbench.datasets.stats import PowerSums, transform_of_zero, transform_samples

pytestmark = pytest.mark.mitsuba

TRANSFORMS = [("identity", 1.0), ("box-cox", 0.5), ("box-cox", 0.25), ("box-cox", 1.5),
              ("yeo-johnson", 0.5), ("yeo-johnson", 0.0), ("yeo-johnson", 2.0),
              ("yeo-johnson", -1.5)]
#: Float64 sums of the same samples in another order and with Dr.Jit's own pow/log/sqrt:
#: measured ≤ 3e-14 relative; 1e-12 leaves room and is still 6 orders below the 1e-6 the
#: statistics are held to (tests/datasets/test_render.py).
RTOL = 1e-12
#: Rounding of one transformed sample in ulps: PowerSums forms u = g(x) − g(0) as a difference
#: ((x^λ − 1)/λ + 1/λ for Box-Cox), which costs a few ulps of |g(0)| where u is small; the kernel
#: forms x^λ/λ directly. The bound below charges that to the reference, not the kernel.
ULPS = 8


@pytest.fixture(scope="module")
def jit(renderer):
    if not render_moments.jit_variant(renderer.variant()):
        pytest.skip("the one-pass kernel needs a JIT variant")
    return renderer


def _close(got, want, rtol=RTOL, atol=0.0):
    err = np.abs(got - want)
    bound = rtol * np.abs(want) + atol
    assert np.all(err <= bound), float(np.max(err - bound))


def _power_sum_bounds(samples, axis, transform, lam):
    """Per element, how far float64 rounding of the per-sample terms may move S1, S2, S3: a
    sample's u is good to ULPS·eps·(|g(0)| + |u|); u^p then moves by p·|u|^(p−1) times that."""
    u = transform_samples(samples, transform, lam) - transform_of_zero(transform, lam)
    d = ULPS * np.finfo(np.float64).eps * (abs(transform_of_zero(transform, lam)) + np.abs(u))
    return [np.sum(p * np.abs(u) ** (p - 1) * d, axis=axis) for p in (1, 2, 3)]


@pytest.mark.parametrize("transform,lam", TRANSFORMS)
def test_kernel_sums_equal_per_sample_float64_on_its_own_samples(jit, transform, lam):
    sc = render.loaded_scene(scenes.get("cornell"), render.parse_res(12))
    b = render_moments.batch_sums(sc, 16, seed=5, stats=(transform, lam), keep_samples=True)
    assert b.samples.shape == (12, 12, 16, 3) and b.samples.dtype == np.float32
    ref = PowerSums((12, 12, 3), transform, lam)
    for j in range(16):  # the readable per-sample definition (stats.PowerSums.add)
        ref.add(b.samples[:, :, j])
    _close(b.plain, b.samples.astype(np.float64).sum(axis=2))
    bounds = _power_sum_bounds(b.samples.astype(np.float64), 2, transform, lam)
    for got, want, atol in zip((b.s1, b.s2, b.s3), (ref.s1, ref.s2, ref.s3), bounds):
        _close(got, want, atol=atol)
    assert (b.n_nonfinite, b.n_clamped) == (ref.n_nonfinite, ref.n_clamped)


@pytest.mark.parametrize("transform,lam", TRANSFORMS)
def test_accumulate_edge_rules_equal_power_sums(jit, transform, lam):
    # NaN, ±inf, negatives, zeros and a wide range of magnitudes, as PowerSums treats them
    mi = jit
    rng = np.random.default_rng(1)
    n_px, m = 50, 8
    x = (rng.standard_normal((n_px, m, 3)) * 10.0 ** rng.uniform(-6, 3, (n_px, m, 3)))
    x = x.astype(np.float32)
    x[0, 0, 0], x[1, 2, 1], x[2, 3, 2], x[3] = np.nan, np.inf, -np.inf, 0.0
    rgb = mi.Color3f(*(mi.Float(np.ascontiguousarray(x[..., c].reshape(-1))) for c in range(3)))
    pixel = mi.UInt32(np.repeat(np.arange(n_px, dtype=np.uint32), m))
    sums, counts = render_moments.accumulate(rgb, pixel, n_px, (transform, lam))
    got = {k: v.numpy().reshape(n_px, 3) for k, v in sums.items()}
    ref = PowerSums((n_px, 3), transform, lam)
    for j in range(m):
        ref.add(x[:, j])
    _close(got["plain"], np.where(np.isfinite(x), x, 0).astype(np.float64).sum(axis=1))
    xf = np.where(np.isfinite(x), x, 0).astype(np.float64)
    if transform == "box-cox":
        xf = np.maximum(xf, 0.0)
    for k, atol in zip(("s1", "s2", "s3"), _power_sum_bounds(xf, 1, transform, lam)):
        _close(got[k], getattr(ref, k), atol=atol)
    n_bad, n_clamped = (int(v) for v in counts.numpy())
    assert n_bad == ref.n_nonfinite == 3
    assert n_clamped == ref.n_clamped
    assert (n_clamped > 0) == (transform == "box-cox")


@pytest.mark.parametrize("integrator", ["path", "direct", "volpath", "prb", "depth"])
def test_one_batch_is_mitsubas_own_render_at_the_same_seed(jit, integrator):
    # the kernel draws its samples in mi.render's order (pixel-major wavefront, independent
    # sampler, position first), so one batch of m spp at seed s is mi.render(spp=m, seed=s)
    # up to the film's float32 accumulation, for C++ and Python (prb) integrators alike
    mi = jit
    d = scenes.get("cornell").scene_dict(mi, render.parse_res(16))
    d["sensor"] = {**d["sensor"], "sampler": {"type": "independent"}}
    d["integrator"] = {"type": integrator}
    sc = mi.load_dict(d)
    b = render_moments.batch_sums(sc, 64, seed=11)
    plain = np.array(mi.render(sc, spp=64, seed=11), dtype=np.float64)
    np.testing.assert_allclose(b.plain / 64, plain, rtol=2e-5, atol=1e-6)


def test_a_python_integrator_is_told_apart_after_a_variant_switch(jit):
    """With mitransient imported (any transient render), a switch of Mitsuba's variant and back
    (a scene file that sets it is refused and the variant put back) left ``prb`` no instance of
    ``mi.ad``'s ADIntegrator: the kernel called it as a C++ integrator and failed."""
    mi = jit
    pytest.importorskip("mitransient")
    mine = mi.variant()
    other = "scalar_rgb" if mine != "scalar_rgb" else "llvm_ad_rgb"
    if other not in mi.variants():
        pytest.skip(f"{other} is not compiled into this Mitsuba")
    mi.set_variant(other)
    mi.set_variant(mine)
    d = scenes.get("cornell").scene_dict(mi, render.parse_res(8))
    d["sensor"] = {**d["sensor"], "sampler": {"type": "independent"}}
    d["integrator"] = {"type": "prb"}
    sc = mi.load_dict(d)
    b = render_moments.batch_sums(sc, 4, seed=11)
    plain = np.array(mi.render(sc, spp=4, seed=11), dtype=np.float64)
    np.testing.assert_allclose(b.plain / 4, plain, rtol=2e-5, atol=1e-6)


def _edge_scene(mi, res):
    # a lit rectangle covering exactly the left half of the view (its edge on the centre
    # line of an even-width image): a sample that strayed into a neighbouring pixel, or a
    # position drawn outside its pixel, would mix 0 and 2 in the two middle columns
    return {"type": "scene",
            "sensor": scenes.camera_dict(mi, res, origin=[0, 0, 4], target=[0, 0, 0]),
            "lamp": {"type": "rectangle",
                     "to_world": mi.ScalarTransform4f().translate([-50.0, 0.0, 0.0])
                     @ mi.ScalarTransform4f().scale([50.0, 50.0, 1.0]),
                     "emitter": {"type": "area",
                                 "radiance": {"type": "rgb", "value": [2.0, 2.0, 2.0]}}}}


def test_every_sample_stays_in_its_own_pixel(jit):
    edge = Scene("edge", "steady", "test", _edge_scene, max_depth=1)
    x = np.concatenate(list(render.sample_batches(edge, 16, 32, seed=2)), axis=1)
    assert set(np.unique(x)) <= {0.0, 2.0}
    lit = (x == 2.0).all(axis=(0, 1, 3))
    dark = (x == 0.0).all(axis=(0, 1, 3))
    # every column is all-lit or all-dark, and exactly half of them are lit
    assert np.all(lit | dark) and lit.sum() == 8


def _z(a, var_a, b, var_b):
    var = var_a + var_b
    ok = var > 0
    # no spread at all: both see the same constant (a light), up to float32 rounding
    np.testing.assert_allclose(a[~ok], b[~ok], rtol=1e-6)
    return (a[ok] - b[ok]) / np.sqrt(var[ok])


def test_kernel_colour_agrees_with_the_host_path_at_equal_spp(jit):
    # different random numbers, the same estimator: per-pixel differences are Monte Carlo
    # noise of the two means, whose variances both paths' identity statistics give
    sc = scenes.get("cornell")
    a, sa, _ = render.render_passes(sc, 24, 128, seed=4, stats=("identity", 1.0),
                                    progress=False, kernel=True)
    b, sb, _ = render.render_passes(sc, 24, 128, seed=4, stats=("identity", 1.0),
                                    progress=False, kernel=False)
    np.testing.assert_allclose(a, sa.mean, rtol=1e-6, atol=1e-7)
    z = _z(sa.mean, sa.var_mean, sb.mean, sb.var_mean)
    # heavy-tailed path-tracing samples: a loose per-pixel bound, a tight one on the average
    assert np.mean(np.abs(z) > 4) < 0.01
    assert abs(z.mean()) < 4 / np.sqrt(z.size) + 0.05


def test_reference_from_kernel_chunks_agrees_with_the_noisy_render(jit):
    sc = scenes.get("cornell")
    ref, ref_var, _ = render.render_reference(sc, 16, 512, seed=3, chunk=32, progress=False)
    assert ref.shape == (16, 16, 3) and np.all(np.isfinite(ref))
    assert np.all(ref_var >= 0) and ref_var.mean() > 0
    color, st, _ = render.render_passes(sc, 16, 512, seed=9, stats=("identity", 1.0),
                                        progress=False)
    z = _z(ref.astype(np.float64), ref_var.astype(np.float64), color.astype(np.float64),
           st.var_mean)
    assert np.mean(np.abs(z) > 5) < 0.02
    assert abs(z.mean()) < 4 / np.sqrt(z.size) + 0.1
    # the chunk spread estimates the same variance of the mean as the samples do
    ratio = ref_var.mean() / st.var_mean.mean()
    assert 0.5 < ratio < 2.0


def test_several_batches_add_up_to_the_samples_of_all(jit, monkeypatch):
    # a small batch bound forces 4 kernels of 2 spp, each with its own seed
    monkeypatch.setattr(render, "MAX_BATCH_PIXELS", 2 * 16 * 16)
    sc = scenes.get("cornell")
    assert render.batch_size(16, 8) == 2
    color, st, timing = render.render_passes(sc, 16, 8, seed=1, stats=("box-cox", 0.5),
                                             progress=False)
    x = np.concatenate(list(render.sample_batches(sc, 16, 8, seed=1)), axis=1)
    assert x.shape == (16, 8, 16, 3) and timing["copies"] == 2 and np.all(st.n == 8)
    np.testing.assert_allclose(color, x.astype(np.float64).mean(axis=1), rtol=1e-6, atol=1e-7)
    ref = PowerSums((16, 16, 3), "box-cox", 0.5)
    ref.add_batch(x, axis=1)
    want = ref.finalize()
    np.testing.assert_allclose(st.mean, want.mean, rtol=1e-9)
    np.testing.assert_allclose(st.var_mean, want.var_mean, rtol=1e-6, atol=1e-15)


def test_the_sampling_version_is_part_of_a_steady_cells_identity(renderer, monkeypatch):
    """How the noisy samples are drawn changes every number of a cell, so it is in the scene
    fingerprint a sweep cell carries (and in the noisy and reference cache keys)."""
    from dbench import datasets

    before = datasets.scene_fingerprint("cornell", 8)
    monkeypatch.setattr(render, "SAMPLES_VERSION", render.SAMPLES_VERSION + "-other")
    assert datasets.scene_fingerprint("cornell", 8) != before
