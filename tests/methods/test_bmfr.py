"""bmfr: Householder least squares and the blockwise fit (docs/methods/bmfr.md §8 checks)."""
import numpy as np
import pytest

from dbench import registry
from dbench.run.sequence_run import run_sequence
from dbench.synthetic import synthetic_sequence
from dbench.errors import DbenchInputError
from dbench.methods import bmfr as B
from dbench.methods.bmfr import householder_lstsq

WORKED = np.array([[1, 5.5, 6.5, 1.2, 0.5], [1, 5.6, 6.5, 1.4, 0.4], [1, 5.7, 6.4, 1.2, 0.65],
                   [1, 5.4, 6.3, 1.3, 0.8], [1, 5.7, 6.2, 1.4, 0.62], [1, 5.4, 6.3, 1.3, 0.55]])


@pytest.mark.parametrize("backend", ["numba", "reference", "torch"])
def test_equals_numpy_lstsq_on_random_full_rank_batches(backend):
    rng = np.random.default_rng(0)
    for m, n, c in ((1024, 10, 3), (40, 7, 1), (13, 13, 2)):
        A = rng.normal(size=(30, m, n))
        Bm = rng.normal(size=(30, m, c))
        X = householder_lstsq(A, Bm, backend=backend)
        ref = np.stack([np.linalg.lstsq(a, b, rcond=None)[0] for a, b in zip(A, Bm)])
        np.testing.assert_allclose(X, ref, rtol=1e-9, atol=1e-9)


def test_worked_example_and_residual():
    T, z = WORKED[:, :4], WORKED[:, 4:]
    for backend in ("numba", "reference", "torch"):
        X = householder_lstsq(T, z, backend=backend)
        np.testing.assert_allclose(X[:, 0], [7.9178571, -0.0994286, -0.9105714, -0.7554286],
                                   atol=1e-7)
        np.testing.assert_allclose(X, np.linalg.lstsq(T, z, rcond=None)[0], atol=1e-10)
    # residual norm = ‖R̃[M:, M]‖ and the |diag R| of the spec
    R = np.concatenate([T, z], 1)[None].copy()
    Xr, _ = B.householder_lstsq_reference(R[..., :4], R[..., 4:])
    assert abs(np.linalg.norm(T @ Xr[0] - z) - 0.1891462) < 1e-7
    X1, _ = B.householder_lstsq_reference(T[None], z[None], stable_sign=False)
    np.testing.assert_allclose(X1, Xr, atol=1e-9)  # the seed's sign convention, same solution


def test_shared_r_equals_independent_solves():
    rng = np.random.default_rng(1)
    A, Bm = rng.normal(size=(5, 200, 10)), rng.normal(size=(5, 200, 3))
    X = householder_lstsq(A, Bm)
    for q in range(3):
        np.testing.assert_allclose(X[..., q:q + 1], householder_lstsq(A, Bm[..., q:q + 1]),
                                   atol=1e-12)


def _flat_wall(size=32, noise=0.0, rng=None):
    """A fronto-parallel wall block: all normals (0, 0, 1), P_z constant."""
    y, x = np.mgrid[0:size, 0:size].astype(np.float64)
    normal = np.zeros((3, size, size))
    normal[2] = 1.0
    pos = np.stack([x * 0.01, y * 0.01, np.full((size, size), 2.0)])
    feats, scaled = B.feature_stack(normal.astype(np.float32), pos.astype(np.float32))
    return feats, scaled, pos


def test_rank_deficient_flat_wall_block():
    feats, scaled, pos = _flat_wall()
    T = feats.reshape(10, -1).T.astype(np.float64)
    assert np.linalg.matrix_rank(T) < 10
    rng = np.random.default_rng(2)
    truth = (0.3 + 0.5 * pos[0] - 0.2 * pos[1])[None].repeat(3, 0)
    z = (truth + 0.1 * rng.normal(size=truth.shape)).astype(np.float32)
    mask = np.ones(z.shape[1:], bool)
    out, dropped = B.bmfr_fit_fast(z, feats, scaled, mask, mask, 32, (0, 0), 0.01, 3,
                                   clamp=False)
    assert np.isfinite(out).all() and dropped == 0  # the noise makes it full rank
    err_fit = np.sqrt(((out - truth) ** 2).mean())
    err_mean = np.sqrt(((z.mean(axis=(1, 2), keepdims=True) - truth) ** 2).mean())
    assert err_fit <= err_mean and err_fit < 1e-2 + 0.1 / np.sqrt(1024) * 4
    # without noise, identical rows trigger the safeguard, the fit stays finite
    out0, dropped0 = B.bmfr_fit_fast(z, feats, scaled, mask, mask, 32, (0, 0), 0.0, 3)
    assert dropped0 > 0 and np.isfinite(out0).all()


def test_small_block_with_identical_rows_triggers_the_safeguard_only_without_noise():
    A = np.ones((1, 36, 7))
    A[0, :, 1:] = 0.5
    z = np.full((1, 36, 3), 0.7)
    _, dropped = householder_lstsq(A, z, return_dropped=True)
    assert dropped[0] > 0
    rng = np.random.default_rng(3)
    An = A.copy()
    An[0, :, 1:] += rng.uniform(-0.01, 0.01, size=(36, 6))
    X, dropped = householder_lstsq(An, z, return_dropped=True)
    assert dropped[0] == 0 and np.isfinite(X).all()


def test_exact_in_the_span_and_constant_image():
    feats, scaled, pos = _flat_wall()
    px = (pos[0] - pos[0].min()) / max(np.ptp(pos[0]), 1.0)
    target = (0.3 + 0.2 * px)[None].repeat(3, 0).astype(np.float32)
    mask = np.ones(px.shape, bool)
    out, _ = B.bmfr_fit_reference(target, feats, scaled, mask, mask, 32, (0, 0), 0.0, 0)
    np.testing.assert_allclose(out, target, atol=1e-6)  # float32 storage of the result
    out, _ = B.bmfr_fit_fast(target, feats, scaled, mask, mask, 32, (0, 0), 0.01, 0)
    np.testing.assert_allclose(out, target, rtol=1e-2)
    const = np.full_like(target, 0.42)
    for eta in (0.0, 0.01):
        out, _ = B.bmfr_fit_fast(const, feats, scaled, mask, mask, 32, (5, -3), eta, 1)
        np.testing.assert_allclose(out, 0.42, atol=1e-6)


def test_per_block_scaling():
    h = w = 8
    normal = np.zeros((3, h, w), np.float32)
    normal[2] = 1
    for lo, hi, expect_range in ((100.0, 103.0, 1.0), (2.0, 2.5, 0.5)):
        pos = np.zeros((3, h, w), np.float32)
        pos[0] = np.linspace(lo, hi, w)[None, :]
        feats, scaled = B.feature_stack(normal, pos)
        # a target that is exactly the scaled P_x column: the fit reproduces it
        sx = (pos[0] - lo) / max(hi - lo, 1.0)
        assert abs(sx.max() - expect_range) < 1e-5 and abs(sx.min()) < 1e-6
        z = np.stack([sx] * 3).astype(np.float32)
        mask = np.ones((h, w), bool)
        out, _ = B.bmfr_fit_reference(z, feats, scaled, mask, mask, 8, (0, 0), 0.0, 0)
        np.testing.assert_allclose(out, z, atol=1e-5)


def test_offsets_cycle_and_cover_every_pixel():
    offs = B.grid_offsets(32, 16, seed=0)
    assert len({tuple(o) for o in offs}) == 16 and tuple(offs[0]) == (0, 0)
    assert (offs >= -16).all() and (offs < 16).all()
    m = registry.get("bmfr")
    m.reset()
    seq = synthetic_sequence(8, 8, frames=18)
    seen = []
    for f in seq:
        m.denoise(f)
        seen.append(m.last["offset"])
    assert seen[:16] == [tuple(int(v) for v in o) for o in m.grid] and seen[16] == seen[0]
    for o in offs:
        cover = np.zeros((45, 70), int)
        for y0, x0 in B.block_origins(45, 70, 32, o):
            cover[max(y0, 0):y0 + 32, max(x0, 0):x0 + 32] += 1
        assert (cover == 1).all()


def test_fit_fast_equals_reference_and_noise_streams_agree():
    rng = np.random.default_rng(4)
    h, w = 45, 70
    z = rng.random((3, h, w)).astype(np.float32)
    n = rng.normal(size=(3, h, w)).astype(np.float32)
    n /= np.linalg.norm(n, axis=0)
    pos = (rng.random((3, h, w)) * 5).astype(np.float32)
    fit, recon = rng.random((h, w)) > 0.1, rng.random((h, w)) > 0.05
    fit[:, 50:] = False  # blocks without fit rows, and a corner without anything to rebuild:
    recon[30:, :20] = False  # both keep z
    for preset in ("paper", "seed", "normals"):
        feats, scaled = B.feature_stack(n, pos, preset)
        for off in ((0, 0), (-14, -14), (4, -6)):
            r, dr = B.bmfr_fit_reference(z, feats, scaled, fit, recon, 32, off, 0.01, 7)
            f, df = B.bmfr_fit_fast(z, feats, scaled, fit, recon, 32, off, 0.01, 7)
            np.testing.assert_allclose(f, r, rtol=1e-5, atol=1e-6)
            assert dr == df
            # a kept output buffer full of stale values: the kernel writes every pixel
            kept = np.full_like(z, np.nan)
            g, _ = B.bmfr_fit_fast(z, None, scaled, fit, recon, 32, off, 0.01, 7,
                                   source=(n, pos, preset), out=kept)
            assert g is kept
            np.testing.assert_allclose(g, r, rtol=1e-5, atol=1e-6)


def test_whole_method_backends_agree_and_output_is_non_negative():
    seq = synthetic_sequence(24, 40, frames=4)
    a, b = registry.get("bmfr"), registry.get("bmfr", backend="reference")
    a.reset()
    b.reset()
    for f in seq:
        oa, ob = a.denoise(f), b.denoise(f)
        np.testing.assert_allclose(oa, ob, rtol=1e-4, atol=1e-5)
        assert (oa >= 0).all()


def test_block_seams_fade_with_the_moving_grid():
    from dbench.data import Frame

    h = w = 64
    rng = np.random.default_rng(5)
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    clean = (0.5 + 0.3 * np.sin(x / 9.0) * np.cos(y / 7.0))[..., None] * np.ones(3)
    g = dict(albedo=np.ones((h, w, 3)), depth=np.ones((h, w, 1)),
             normal=np.tile([0, 0, 1.0], (h, w, 1)),
             position=np.dstack([x / w, y / h, np.zeros((h, w))]), motion=np.zeros((h, w, 2)))
    m = registry.get("bmfr")
    m.reset()
    outs = [m.denoise(Frame(color=clean * rng.exponential(1.0, (h, w, 1)), **g))
            for _ in range(17)]

    def seam_excess(img):  # spec §8 check 9: border pairs against interior pairs
        d = np.abs(np.diff(img, axis=1)).mean(-1)
        return d[:, 31].mean() - d[:, [10, 20, 42, 52]].mean()

    assert seam_excess(outs[0]) > 0
    assert seam_excess(outs[16]) <= 0.5 * seam_excess(outs[0])


def test_bmfr_beats_noisy_on_a_synthetic_sequence():
    seq = synthetic_sequence(64, 64, frames=10)
    r = {n: run_sequence(n, seq, warmup=4).summary["mean_rmse"] for n in ("noisy", "bmfr")}
    assert r["bmfr"] < r["noisy"]


def test_errors_and_parameters():
    with pytest.raises(DbenchInputError, match="A, B"):
        householder_lstsq(np.ones((2, 5, 3)), np.ones((3, 5, 1)))
    for bad in (dict(features="all"), dict(block_size=1), dict(alpha1=2), dict(backend="x"),
                dict(preset="paper-ish")):
        with pytest.raises(DbenchInputError, match=list(bad)[0]):
            registry.get("bmfr", **bad)
    assert registry.get("bmfr", preset="seed").params["block_size"] == 64
    f = synthetic_sequence(6, 6, frames=1)[0]
    with pytest.raises(DbenchInputError, match="position"):
        registry.get("bmfr").denoise(f.with_buffers(position=None))


def test_fit_reading_normals_and_positions_directly_equals_the_stack():
    rng = np.random.default_rng(6)
    h, w = 40, 52
    z = rng.random((3, h, w)).astype(np.float32)
    n = rng.normal(size=(3, h, w)).astype(np.float32)
    pos = (rng.random((3, h, w)) * 3).astype(np.float32)
    mask = rng.random((h, w)) > 0.1
    for preset in ("paper", "seed", "positions"):
        feats, scaled = B.feature_stack(n, pos, preset)
        a, _ = B.bmfr_fit_fast(z, feats, scaled, mask, mask, 32, (3, -5), 0.01, 2)
        b, _ = B.bmfr_fit_fast(z, None, scaled, mask, mask, 32, (3, -5), 0.01, 2,
                               source=(n, pos, preset))
        np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-7)


# -- the PyTorch backend (CPU tensors here; CUDA when present) ---------------------------------

def test_torch_lstsq_safeguard_and_fit_equal_reference():
    from dbench.methods.bmfr import torch_path as BT

    A = np.ones((1, 36, 7))
    A[0, :, 1:] = 0.5
    z = np.full((1, 36, 3), 0.7)
    X, dropped = householder_lstsq(A, z, backend="torch", return_dropped=True)
    Xr, dropped_r = householder_lstsq(A, z, backend="reference", return_dropped=True)
    assert dropped[0] == dropped_r[0] > 0
    np.testing.assert_allclose(X, Xr, atol=1e-9)
    rng = np.random.default_rng(4)
    idx = rng.integers(0, 1 << 40, 500)
    import torch
    for seed, col in ((0, 1), (7, 6), (2 ** 62 + 5, 9)):  # same noise stream bit for bit
        np.testing.assert_array_equal(BT.uniform_hash_torch(seed, torch.as_tensor(idx), col),
                                      B.uniform_hash(seed, idx, col))
    h, w = 45, 70
    zz = rng.random((3, h, w)).astype(np.float32)
    n = rng.normal(size=(3, h, w)).astype(np.float32)
    n /= np.linalg.norm(n, axis=0)
    pos = (rng.random((3, h, w)) * 5).astype(np.float32)
    fit, recon = rng.random((h, w)) > 0.1, rng.random((h, w)) > 0.05
    for preset in ("paper", "seed", "normals"):
        feats, scaled = B.feature_stack(n, pos, preset)
        np.testing.assert_array_equal(BT.feature_stack_torch(n, pos, preset).numpy(), feats)
        for off in ((0, 0), (-14, -14), (4, -6)):
            r, dr = B.bmfr_fit_reference(zz, feats, scaled, fit, recon, 32, off, 0.01, 7)
            t, dt = B.bmfr_fit("torch", zz, feats, scaled, fit, recon, 32, off, 0.01, 7)
            assert t.dtype == np.float32 and dt == dr
            np.testing.assert_allclose(t, r, rtol=1e-5, atol=1e-6)
    feats, scaled, _ = _flat_wall()  # rank deficient without noise: same columns dropped
    zw = rng.random((3, 32, 32)).astype(np.float32)
    mask = np.ones((32, 32), bool)
    r, dr = B.bmfr_fit_reference(zw, feats, scaled, mask, mask, 32, (0, 0), 0.0, 3)
    t, dt = B.bmfr_fit("torch", zw, feats, scaled, mask, mask, 32, (0, 0), 0.0, 3)
    assert dt == dr > 0 and np.isfinite(t).all()
    # rank-deficient: the solution is not unique (Numba differs from the reference as much);
    # the fit residual is what the backends share
    rmse = [np.sqrt(((o - zw) ** 2).mean()) for o in (t, r)]
    assert rmse[0] <= rmse[1] * (1 + 1e-4)


def test_whole_method_torch_equals_reference_over_a_hard_sequence():
    from test_accumulate import hard_sequence

    a, b = registry.get("bmfr", backend="torch"), registry.get("bmfr", backend="reference")
    a.reset()
    b.reset()
    seen = set()
    for f in hard_sequence(24, 40, frames=5):  # disocclusion, NaN/Inf colour and motion
        oa, ob = a.denoise(f), b.denoise(f)
        assert oa.dtype == np.float32 and np.isfinite(oa).all() and (oa >= 0).all()
        np.testing.assert_allclose(oa, ob, rtol=1e-4, atol=1e-5)
        assert a.last["dropped"] == b.last["dropped"]
        seen |= set(np.unique(a.last["status"]).tolist())
    assert seen == {0, 1, 2}


def test_torch_backend_validation_and_auto(monkeypatch):
    import torch

    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    assert registry.get("bmfr").backend == "numba"
    assert registry.get("bmfr").params["backend"] == "numba"  # recorded resolved
    assert registry.get("bmfr", backend="torch").backend == "torch"
    with pytest.raises(DbenchInputError, match="backend"):
        registry.get("bmfr", backend="cuda")
    with pytest.raises(DbenchInputError, match="backend"):
        householder_lstsq(np.ones((1, 5, 2)), np.ones((1, 5, 1)), backend="cuda")


# -- issue 16: the seed's random samples per block, gradient-driven accumulation -------------

def test_block_sample_mask_draws_w_pixels_per_block():
    from dbench.methods.bmfr.reference import block_origins, block_sample_mask

    h, w, b = 40, 50, 16
    fit = np.ones((h, w), bool)
    fit[:5] = False
    offset = (-6, 3)
    mask = block_sample_mask(fit, b, offset, 36, seed=7)
    assert not (mask & ~fit).any()
    for y0, x0 in block_origins(h, w, b, offset):
        ys, xs = slice(max(y0, 0), min(y0 + b, h)), slice(max(x0, 0), min(x0 + b, w))
        assert mask[ys, xs].sum() == min(36, fit[ys, xs].sum())
    np.testing.assert_array_equal(mask, block_sample_mask(fit, b, offset, 36, seed=7))
    assert not np.array_equal(mask, block_sample_mask(fit, b, offset, 36, seed=8))


def test_seed_preset_fits_from_36_samples_and_still_beats_noisy():
    m = registry.get("bmfr", preset="seed")
    assert (m.params["block_size"], m.params["samples"], m.params["features"]) == (64, 36, "seed")
    seq = synthetic_sequence(64, 64, frames=10)
    r = {n: run_sequence(registry.get(n, **kw), seq, warmup=4).summary["mean_rmse"]
         for n, kw in (("noisy", {}), ("bmfr", dict(preset="seed")))}
    assert r["bmfr"] < r["noisy"]
    with pytest.raises(DbenchInputError, match="samples"):
        registry.get("bmfr", samples=0)


def test_temporal_gradient_drops_the_history_at_a_light_change():
    """With the re-shaded gradient samples (docs/methods/svgf.md §6) BMFR's two accumulations restart
    where the light changed (α ≥ 0.99), and keep the BMFR code's α otherwise."""
    from tests.methods.test_asvgf import _static

    seq = _static(16, 16, 14, off_at=10)
    for flag in (True, False):
        m = registry.get("bmfr", temporal_gradient=flag, block_size=8)
        m.reset()
        means = []
        for i, f in enumerate(seq):
            means.append(m.denoise(f).mean())
            if flag and i == 10:
                assert np.allclose(m.last["gradient"], 1.0)
        if flag:
            assert means[11] < 0.05 * np.mean(means[5:10])
        else:
            assert means[11] > 0.5 * np.mean(means[5:10])
    assert "gradient" in registry.get("bmfr").optional_needs


def test_reflection_feature_presets_read_their_buffers():
    """Seed 001 §1.2.1's feature buffers: "reflected" reads ``reflected_normal`` instead of the
    shading normal, "+geo" adds ``geo_normal``; all three backends build the same columns; a
    frame without the buffer is refused naming it."""
    from dbench.methods.bmfr.params import FEATURE_PRESETS, normal_column, normal_sources

    assert normal_sources("reflected+geo") == ("g", "r")
    assert normal_column("reflected+geo", "rx") == 3 and normal_column("reflected+geo", "gz") == 2
    rng = np.random.default_rng(11)
    h, w = 20, 28
    normals = rng.normal(size=(6, h, w)).astype(np.float32)
    position = rng.normal(size=(3, h, w)).astype(np.float32)
    feats, scaled = B.feature_stack(normals, position, "reflected+geo")
    assert feats.shape[0] == len(FEATURE_PRESETS["reflected+geo"]) == 13
    np.testing.assert_array_equal(feats[1:4], normals[3:6])  # r first among the columns
    np.testing.assert_array_equal(feats[4:7], normals[0:3])
    np.testing.assert_array_equal(B.feature_stack_torch(normals, position, "reflected+geo")
                                  .cpu().numpy(), feats)
    z = rng.gamma(1.0, 1.0, (3, h, w)).astype(np.float32)
    fit = np.ones((h, w), bool)
    args = (16, (0, 0), 0.01, 5)
    ref, _ = B.bmfr_fit_reference(z, feats, scaled, fit, fit, *args)
    fast, _ = B.bmfr_fit_fast(z, None, scaled, fit, fit, *args,
                              source=(normals, position, "reflected+geo"))
    np.testing.assert_allclose(fast, ref, rtol=1e-4, atol=1e-5)

    f = synthetic_sequence(16, 16, frames=1)[0]
    for preset, buffer in (("reflected", "reflected_normal"), ("paper+geo", "geo_normal")):
        with pytest.raises(DbenchInputError, match=buffer):
            registry.get("bmfr", features=preset).denoise(f)
    # with the buffers equal to the shading normal, "reflected" is "paper"
    g = f.with_buffers(reflected_normal=f.normal, geo_normal=f.normal)
    outs = [registry.get("bmfr", features=p).denoise(g) for p in ("paper", "reflected")]
    np.testing.assert_array_equal(outs[0], outs[1])
    assert np.isfinite(registry.get("bmfr", features="reflected+geo").denoise(g)).all()


@pytest.mark.parametrize("backend", ["numba", "reference"])
def test_without_an_emission_buffer_the_emission_history_is_left_out(backend):
    """No ``emission`` buffer: the emission is 0 everywhere, so its three history planes are
    neither reprojected nor accumulated; the output equals the one with a zero buffer."""
    seq = synthetic_sequence(24, 40, frames=4)
    zero = np.zeros((24, 40, 3), np.float32)
    for handback in ("wiener", "none"):
        a, b = (registry.get("bmfr", backend=backend, handback=handback) for _ in range(2))
        a.reset()
        b.reset()
        for f in seq:
            np.testing.assert_array_equal(a.denoise(f), b.denoise(f.with_buffers(emission=zero)))
        assert b.history.buffers.shape[0] == a.history.buffers.shape[0] + 3
