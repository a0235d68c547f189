"""The ``emitter`` buffer, the reference's own variance (``reference_var``), references shared
across noisy seeds (``ref_seed``) and ``scene_fingerprint`` (docs/judging.md §1-2)."""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from dbench import datasets
from dbench.data import FRAME_BUFFERS, TRANSIENT_PIXEL_BUFFERS, Frame, TransientFrame
from dbench.datasets import emitter as E
from dbench.datasets import render as R
from dbench.errors import DbenchInputError

RES = 32


# -- no rendering ------------------------------------------------------------------------------

def test_buffer_tables_and_frame_fields():
    assert FRAME_BUFFERS["emitter"] == 1 and TRANSIENT_PIXEL_BUFFERS["emitter"] == 1
    f = Frame(color=np.zeros((4, 5, 3)), emitter=np.ones((4, 5, 1)),
              reference=np.zeros((4, 5, 3)), reference_var=np.zeros((4, 5, 3), np.float64))
    assert f.emitter.dtype == np.float32 and f.reference_var.dtype == np.float32
    with pytest.raises(DbenchInputError, match="reference_var"):
        Frame(color=np.zeros((4, 5, 3)), reference_var=np.zeros((4, 5, 1)))
    with pytest.raises(DbenchInputError, match="emitter"):
        Frame(color=np.zeros((4, 5, 3)), emitter=np.zeros((4, 5, 3)))
    v = TransientFrame(color=np.zeros((4, 5, 6, 3)), emitter=np.zeros((4, 5, 1)),
                       reference_var=np.zeros((4, 5, 6, 3)))
    assert v.reference_var.shape == (4, 5, 6, 3)
    with pytest.raises(DbenchInputError, match="reference_var"):
        TransientFrame(color=np.zeros((4, 5, 6, 3)), reference_var=np.zeros((4, 5, 3)))
    for name in datasets.available_scenes():
        sc = datasets.get_scene(name)
        assert "emitter" in sc.provides, name


@pytest.mark.parametrize("spp, expected", [
    (4096, [256] * 16), (64, [4] * 16), (100, [6] * 16 + [4]), (8, [1] * 8), (1, [1]),
    (16, [1] * 16), (10000, [256] * 39 + [16]),
])
def test_reference_chunks(spp, expected):
    chunks = R.reference_chunks(spp)
    assert chunks == expected and sum(chunks) == spp
    if spp >= 16:
        assert len(chunks) >= 16


def test_chunk_moments_match_the_formula():
    rng = np.random.default_rng(0)
    sizes = [6] * 16 + [4]
    means = [rng.gamma(2.0, 1.0, size=(3, 4)) for _ in sizes]
    acc = R.ChunkMoments((3, 4))
    for m, n in zip(means, sizes):
        acc.add(m, n)
    n_tot = sum(sizes)
    m = sum(n * x for n, x in zip(sizes, means)) / n_tot
    sigma2 = sum(n * (x - m) ** 2 for n, x in zip(sizes, means)) / (len(sizes) - 1)
    np.testing.assert_allclose(acc.mean(), m, rtol=1e-12)
    np.testing.assert_allclose(acc.var_mean(), sigma2 / n_tot, rtol=1e-10)
    one = R.ChunkMoments((2,))
    one.add(np.ones(2), 5)
    assert np.all(one.var_mean() == 0)


def test_ref_seed_is_checked():
    with pytest.raises(DbenchInputError, match="ref_seed"):
        datasets.load("cornell", spp=1, res=8, needs={"reference"}, ref_seed=-1)


# -- the emitter buffer ------------------------------------------------------------------------

@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return datasets.Cache(tmp_path_factory.mktemp("emitter-refvar-cache"))


@pytest.fixture(scope="module")
def cornell(renderer, cache):
    return datasets.load("cornell", spp=16, res=RES, ref_spp=64, cache=cache, progress=False,
                         needs={"reference"})


def _emission_only(renderer, res: int) -> np.ndarray:
    """max_depth 1 (directly visible emitters only), 64 spp, box filter."""
    mi = renderer
    sc = R.loaded_scene(datasets.get_scene("cornell"), res)
    img = mi.render(sc, integrator=mi.load_dict({"type": "path", "max_depth": 1}), spp=64,
                    seed=123)
    return np.array(img, np.float64)


def test_cornell_emitter_buffer(renderer, cornell):
    e = cornell.emitter[..., 0]
    assert cornell.emitter.shape == (RES, RES, 1) and cornell.emitter.dtype == np.float32
    assert e.min() >= 0.0 and e.max() <= 1.0
    emission = _emission_only(renderer, RES).max(axis=-1)
    # the middle of the ceiling light: the brightest pixel of the emission-only render
    y, x = np.unravel_index(np.argmax(emission), emission.shape)
    assert e[y, x] == 1.0
    # walls, floor and boxes
    for y, x in ((RES // 2, 1), (RES // 2, RES - 2), (RES - 2, RES // 2), (RES // 2, RES // 2)):
        assert e[y, x] == 0.0, (y, x)
    assert np.any((e > 0) & (e < 1)), "light-edge pixels are partial"
    # the same pixels as the emission-only render (up to independent sampling of thin slivers)
    lit, covered = emission > 0, e > 0
    assert abs(int(lit.sum()) - int(covered.sum())) <= max(2, 0.2 * lit.sum())
    near = lit.copy()
    near[1:] |= lit[:-1]
    near[:-1] |= lit[1:]
    near[:, 1:] |= near[:, :-1].copy()
    near[:, :-1] |= near[:, 1:].copy()
    assert not np.any(covered & ~near)
    assert np.all(e[lit & (emission > 0.5 * emission.max())] > 0)


def _facing_rect_scene(mi, res: int, facing: bool = True, env: float | None = None) -> dict:
    T = mi.ScalarTransform4f
    d = {"type": "scene",
         "sensor": {"type": "perspective", "fov": 30, "fov_axis": "x",
                    "to_world": T().look_at(origin=[0, 0, 0], target=[0, 0, 1], up=[0, 1, 0]),
                    "film": {"type": "hdrfilm", "width": res, "height": res,
                             "rfilter": {"type": "box"}},
                    "sampler": {"type": "independent"}},
         # a white diffuse BSDF on the light: the "lights are black" convention does not hold
         "lamp": {"type": "rectangle",
                  "to_world": T().translate([0, 0, 3]).rotate([0, 1, 0], 180 if facing else 0)
                  .scale(0.5),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [1, 1, 1]}},
                  "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [2, 2, 2]}}}}
    if env is not None:
        d["sky"] = {"type": "constant", "radiance": {"type": "rgb", "value": [env] * 3}}
    return d


def test_emitter_with_a_white_bsdf_and_the_environment(renderer):
    mi, res = renderer, 16
    c = res // 2
    e = E.render_emitter_dict(_facing_rect_scene(mi, res), 16, seed=1)
    assert e.shape == (res, res, 1)
    assert e[c, c, 0] == 1.0 and e[0, 0, 0] == 0.0      # the lamp; a miss without environment
    back = E.render_emitter_dict(_facing_rect_scene(mi, res, facing=False), 16, seed=1)
    assert back.max() == 0.0                            # it emits away from the camera
    sky = E.render_emitter_dict(_facing_rect_scene(mi, res, env=0.5), 16, seed=1)
    assert sky[0, 0, 0] == 1.0 and sky[c, c, 0] == 1.0
    dark = E.render_emitter_dict(_facing_rect_scene(mi, res, env=0.0), 16, seed=1)
    assert dark[0, 0, 0] == 0.0 and dark[c, c, 0] == 1.0


def _mirror_scene(mi, res: int, bsdf: dict) -> dict:
    """A surface with ``bsdf`` filling the view at z = 3 and a lamp behind the camera facing
    it: the lamp is seen only in the surface's reflection."""
    T = mi.ScalarTransform4f
    return {"type": "scene",
            "sensor": {"type": "perspective", "fov": 30, "fov_axis": "x",
                       "to_world": T().look_at(origin=[0, 0, 0], target=[0, 0, 1], up=[0, 1, 0]),
                       "film": {"type": "hdrfilm", "width": res, "height": res,
                                "rfilter": {"type": "box"}},
                       "sampler": {"type": "independent"}},
            "wall": {"type": "rectangle", "bsdf": bsdf,
                     "to_world": T().translate([0, 0, 3]).rotate([0, 1, 0], 180).scale(2.0)},
            "lamp": {"type": "rectangle", "to_world": T().translate([0, 0, -2]).scale(0.5),
                     "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [5] * 3}}}}


MIRRORS = {"smooth conductor": ({"type": "conductor"}, 1.0),
           "rough conductor": ({"type": "roughconductor", "alpha": 0.2}, 0.0),
           "glass": ({"type": "dielectric"}, 0.0),
           "smooth plastic": ({"type": "plastic"}, 0.0),
           "diffuse": ({"type": "diffuse"}, 0.0)}


@pytest.mark.parametrize("name", list(MIRRORS))
def test_lights_seen_in_smooth_mirrors_count(renderer, name):
    """Only a smooth mirror's reflection of a light is deterministic; rough metal, glass (a
    random lobe), smooth plastic and diffuse surfaces show noise, not the light."""
    bsdf, centre = MIRRORS[name]
    res = 16
    e = E.render_emitter_dict(_mirror_scene(renderer, res, bsdf), 16, seed=2)
    assert e[res // 2, res // 2, 0] == centre, name
    assert e[0, 0, 0] == 0.0  # the corners see the mirror beside the lamp's image


def test_emitter_integrator_in_scalar_rgb(renderer):
    code = textwrap.dedent("""
        import numpy as np
        from dbench.datasets import emitter as E
        from dbench.datasets.mitsuba_env import mitsuba
        from tests.datasets.test_emitter_refvar import _facing_rect_scene
        mi = mitsuba()
        assert mi.variant() == "scalar_rgb", mi.variant()
        e = E.render_emitter_dict(_facing_rect_scene(mi, 8, env=0.5), 4, seed=1)
        f = E.render_emitter_dict(_facing_rect_scene(mi, 8, facing=False), 4, seed=1)
        from tests.datasets.test_emitter_refvar import _mirror_scene
        g = E.render_emitter_dict(_mirror_scene(mi, 8, {"type": "conductor"}), 4, seed=1)
        print("OK", e.shape, float(e.min()), float(f.max()), float(g[3:5, 3:5].min() > 0), float(g[0, 0, 0]))
    """)
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    env = {**os.environ, "DBENCH_VARIANT": "scalar_rgb", "PYTHONPATH": root}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                         cwd=root, timeout=300)
    assert "OK (8, 8, 1) 1.0 0.0 1.0 0.0" in out.stdout, out.stdout + out.stderr


# -- reference variance and shared references ----------------------------------------------------

def test_reference_var_and_meta(cornell):
    v = cornell.reference_var
    assert v.shape == cornell.reference.shape == (RES, RES, 3) and v.dtype == np.float32
    assert np.all(v >= 0) and np.mean(v > 0) > 0.9     # path-traced pixels are noisy
    m = cornell.meta
    assert m["ref_spp"] == 64 and m["ref_seed"] == 0 and m["ref_render_s"] > 0
    assert m["ref_rmse"] == pytest.approx(float(np.sqrt(np.mean(v.astype(np.float64)))))
    assert cornell.emitter is not None                   # the judge needs it with a reference


def test_noisy_seeds_share_one_reference(renderer, cache, cornell):
    other = datasets.load("cornell", spp=16, res=RES, seed=7, ref_spp=64, cache=cache,
                          progress=False, needs={"reference"})
    assert "reference" in other.meta["cache_hits"] and "reference" not in other.meta["rendered"]
    assert "color" in other.meta["rendered"]
    assert not np.array_equal(other.color, cornell.color)
    np.testing.assert_array_equal(other.reference, cornell.reference)
    np.testing.assert_array_equal(other.reference_var, cornell.reference_var)
    assert other.meta["ref_render_s"] == pytest.approx(cornell.meta["ref_render_s"])
    fresh = datasets.load("cornell", spp=16, res=RES, seed=7, ref_spp=64, ref_seed=3,
                          cache=cache, progress=False, needs={"reference"})
    assert "reference" in fresh.meta["rendered"] and fresh.meta["ref_seed"] == 3
    assert not np.array_equal(fresh.reference, cornell.reference)


def test_reference_noise_is_removed_from_the_mse(renderer, cache):
    """docs/judging.md §2: the 16-spp input against a 64-spp and a 4096-spp reference. Raw
    RMSE differ by ≈ √1.25 ≈ 1.12; sqrt(MSE − mean(reference_var)) agrees within 5 %. Surface
    pixels (emitter = 0; the few light pixels alias and dominate a single render's MSE), mean
    over 8 noisy seeds, each against its own 64-spp reference (ref_seed = seed)."""
    kw = dict(spp=16, res=RES, cache=cache, progress=False)
    ref4k = datasets.load("cornell", needs={"reference"}, ref_spp=4096, ref_seed=100, **kw)
    surface = ref4k.emitter[..., 0] == 0
    mse64, var64, mse4k = [], [], []
    for s in range(8):
        r64 = datasets.load("cornell", needs={"reference"}, seed=s, ref_spp=64, ref_seed=s, **kw)
        x = r64.color.astype(np.float64)
        mse64.append(np.mean((x - r64.reference)[surface] ** 2))
        var64.append(np.mean(r64.reference_var[surface].astype(np.float64)))
        mse4k.append(np.mean((x - ref4k.reference)[surface] ** 2))
    var4k = np.mean(ref4k.reference_var[surface].astype(np.float64))
    raw64, raw4k = np.sqrt(np.mean(mse64)), np.sqrt(np.mean(mse4k))
    unb64 = np.sqrt(max(0.0, np.mean(mse64) - np.mean(var64)))
    unb4k = np.sqrt(max(0.0, np.mean(mse4k) - var4k))
    print(f"raw {raw64:.5f} / {raw4k:.5f} = {raw64 / raw4k:.4f}; "
          f"unbiased {unb64:.5f} / {unb4k:.5f} = {unb64 / unb4k:.4f}")
    assert 1.05 < raw64 / raw4k < 1.2
    assert abs(unb64 / unb4k - 1.0) < 0.05


# -- sequences, transient, fingerprints ----------------------------------------------------------

def test_sequence_emitter_and_reference_var(renderer, cache):
    seq = datasets.load("flicker", spp=1, res=16, frames=2, ref_spp=16, cache=cache,
                        progress=False, needs={"reference"})
    for f in seq:
        assert f.emitter.shape == (16, 16, 1) and f.reference_var.shape == (16, 16, 3)
        assert f.emitter.min() >= 0 and f.emitter.max() <= 1
        assert np.all(f.reference_var >= 0) and np.any(f.reference_var > 0)
        assert f.meta["ref_seed"] == 0 and f.meta["ref_spp"] == 16
    assert seq.meta["ref_spp"] == 16 and seq.meta["ref_rmse"] > 0
    assert seq.meta["ref_render_s"] > 0
    again = datasets.load("flicker", spp=1, res=16, frames=2, seed=4, ref_spp=16, cache=cache,
                          progress=False, needs={"reference"})
    assert not any(n.startswith("reference") for n in again.meta["rendered"])
    np.testing.assert_array_equal(again[1].reference_var, seq[1].reference_var)


@pytest.fixture()
def llvm(renderer):
    from dbench.datasets import mitsuba_env
    if not mitsuba_env.mitsuba().variant().startswith(("llvm", "cuda")):
        pytest.skip("transient rendering needs the llvm_ad_rgb variant")


def test_transient_emitter_and_reference_var(llvm, cache):
    v = datasets.load("cornell-transient", spp=4, res=8, bins=12, ref_spp=32, cache=cache,
                      progress=False, needs={"reference"})
    assert v.reference.shape == v.reference_var.shape == (8, 8, 12, 3)
    assert v.emitter.shape == (8, 8, 1)
    assert np.all(v.reference_var >= 0) and np.any(v.reference_var > 0)
    assert v.meta["ref_spp"] == 32 and v.meta["ref_seed"] == 0 and v.meta["ref_rmse"] > 0
    w = datasets.load("cornell-transient", spp=4, res=8, bins=12, seed=9, ref_spp=32,
                      cache=cache, progress=False, needs={"reference"})
    assert "reference" in w.meta["cache_hits"]
    np.testing.assert_array_equal(w.reference_var, v.reference_var)


def test_scene_fingerprint(renderer, monkeypatch):
    def no_render(*a, **k):
        raise AssertionError("scene_fingerprint must not render")

    monkeypatch.setattr(renderer, "render", no_render)
    fps = {n: datasets.scene_fingerprint(n, 16)
           for n in ("cornell", "mirrors", "flicker", "orbit", "cornell-transient")}
    for fp in fps.values():
        assert len(fp) == 16 and all(c in "0123456789abcdef" for c in fp)
    assert len(set(fps.values())) == len(fps)
    assert datasets.scene_fingerprint("cornell", 16) == fps["cornell"]
    assert datasets.scene_fingerprint("cornell", 32) != fps["cornell"]
