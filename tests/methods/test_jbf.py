"""Tests of the joint bilateral filter and the illumination filter (docs/methods/jbf.md §3, checks 1-9).

Checks 10-12 need renders and live with the dataset tests; check 6 (3D/transient) comes with the
transient variant. Fast-path tolerance: max relative difference 1e-5 against the float64
reference (float32 weights; measured ≈ 1e-6).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from dbench.data import Frame
from dbench.errors import DbenchInputError
from dbench.methods import jbf as core
from dbench.registry import get

FAST_RTOL = 1e-5


def rel_err(a, b):
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return float(np.max(np.abs(a - b) / np.maximum(np.abs(b), 1e-3))) if a.size else 0.0


def random_gbuffers(h, w, seed=0, background=0.2):
    """G-buffers with repeated values (so weights are not all tiny) and background pixels."""
    rng = np.random.default_rng(seed)
    albedo = np.where(rng.random((h, w, 1)) < 0.5, rng.random((h, w, 3)), 0.5)
    normal = rng.normal(size=(h, w, 3))
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    normal = np.where(rng.random((h, w, 1)) < 0.5, normal, [0.0, 0.0, 1.0])
    depth = np.where(rng.random((h, w, 1)) < background, 0.0, 1.0 + rng.random((h, w, 1)))
    albedo = np.where(depth > 0, albedo, 0.0)
    normal = np.where(depth > 0, normal, 0.0)
    color = rng.random((h, w, 3)) + 0.05
    position = rng.random((h, w, 3)) * 0.3
    return color, albedo, normal, depth, position


def flat(h, w, albedo=0.5):
    alb = np.full((h, w, 3), albedo)
    nrm = np.zeros((h, w, 3))
    nrm[..., 2] = 1.0
    return alb, nrm, np.ones((h, w, 1))


# ------------------------------------------------------------------ fast path == reference

@pytest.mark.parametrize("shape", [(1, 1), (1, 9), (9, 1), (13, 17), (31, 29)])
@pytest.mark.parametrize("radius", [0, 1, 5, 20])
def test_fast_equals_reference(shape, radius):
    color, albedo, normal, depth, _ = random_gbuffers(*shape, seed=radius + shape[0])
    guide = core.make_guide(albedo, normal, depth, radius=radius)
    ref = core.jbf_reference(color, guide)
    fast = core.jbf_fast(color, guide)
    assert fast.dtype == np.float32 and fast.shape == color.shape
    assert rel_err(fast, ref) < FAST_RTOL


@pytest.mark.parametrize("options", [
    dict(sigma_convention="sd", window="disk"),
    dict(features=("xy", "albedo", "normal", "position", "depth")),
    dict(hit_mask=False, window="disk"),
    dict(features=("albedo",)),
])
def test_fast_equals_reference_options(options):
    color, albedo, normal, depth, position = random_gbuffers(23, 19, seed=3)
    guide = core.make_guide(albedo, normal, depth, position, radius=6, **options)
    ref = core.jbf_reference(color, guide)
    assert rel_err(core.jbf_fast(color, guide), ref) < FAST_RTOL
    assert rel_err(core.jbf_fast(color, guide, backend="torch"), ref) < FAST_RTOL


def test_illumination_fast_equals_reference():
    color, albedo, normal, depth, position = random_gbuffers(29, 23, seed=5)
    albedo[3:6, 3:6, 1] = 0.0                       # some channels pass through
    for use_position in (False, True):
        setup = core.make_illumination_setup(albedo, normal, depth, position, radius=7,
                                             use_position=use_position, sigma_P=0.2)
        ref = core.illumination_reference(color, setup)
        assert rel_err(core.illumination_fast(color, setup), ref) < FAST_RTOL


# ------------------------------------------------------------------ docs/methods/jbf.md §3

def test_check1_box_mean_when_rho_is_one():
    rng = np.random.default_rng(1)
    color = rng.random((20, 24, 3))
    alb, nrm, depth = flat(20, 24)
    alb = rng.random((20, 24, 3))                   # would matter if Σ were finite
    r = 3
    opts = dict(radius=r, sigma=(math.inf,) * 8, hit_mask=False)
    out_ref = core.jbf_reference(color, core.make_guide(alb, nrm, depth, **opts))
    out_fast = joint = core.joint_bilateral_filter(color, alb, nrm, depth, **opts)
    box = np.zeros_like(color)
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            box[r:-r, r:-r] += color[r + dy:20 - r + dy, r + dx:24 - r + dx]
    box /= (2 * r + 1) ** 2
    np.testing.assert_allclose(out_ref[r:-r, r:-r], box[r:-r, r:-r], atol=1e-12, rtol=0)
    np.testing.assert_allclose(joint[r:-r, r:-r], box[r:-r, r:-r], rtol=FAST_RTOL)
    assert out_fast.dtype == np.float32


def _weight(guide, y, x, dy, dx):
    k = int(np.flatnonzero((guide.dy == dy) & (guide.dx == dx))[0])
    return core.reference_weights(guide, k)[y, x]


def test_check2_seed_and_sd_weights():
    alb, nrm, depth = flat(6, 6)
    g = core.make_guide(alb, nrm, depth, radius=5)
    assert _weight(g, 0, 0, 3, 4) == pytest.approx(0.2865048, abs=1e-7)
    assert _weight(g, 0, 0, 4, 3) == pytest.approx(0.2865048, abs=1e-7)
    alb2 = alb.copy()
    alb2[0, 1, 0] += 0.1
    assert _weight(core.make_guide(alb2, nrm, depth, radius=1), 0, 0, 0, 1) == pytest.approx(
        0.7788008 * math.exp(-0.05), abs=1e-7)
    nrm2 = nrm.copy()
    nrm2[0, 1] = (0.0, 0.6, 0.8)
    assert _weight(core.make_guide(alb, nrm2, depth, radius=1), 0, 0, 0, 1) == pytest.approx(
        0.1353353 * math.exp(-0.05), abs=1e-7)
    gsd = core.make_guide(alb, nrm, depth, radius=5, sigma_convention="sd")
    assert _weight(gsd, 0, 0, 3, 4) == pytest.approx(0.8824969, abs=1e-7)
    gsd2 = core.make_guide(alb2, nrm, depth, radius=1, sigma_convention="sd",
                           sigma=(math.inf, math.inf) + core.SEED_SIGMA[2:])
    assert _weight(gsd2, 0, 0, 0, 1) == pytest.approx(3.7267e-6, rel=1e-4)


def test_check2_fast_path_weights():
    """Two hit pixels alone: out(0,0) = (c0 + ρ c1)/(1 + ρ) with c0 = 0, c1 = 1."""
    for albedo_diff, normal_j, expected in [
            (0.0, (0, 0, 1), 0.2865048), (0.1, (0, 0, 1), 0.2865048 * 0.7788008),
            (0.0, (0, 0.6, 0.8), 0.2865048 * 0.1353353)]:
        alb, nrm, depth = flat(5, 6)
        depth[:] = 0.0
        depth[0, 0] = depth[3, 4] = 1.0
        alb[3, 4, 0] += albedo_diff
        nrm[3, 4] = normal_j
        color = np.zeros((5, 6, 3))
        color[3, 4] = 1.0
        out = core.joint_bilateral_filter(color, alb, nrm, depth, radius=5)
        assert out[0, 0, 0] == pytest.approx(expected / (1 + expected), rel=1e-6)


def test_check3_normalisation_and_constant_image():
    color, albedo, normal, depth, _ = random_gbuffers(17, 15, seed=7)
    guide = core.make_guide(albedo, normal, depth, radius=4)
    centre = int(np.flatnonzero((guide.dy == 0) & (guide.dx == 0))[0])
    np.testing.assert_array_equal(core.reference_weights(guide, centre), 1.0)
    _, weights = core.jbf_reference(color, guide, return_weights=True)
    assert np.all(weights >= 0)
    np.testing.assert_allclose(weights.sum(0), 1.0, atol=1e-12)
    const = np.full_like(color, 0.37)
    np.testing.assert_allclose(core.jbf_reference(const, guide), 0.37, atol=1e-12, rtol=0)
    np.testing.assert_allclose(core.jbf_fast(const, guide), 0.37, rtol=FAST_RTOL)


def test_check4_hit_mask():
    alb, nrm, depth = flat(6, 6)
    depth[:, 3:] = 0.0                                # right half is background
    alb[:, 3:] = 0.5                                  # same albedo: only the mask separates
    nrm[:, 3:] = 0.0
    color = np.ones((6, 6, 3))
    color[:, 3:] = 100.0
    guide = core.make_guide(alb, nrm, depth, radius=2)
    _, weights = core.jbf_reference(color, guide, return_weights=True)
    k = int(np.flatnonzero((guide.dy == 0) & (guide.dx == 1))[0])
    assert weights[k, 2, 2] == 0.0                    # hit (2, 2) gets nothing from (2, 3)
    np.testing.assert_allclose(core.jbf_fast(color, guide)[:, :3], 1.0, rtol=FAST_RTOL)
    g2 = core.make_guide(alb, nrm, depth, radius=2, hit_mask=False,
                         sigma=(math.inf, math.inf) + core.SEED_SIGMA[2:])
    assert _weight(g2, 2, 2, 0, 1) == pytest.approx(0.0067379, abs=1e-7)


@pytest.mark.parametrize("window,taps", [("square", 9), ("disk", 6)])
def test_check5_corner_taps_and_no_padding(window, taps):
    r = 2
    alb, nrm, depth = flat(8, 9)
    guide = core.make_guide(alb, nrm, depth, radius=r, window=window,
                            sigma=(math.inf,) * 8)
    _, weights = core.jbf_reference(np.ones((8, 9, 3)), guide, return_weights=True)
    # square: (r+1)² = 9 taps; disk of radius 2: the quarter disk has 6 offsets
    assert int(np.count_nonzero(weights[:, 0, 0])) == taps
    assert int(np.count_nonzero(weights[:, -1, -1])) == taps


def test_check5_padding_has_no_influence():
    """Embed the image in a canvas of 1e30 pixels with no G-buffer (isolated): unchanged."""
    color, albedo, normal, depth, _ = random_gbuffers(11, 13, seed=9)
    big = lambda a, fill: np.pad(a, ((4, 4), (4, 4), (0, 0)), constant_values=fill)
    ref = core.joint_bilateral_filter(color, albedo, normal, depth, radius=4, backend="reference")
    fast = core.joint_bilateral_filter(color, albedo, normal, depth, radius=4)
    for backend in ("reference", "numba"):
        out = core.joint_bilateral_filter(big(color, 1e30), big(albedo, np.nan),
                                          big(normal, np.nan), big(depth, 1.0), radius=4,
                                          backend=backend)[4:-4, 4:-4]
        np.testing.assert_allclose(out, ref if backend == "reference" else fast, rtol=FAST_RTOL)


def test_check7_illumination_invariants():
    color, albedo, normal, depth, _ = random_gbuffers(15, 14, seed=11)
    for radius in (1, 4):
        setup = core.make_illumination_setup(albedo, normal, depth, radius=radius)
        _, weights = core.illumination_reference(color, setup, return_weights=True)
        centre = int(np.flatnonzero((setup.guide.dy == 0) & (setup.guide.dx == 0))[0])
        usable = albedo > setup.eps_albedo
        assert np.all(weights >= 0)
        assert np.all(weights[centre][usable] >= 0.5)
        np.testing.assert_allclose(weights.sum(0)[usable], 1.0, atol=1e-12)


def _checkerboard(h, w, size=8):
    yy, xx = np.mgrid[0:h, 0:w]
    a = np.where(((yy // size) + (xx // size)) % 2 == 0, 0.1, 0.9)
    return np.repeat(a[..., None], 3, axis=-1)


def test_check8_illumination_preserves_dc_and_texture():
    alb = _checkerboard(48, 40)
    _, nrm, depth = flat(48, 40)
    e0 = np.array([0.7, 1.3, 2.0])
    color = alb * e0
    out_ref = core.illumination_reference(color, core.make_illumination_setup(alb, nrm, depth))
    np.testing.assert_allclose(out_ref, color, atol=1e-12, rtol=0)
    np.testing.assert_allclose(core.illumination_filter(color, alb, nrm, depth), color, rtol=FAST_RTOL)
    # the JBF with the seed Σ leaves this noise-free input unchanged as well (albedo term e^-48)
    jbf = core.jbf_reference(color, core.make_guide(alb, nrm, depth))
    np.testing.assert_allclose(jbf, color, atol=1e-12, rtol=0)


def test_check9_illumination_variance_bound():
    rng = np.random.default_rng(12)
    alb, nrm, depth = flat(256, 256, albedo=0.5)
    e = rng.normal(1.0, 0.1, size=(256, 256, 3))
    out = core.illumination_filter(alb * e, alb, nrm, depth) / 0.5
    interior = out[20:-20, 20:-20]
    assert 0.048 <= float(interior.std()) <= 0.053
    assert abs(float(out.mean()) - 1.0) <= 0.002


# ------------------------------------------------------------------ robustness and the method

def test_nan_pixel_does_not_spread():
    color, albedo, normal, depth, _ = random_gbuffers(12, 12, seed=13, background=0.0)
    bad = color.copy()
    bad[5, 6] = [np.nan, 1.0, np.inf]
    guide = core.make_guide(albedo, normal, depth, radius=3)
    ref = core.jbf_reference(bad, guide)
    fast = core.jbf_fast(bad, guide)
    assert np.all(np.isfinite(ref)) and np.all(np.isfinite(fast))
    # the missing pixel's output is the weighted mean of its valid neighbours
    _, weights = core.jbf_reference(bad, guide, return_weights=True)
    centre = int(np.flatnonzero((guide.dy == 0) & (guide.dx == 0))[0])
    assert weights[centre, 5, 6] == 0.0
    assert rel_err(fast, ref) < FAST_RTOL
    # nobody else sees it: same as filtering with that pixel isolated from everyone
    isolated = guide.isolate(np.pad(np.ones((1, 1), bool), ((5, 6), (6, 5))))
    clean = color.copy()
    clean[5, 6] = 0.0
    other = core.jbf_reference(clean, isolated)
    mask = np.ones((12, 12), bool)
    mask[5, 6] = False
    np.testing.assert_allclose(ref[mask], other[mask], atol=1e-12)
    # illumination mode too
    out = core.illumination_filter(bad, albedo, normal, depth, radius=3)
    assert np.all(np.isfinite(out))


def test_nonfinite_gbuffer_isolates_pixel():
    color, albedo, normal, depth, _ = random_gbuffers(9, 9, seed=14, background=0.0)
    normal[4, 4] = np.nan
    out = core.joint_bilateral_filter(color, albedo, normal, depth, radius=2)
    assert np.all(np.isfinite(out))
    np.testing.assert_allclose(out[4, 4], color[4, 4], rtol=FAST_RTOL)


@pytest.mark.parametrize("kwargs,name", [
    (dict(albedo=np.zeros((8, 7, 3))), "albedo"),
    (dict(normal=np.zeros((8, 8))), "normal"),
    (dict(depth=np.zeros((8, 8, 2))), "depth"),
    (dict(color=np.zeros((8, 8))), "color"),
    (dict(position=np.zeros((8, 8, 2))), "position"),
])
def test_bad_shapes_name_the_buffer(kwargs, name):
    args = dict(color=np.ones((8, 8, 3)), albedo=np.ones((8, 8, 3)),
                normal=np.ones((8, 8, 3)), depth=np.ones((8, 8, 1)), position=np.ones((8, 8, 3)))
    args.update(kwargs)
    with pytest.raises(DbenchInputError, match=name):
        core.joint_bilateral_filter(args["color"], args["albedo"], args["normal"],
                                    args["depth"], args["position"],
                                    features=("xy", "albedo", "normal", "position"))


@pytest.mark.parametrize("params,name", [
    (dict(radius=-1), "radius"), (dict(radius=2.5), "radius"), (dict(sigma=(1, 2)), "sigma"),
    (dict(sigma=(10, 10, 0.02, 0.02, 0.02, 0.1, 0.1, -1)), "sigma"),
    (dict(sigma_convention="std"), "sigma_convention"), (dict(window="circle"), "window"),
    (dict(mode="nlm"), "mode"), (dict(backend="gpu"), "backend"),
    (dict(features=("xy", "colour")), "features"), (dict(self_weight_min=2), "self_weight_min"),
    (dict(preset="fast"), "preset"), (dict(beta=-1), "beta"), (dict(bogus=1), "bogus"),
])
def test_bad_parameters_name_the_parameter(params, name):
    with pytest.raises(DbenchInputError, match=name):
        get("jbf", **params)


def test_registered_method_on_frame():
    color, albedo, normal, depth, position = random_gbuffers(16, 18, seed=15)
    frame = Frame(color=color.astype(np.float32), albedo=albedo.astype(np.float32),
                  normal=normal.astype(np.float32), depth=depth.astype(np.float32),
                  position=position.astype(np.float32))
    m = get("jbf", radius=3)
    out = m.denoise(frame)
    assert out.dtype == np.float32 and out.shape == color.shape
    ref = get("jbf", radius=3, backend="reference").denoise(frame)
    assert rel_err(out, ref) < FAST_RTOL
    assert m.last_settings["radius"] == 3 and m.last_settings["sigma_convention"] == "variance"
    # no depth (renders from files): the hit mask comes from the normals (zero where nothing
    # is hit); a "depth" feature still needs the buffer
    nodepth = Frame(color=frame.color, albedo=frame.albedo, normal=frame.normal)
    hit = np.any(frame.normal != 0, axis=-1, keepdims=True).astype(np.float32)
    g_hit = core.make_guide(frame.albedo, frame.normal, hit, radius=3)
    assert rel_err(m.denoise(nodepth), core.jbf_reference(frame.color, g_hit)) < FAST_RTOL
    with pytest.raises(DbenchInputError, match="depth"):
        get("jbf", radius=3, features=("xy", "albedo", "depth")).denoise(nodepth)
    g = core.make_guide(frame.albedo, frame.normal, None, radius=3)
    assert rel_err(core.jbf_fast(frame.color, g), core.jbf_reference(frame.color, g)) < FAST_RTOL
    # presets fill what is not given
    statmc = get("jbf", preset="statmc", radius=4)
    assert statmc.params["sigma_convention"] == "sd" and statmc.params["window"] == "disk"
    assert statmc.params["radius"] == 4
    assert statmc.denoise(frame).shape == color.shape
    illum = get("jbf", mode="illumination", radius=3)
    assert illum.denoise(frame).dtype == np.float32
    assert 0 < illum.last_settings["C"] < 1
    assert get("jbf").applies_to("steady", {"color", "albedo", "normal", "depth"})[0]


def test_emitter_buffer_keeps_lights_apart_whatever_their_albedo():
    """With the optional ``emitter`` buffer, a light whose albedo equals its surroundings' (as
    in other renderers' files) is filtered only with itself: its pixels stay at its radiance."""
    h = w = 16
    albedo = np.full((h, w, 3), 0.8, np.float32)
    normal = np.zeros((h, w, 3), np.float32)
    normal[..., 2] = 1.0
    color = np.full((h, w, 3), 0.5, np.float32)
    emitter = np.zeros((h, w, 1), np.float32)
    color[6:10, 6:10] = 20.0
    emitter[6:10, 6:10] = 1.0
    plain = Frame(color=color, albedo=albedo, normal=normal)
    with_emitter = Frame(color=color, albedo=albedo, normal=normal, emitter=emitter)
    m = get("jbf", radius=4)
    assert m.denoise(plain)[8, 8, 0] < 10.0          # the light bleeds into the wall
    out = m.denoise(with_emitter)
    np.testing.assert_allclose(out[6:10, 6:10], 20.0, rtol=1e-5)
    np.testing.assert_allclose(out[0:3, 0:3], 0.5, rtol=1e-5)
    assert "emitter" in m.optional_needs and "depth" not in m.needs
