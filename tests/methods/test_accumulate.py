"""accumulate and the shared temporal module (docs/methods/temporal.md §6 checks)."""
import numpy as np
import pytest

from dbench import registry
from dbench.data import Frame
from dbench.errors import DbenchInputError
from dbench.methods import temporal as T


def _flat(h, w, color, motion=(0.0, 0.0), depth=1.0, meta=None):
    mot = np.zeros((h, w, 2), np.float32)
    mot[..., 0], mot[..., 1] = motion
    return Frame(color=color, depth=np.full((h, w, 1), depth), normal=np.tile([0, 0, 1.0], (h, w, 1)),
                 position=np.zeros((h, w, 3)), motion=mot, meta=meta or {})


def _random_geometry(rng, h, w, motion_scale=1.5):
    normal = rng.normal(size=(3, h, w))
    normal[2] += 6
    normal /= np.linalg.norm(normal, axis=0)
    geo = T.Geometry(hit=rng.random((h, w)) > 0.1, depth=(2 + 0.05 * rng.random((h, w))).astype(np.float32),
                     normal=normal.astype(np.float32),
                     motion=(motion_scale * rng.normal(size=(2, h, w))).astype(np.float32))
    geo.depth[~geo.hit] = 0
    geo.normal[:, ~geo.hit] = 0
    geo.motion[:, rng.random((h, w)) < 0.03] = np.nan
    return geo


# -- accumulation (spec §2, §6.1, §6.7) -------------------------------------------------------

def test_static_accumulation_is_the_arithmetic_mean_and_population_variance():
    rng = np.random.default_rng(0)
    frames = [_flat(6, 7, rng.random((6, 7, 3)) * 3) for _ in range(20)]
    m = registry.get("accumulate")
    m.reset()
    for f in frames:
        out = m.denoise(f)
    stack = np.stack([f.color.astype(np.float64) for f in frames])
    np.testing.assert_allclose(out, stack.mean(0), rtol=1e-6, atol=1e-6)
    lum = stack @ T.LUMA.astype(np.float64)
    np.testing.assert_allclose(m.last["variance"], lum.var(0), rtol=1e-4, atol=1e-5)
    assert (m.last["n"] == 20).all() and (m.last["status"] == T.BILINEAR).all()


def test_history_cap_256():
    ok = np.ones((2, 2), bool)
    acc, n = np.zeros((3, 2, 2), np.float32), np.zeros((2, 2), np.float32)
    for i in range(300):  # 300 static frames through the accumulation kernel
        acc, n, a = T.accumulate_fast(np.ones((3, 2, 2), np.float32), acc, n, ok if i else ~ok)
    assert (n == 256).all() and np.allclose(a, 1 / 256)
    m = registry.get("accumulate", n_max=4)  # the method honours its cap
    m.reset()
    f = _flat(2, 2, np.ones((2, 2, 3)))
    for _ in range(6):
        m.denoise(f)
    assert (m.last["n"] == 4).all()
    hist = np.zeros((3, 2, 2), np.float32)
    _, n, a = T.accumulate(np.ones((3, 2, 2), np.float32), hist, np.full((2, 2), 256.0),
                           np.ones((2, 2), bool))
    assert (n == 256).all() and np.allclose(a, 1 / 256)


def test_accumulate_fast_equals_reference():
    rng = np.random.default_rng(1)
    s, hst = rng.random((5, 9, 11)).astype(np.float32), rng.random((5, 9, 11)).astype(np.float32)
    n_hist = rng.integers(0, 300, (9, 11)).astype(np.float32)
    ok, sok = rng.random((9, 11)) > 0.3, rng.random((9, 11)) > 0.2
    alpha = rng.random((9, 11)).astype(np.float32)
    for kw in (dict(alpha_min=0.2), dict(alpha=alpha), dict(alpha_min=0.0, sample_ok=sok)):
        r = T.accumulate(s, hst, n_hist, ok, **kw)
        f = T.accumulate_fast(s, hst, n_hist, ok, **kw)
        for a, b in zip(r, f):
            np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-7)


# -- reprojection (spec §3, §6.2-6.6, §6.8) ---------------------------------------------------

@pytest.mark.parametrize("backend", ["numba", "reference"])
def test_identity_reprojection_keeps_history_exactly(backend):
    rng = np.random.default_rng(2)
    geo = T.Geometry.flat(7, 9, motion=(0.0, 0.0))
    hist = rng.random((4, 7, 9)).astype(np.float32)
    out, status = T.reproject(hist, geo, geo, np.ones((7, 9), bool), backend=backend)
    np.testing.assert_array_equal(out, hist)
    assert (status == T.BILINEAR).all()


@pytest.mark.parametrize("backend", ["numba", "reference"])
@pytest.mark.parametrize("shift", [(1, 0), (-2, 1), (3, -3)])
def test_integer_translation_moves_the_image_exactly(backend, shift):
    rng = np.random.default_rng(3)
    h, w = 8, 10
    dx, dy = shift
    geo = T.Geometry.flat(h, w, motion=(float(dx), float(dy)))
    hist = rng.random((3, h, w)).astype(np.float32)
    out, status = T.reproject(hist, geo, geo, np.ones((h, w), bool), backend=backend)
    ys = slice(max(0, -dy), min(h, h - dy))
    xs = slice(max(0, -dx), min(w, w - dx))
    np.testing.assert_array_equal(out[:, ys, xs],
                                  hist[:, ys.start + dy:ys.stop + dy, xs.start + dx:xs.stop + dx])
    assert (status[ys, xs] == T.BILINEAR).all()


def test_reproject_fast_equals_reference_on_random_geometry():
    rng = np.random.default_rng(4)
    h, w = 23, 31
    cur, prev = _random_geometry(rng, h, w), _random_geometry(rng, h, w)
    prev.depth[prev.hit] = cur.depth[prev.hit] * (1 + 0.08 * rng.normal(size=prev.hit.sum()))
    hist = rng.random((6, h, w)).astype(np.float32)
    prev_ok = rng.random((h, w)) > 0.1
    r, sr = T.reproject(hist, cur, prev, prev_ok, backend="reference")
    f, sf = T.reproject(hist, cur, prev, prev_ok, backend="numba")
    np.testing.assert_array_equal(sr, sf)
    np.testing.assert_allclose(r, f, rtol=1e-6, atol=1e-6)
    assert {0, 1, 2} <= set(np.unique(sr).tolist())  # every path exercised


@pytest.mark.parametrize("motion", [(0.0, 0.0), (2.0, -1.0), (0.25, 0.625)])
def test_reproject_fast_unrolled_taps_equal_the_reference(motion):
    """The compiled gather's one-tap (integer motion) and four-tap (bilinear) paths, unrolled,
    give the reference's values; on a fronto-parallel plane every pixel takes one path."""
    rng = np.random.default_rng(6)
    h, w = 12, 17
    geo = T.Geometry.flat(h, w, motion=motion)
    hist = rng.random((11, h, w)).astype(np.float32)
    ok = np.ones((h, w), bool)
    r, sr = T.reproject(hist, geo, geo, ok, backend="reference")
    f, sf = T.reproject(hist, geo, geo, ok, backend="numba")
    np.testing.assert_array_equal(sr, sf)
    np.testing.assert_allclose(r, f, rtol=1e-6, atol=1e-7)


def test_bilinear_is_standard_interpolation_and_constant_history_is_kept():
    rng = np.random.default_rng(5)
    h, w = 6, 6
    geo = T.Geometry.flat(h, w, motion=(0.25, 0.625))  # exact in float32
    hist = rng.random((1, h, w))
    out, status = T.reproject_reference(hist, geo.motion, geo.hit, geo.normal, geo.depth, geo.hit,
                                        geo.depth, geo.normal)
    expect = (0.75 * 0.375 * hist[0, 2, 1] + 0.25 * 0.375 * hist[0, 2, 2]
              + 0.75 * 0.625 * hist[0, 3, 1] + 0.25 * 0.625 * hist[0, 3, 2])
    assert abs(out[0, 2, 1] - expect) < 1e-12 and status[2, 1] == T.BILINEAR
    const = np.full((1, h, w), 3.7)
    const[0, 1, 1] = 1e9  # an invalid tap holding 1e9 never leaks
    for trial in range(20):
        ok = rng.random((h, w)) > 0.4
        ok[1, 1] = False
        out, status = T.reproject_reference(const, geo.motion, geo.hit, geo.normal, geo.depth, ok,
                                            geo.depth, geo.normal)
        sel = status > 0
        np.testing.assert_allclose(out[0][sel], 3.7, rtol=0, atol=1e-12)


def test_fallback_kernel_and_normalised_fallback():
    k = T.FALLBACK_KERNEL
    assert abs(k.sum() - 0.9997) < 1e-12
    g = np.sqrt(np.diag(k))  # separable to 4 decimals: k ≈ outer(g1, g1)
    g1 = k[1] / np.sqrt(k[1, 1])
    np.testing.assert_allclose(np.outer(g1, g1), k, atol=1e-4)
    assert g.shape == (3,)
    # a 3×3 fallback of a constant history returns the constant
    h, w = 5, 5
    geo = T.Geometry.flat(h, w, motion=(0.5, 0.5))
    ok = np.zeros((h, w), bool)
    # p← = (2.5, 2.5): no bilinear tap of pixel (2, 2) is valid; the 3×3 search around the
    # nearest pixel (3, 3) finds two
    ok[2, 4] = ok[4, 2] = True
    const = np.full((2, h, w), 0.42, np.float32)
    for backend in ("reference", "numba"):
        out, status = T.reproject(const, geo, geo, ok, backend=backend)
        assert status[2, 2] == T.FALLBACK
        assert abs(out[0, 2, 2] - 0.42) < 1e-7


def test_disocclusion_resets_history():
    h, w = 6, 7
    m = registry.get("accumulate")
    m.reset()
    first = _flat(h, w, np.ones((h, w, 3)))
    first.depth[:4, :4] = 0  # background in frame 0 (a block larger than the 3×3 search)
    m.denoise(first)
    second = _flat(h, w, np.full((h, w, 3), 5.0))
    out = m.denoise(second)
    assert m.last["status"][1, 1] == T.RESET and m.last["n"][1, 1] == 1
    np.testing.assert_array_equal(out[1, 1], [5, 5, 5])
    assert m.last["status"][3, 3] == T.FALLBACK  # next to surviving history
    assert m.last["n"][5, 6] == 2 and np.allclose(out[5, 6], 3.0)


def test_depth_and_normal_tests_reject():
    h, w = 3, 3
    prev = T.Geometry.flat(h, w, depth=1.0)
    cur = T.Geometry.flat(h, w, depth=1.2, motion=(0.0, 0.0))  # 20 % farther: rejected
    out, status = T.reproject(np.ones((1, h, w), np.float32), cur, prev, np.ones((h, w), bool))
    assert (status == T.RESET).all()
    cur = T.Geometry.flat(h, w, depth=1.0, motion=(0.0, 0.0))
    cur.normal[:] = 0
    cur.normal[0] = 1.0  # normals 90° apart
    out, status = T.reproject(np.ones((1, h, w), np.float32), cur, prev, np.ones((h, w), bool))
    assert (status == T.RESET).all()


def test_expected_distance_uses_the_previous_camera_origin():
    h, w = 2, 2
    geo = T.Geometry.flat(h, w)
    geo.position = np.zeros((3, h, w), np.float32)
    geo.position[2] = 4.0
    d = T.expected_distance(geo, np.array([0.0, 3.0, 0.0]))
    np.testing.assert_allclose(d, 5.0)
    np.testing.assert_array_equal(T.expected_distance(geo, None), geo.depth)


def test_behind_previous_camera_is_never_valid():
    from dbench.datasets.sequence.load import look_at_matrix, motion_vectors

    cam = {"to_world": look_at_matrix((0, 0, 0), (0, 0, 1)).tolist(), "fov": 40.0,
           "fov_axis": "x", "width": 4, "height": 4}
    pos = np.zeros((4, 4, 3))
    pos[..., 2] = -2.0  # behind the camera
    pos[0, 0] = (0.0, 0.0, 3.0)
    mot = motion_vectors(pos, np.ones((4, 4)), cam, cam)
    assert np.isnan(mot[1:, :]).all() and np.isfinite(mot[0, 0]).all()
    m = registry.get("accumulate")
    m.reset()
    m.denoise(_flat(4, 4, np.ones((4, 4, 3))))
    f = _flat(4, 4, np.full((4, 4, 3), 3.0))
    f.motion[...] = mot
    out = m.denoise(f)
    assert (m.last["status"][1:] == T.RESET).all()
    np.testing.assert_array_equal(out[1:], 3.0)


# -- policies and errors -----------------------------------------------------------------------

def test_non_finite_pixels_are_missing_and_never_spread():
    m = registry.get("accumulate")
    m.reset()
    c = np.ones((5, 5, 3), np.float32)
    c[2, 2] = np.nan
    out = m.denoise(_flat(5, 5, c))
    assert np.isnan(out[2, 2]).all() and np.isfinite(np.delete(out.reshape(-1, 3), 12, 0)).all()
    out = m.denoise(_flat(5, 5, np.full((5, 5, 3), 3.0)))
    # the empty history is never read: pixel (2, 2) takes its history from the 3×3 fallback
    assert np.isfinite(out).all() and m.last["status"][2, 2] == T.FALLBACK
    assert np.allclose(out[2, 2], 2.0) and np.allclose(out[0, 0], 2.0)
    c = np.full((5, 5, 3), 7.0, np.float32)
    c[1, 1, 0] = np.inf
    out = m.denoise(_flat(5, 5, c))  # history kept where the new sample is missing
    assert np.isfinite(out).all()
    assert np.allclose(out[1, 1], 2.0) and m.last["n"][1, 1] == 2
    assert np.allclose(out[0, 0], 11 / 3) and m.last["n"][0, 0] == 3
    assert np.allclose(out[2, 2], 11 / 3)


def test_without_motion_every_frame_is_a_first_frame():
    m = registry.get("accumulate")
    m.reset()
    f = Frame(color=np.ones((3, 3, 3)), depth=np.ones((3, 3, 1)),
              normal=np.tile([0, 0, 1.0], (3, 3, 1)), position=np.zeros((3, 3, 3)))
    for _ in range(3):
        out = m.denoise(f)
    assert (m.last["n"] == 1).all() and np.allclose(out, 1)


@pytest.mark.parametrize("buffer,bad", [("motion", np.zeros((4, 4, 3))),
                                        ("depth", np.zeros((4, 5, 1))),
                                        ("normal", np.zeros((4, 4, 2)))])
def test_bad_shapes_name_the_buffer(buffer, bad):
    f = _flat(4, 4, np.ones((4, 4, 3)))
    object.__setattr__(f, buffer, bad)
    with pytest.raises(DbenchInputError, match=buffer):
        registry.get("accumulate").denoise(f)


def test_missing_position_is_named():
    f = Frame(color=np.ones((3, 3, 3)), depth=np.ones((3, 3, 1)),
              normal=np.tile([0, 0, 1.0], (3, 3, 1)))
    with pytest.raises(DbenchInputError, match="position"):
        registry.get("accumulate").denoise(f)


def test_bad_parameters():
    with pytest.raises(DbenchInputError, match="alpha_min"):
        registry.get("accumulate", alpha_min=2)
    with pytest.raises(DbenchInputError, match="backend"):
        registry.get("accumulate", backend="cuda-please")


# -- the PyTorch backend (CPU tensors here; CUDA when present) ---------------------------------

def hard_sequence(h=20, w=26, frames=5, seed=0, fractional=True):
    """synthetic_sequence made hostile for history (shared by the svgf/asvgf/bmfr torch tests):
    random motion — fractional (bilinear blends) or, with ``fractional=False``, whole pixels
    (history lengths stay integers, so thresholds on N such as SVGF's N < 4 cannot flip on
    float rounding) —, a block without hit in frame 1 and a 30 % depth jump in frame 3
    (disocclusion: resets and 3×3 fallbacks), NaN/Inf colour pixels and NaN motion."""
    from dbench.synthetic import synthetic_sequence

    rng = np.random.default_rng(seed)
    out = []
    for i, f in enumerate(synthetic_sequence(h, w, frames=frames, seed=seed)):
        color, depth, motion = f.color.copy(), f.depth.copy(), f.motion.copy()
        if i:
            dx, dy = 0.35 * rng.standard_normal(), 0.3 * rng.standard_normal((h, w))
            if not fractional:
                dx, dy = np.round(3 * dx), np.round(3 * dy)
            motion[..., 0] += dx
            motion[..., 1] += dy
            motion[rng.random((h, w)) < 0.03] = np.nan
        if i == 1:
            depth[2:8, 3:10] = 0.0
        if i == 3:
            depth[h // 2:, w // 3:2 * w // 3] *= 1.3
        color[rng.random((h, w)) < 0.02] = np.nan
        color[rng.integers(0, h), rng.integers(0, w), 1] = np.inf
        out.append(f.with_buffers(color=color, depth=depth, motion=motion))
    return out


def test_torch_reproject_and_accumulate_equal_reference():
    rng = np.random.default_rng(4)
    h, w = 23, 31
    cur, prev = _random_geometry(rng, h, w), _random_geometry(rng, h, w)
    prev.depth[prev.hit] = cur.depth[prev.hit] * (1 + 0.08 * rng.normal(size=prev.hit.sum()))
    hist = rng.random((6, h, w)).astype(np.float32)
    prev_ok = rng.random((h, w)) > 0.1
    r, sr = T.reproject(hist, cur, prev, prev_ok, backend="reference")
    t, st = T.reproject(hist, cur, prev, prev_ok, backend="torch")
    assert t.dtype == np.float32 and st.dtype == np.uint8
    np.testing.assert_array_equal(st, sr)
    np.testing.assert_allclose(t, r, rtol=1e-6, atol=1e-6)
    assert {0, 1, 2} <= set(np.unique(st).tolist())
    s, hst = rng.random((5, 9, 11)).astype(np.float32), rng.random((5, 9, 11)).astype(np.float32)
    n_hist = rng.integers(0, 300, (9, 11)).astype(np.float32)
    ok, sok = rng.random((9, 11)) > 0.3, rng.random((9, 11)) > 0.2
    alpha = rng.random((9, 11)).astype(np.float32)
    for kw in (dict(alpha_min=0.2), dict(alpha=alpha), dict(alpha_min=0.0, sample_ok=sok)):
        for a, b in zip(T.accumulate(s, hst, n_hist, ok, **kw),
                        T.accumulate_any("torch", s, hst, n_hist, ok, **kw)):
            np.testing.assert_allclose(b, a, rtol=1e-6, atol=1e-7)


def test_torch_backend_equals_reference_over_a_hard_sequence():
    a = registry.get("accumulate", backend="torch")
    b = registry.get("accumulate", backend="reference")
    a.reset()
    b.reset()
    seen = set()
    for f in hard_sequence():
        oa, ob = a.denoise(f), b.denoise(f)
        np.testing.assert_allclose(oa, ob, rtol=1e-5, atol=1e-5)  # NaN where both are missing
        np.testing.assert_array_equal(a.last["status"], b.last["status"])
        np.testing.assert_allclose(a.last["n"], b.last["n"], rtol=1e-6)  # N is blended too
        seen |= set(np.unique(a.last["status"]).tolist())
    assert seen == {0, 1, 2}


def test_auto_backend_is_numba_without_cuda(monkeypatch):
    import torch

    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    assert T.resolve_backend("auto") == "numba"
    assert registry.get("accumulate").backend == "numba"
    assert registry.get("accumulate", backend="auto").params["backend"] == "numba"
    # with a GPU too: "auto" is the host's compiled path; the GPU runs the device path
    # (denoise_device, docs/gpu.md), not the host-side torch backend
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    assert T.resolve_backend("auto") == "numba"
    with pytest.raises(DbenchInputError, match="backend"):
        T.resolve_backend("cuda")
    with pytest.raises(DbenchInputError, match="backend"):
        registry.get("accumulate", backend="torch-cuda")


def test_fused_numba_frame_equals_reference_over_a_hard_sequence():
    """The Numba backend's fused accumulation (accumulate/fast.py) against the readable chain:
    outputs (NaN where both are missing), N, status and variance over disocclusions, missing
    samples and the 3×3 fallback."""
    a = registry.get("accumulate", backend="numba")
    b = registry.get("accumulate", backend="reference")
    a.reset()
    b.reset()
    for f in hard_sequence():
        oa, ob = a.denoise(f), b.denoise(f)
        np.testing.assert_allclose(oa, ob, rtol=1e-6, atol=1e-6)
        np.testing.assert_array_equal(a.last["status"], b.last["status"])
        np.testing.assert_allclose(a.last["n"], b.last["n"], rtol=1e-6)
        np.testing.assert_allclose(a.last["variance"], b.last["variance"], rtol=1e-5, atol=1e-6)


def test_history_reuses_its_arrays_without_overwriting_what_it_still_needs():
    """History hands out reused arrays (no page faults of fresh ones per frame): staging never
    returns the stored history, the two staging arrays alternate, fetch writes into one array
    each frame, and storing a view of that array keeps a copy (the next fetch overwrites it)."""
    h, w = 5, 7
    geo = T.Geometry.flat(h, w, motion=(0.0, 0.0))
    hist = T.History(backend="numba")
    first = hist.staging(3, h, w)
    first[:] = 1.0
    hist.store(geo, first, finite=True)
    second = hist.staging(3, h, w)
    assert not np.shares_memory(second, first)
    fetched, status = hist.fetch(geo, 3)
    np.testing.assert_array_equal(fetched, 1.0)
    second[:] = 2.0
    hist.store(geo, second, finite=True)
    assert hist.staging(3, h, w) is first  # the arrays alternate
    again, _ = hist.fetch(geo, 3)
    assert again is fetched and (again == 2.0).all()
    hist.store(geo, again[0:3], finite=True)  # a view of the fetched array: kept as a copy
    assert not np.shares_memory(hist.buffers, again)
    again[:] = -1.0
    np.testing.assert_array_equal(hist.fetch(geo, 3)[0], 2.0)


def test_kernels_write_into_given_arrays_or_refuse_them():
    rng = np.random.default_rng(9)
    sample = rng.random((3, 4, 6)).astype(np.float32)
    history = rng.random((3, 4, 6)).astype(np.float32)
    n_hist = np.full((4, 6), 3.0, np.float32)
    ok = np.ones((4, 6), bool)
    plane = np.empty((4, 4, 6), np.float32)
    acc, n, _ = T.accumulate_fast(sample, history, n_hist, ok, out=(plane[0:3], plane[3]))
    assert np.shares_memory(acc, plane) and np.shares_memory(n, plane)
    ref, n_ref, _ = T.accumulate(sample, history, n_hist, ok)
    np.testing.assert_allclose(plane[0:3], ref, rtol=1e-6)
    np.testing.assert_array_equal(plane[3], n_ref)
    with pytest.raises(ValueError, match="out"):
        T.accumulate_fast(sample, history, n_hist, ok, out=(np.empty((3, 4, 6)), None))
