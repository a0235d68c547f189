"""The PSR G-buffer (dbench/datasets/sequence/psr.py, docs/temporal.md §1): mirrors and glass described by
what they show; everything else exactly Mitsuba's AOVs; the colour untouched."""
import numpy as np
import pytest

RES = 16


def _scene(mi, mirror_bsdf, extra=None):
    """Camera at z = 5 looking down −z at a 45° mirror in the origin that reflects towards +x,
    where a diffuse wall (reflectance 0.5, normal −x) stands at x = 3; a light above."""
    T = mi.ScalarTransform4f
    d = {"type": "scene",
         "sensor": {"type": "perspective", "fov": 20,
                    "to_world": T().look_at(origin=[0, 0, 5], target=[0, 0, 0], up=[0, 1, 0]),
                    "film": {"type": "hdrfilm", "width": RES, "height": RES,
                             "rfilter": {"type": "box"}, "pixel_format": "rgb"}},
         "mirror": {"type": "rectangle", "bsdf": mirror_bsdf,
                    "to_world": T().rotate([0, 1, 0], 45).scale(2.0)},
         "wall": {"type": "rectangle", "to_world": T().translate([3, 0, 0]).rotate([0, 1, 0], -90)
                  .scale(6.0),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.5}}},
         "light": {"type": "point", "position": [1.5, 2.5, 1.0],
                   "intensity": {"type": "rgb", "value": 20.0}}}
    d.update(extra or {})
    return d


def _render(mi, d, integrator, seed=3):
    scene = mi.load_dict(d, optimize=False)
    integ = mi.load_dict(integrator, optimize=False)
    return np.array(mi.render(scene, spp=1, seed=seed, integrator=integ), np.float64)


def _buffers(img):
    from dbench.datasets.sequence.psr import PSR_EXTRA_LAYOUT
    from dbench.datasets.sequence.frames import MATCHED_LAYOUT
    layout = MATCHED_LAYOUT + (PSR_EXTRA_LAYOUT if img.shape[-1] > 16 else ())
    return {name: img[..., c0:c0 + nc] for name, c0, nc in layout}


def test_mirror_pixels_see_the_reflected_wall(renderer):
    from dbench.datasets.sequence.psr import psr_integrator

    mi = renderer
    d = _scene(mi, {"type": "conductor", "material": "none"})
    b = _buffers(_render(mi, d, psr_integrator({"type": "path", "max_depth": 4})))
    c = RES // 2
    # the reflected (wall's) normal, the wall's albedo through a perfect mirror, the whole
    # chain's length and the virtual point behind the mirror
    np.testing.assert_allclose(b["normal"][c, c], [-1, 0, 0], atol=1e-4)
    np.testing.assert_allclose(b["albedo"][c, c], [0.5, 0.5, 0.5], atol=1e-4)
    assert b["depth"][c, c, 0] == pytest.approx(8.0, abs=0.05)
    # a pixel spans ≈ 0.18 scene units at that distance; the jittered sample is inside it
    np.testing.assert_allclose(b["position"][c, c], [0, 0, -3], atol=0.2)
    assert b["position"][c, c, 2] == pytest.approx(-3.0, abs=0.05)


def test_colour_equals_a_plain_render_and_diffuse_pixels_equal_mitsubas_aovs(renderer):
    from dbench.datasets.sequence.psr import psr_integrator
    from dbench.datasets.sequence.frames import _matched_integrator

    mi = renderer
    path = {"type": "path", "max_depth": 4}
    d = _scene(mi, {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.3}})
    psr = _render(mi, d, psr_integrator(path))
    plain = _render(mi, d, {"type": "path", "max_depth": 4})
    matched = _render(mi, d, _matched_integrator(path))
    np.testing.assert_array_equal(psr[..., :3], plain[..., :3])
    # no delta surface: every buffer identical to Mitsuba's AOVs
    np.testing.assert_array_equal(psr[..., :matched.shape[-1]], matched)
    b = _buffers(psr)
    # flat rectangles: the geometric normal is the shading normal; nothing glossy: the
    # reflected normal is the pixel's own
    np.testing.assert_allclose(b["geo_normal"], b["normal"], atol=1e-6)
    np.testing.assert_array_equal(b["reflected_normal"], b["normal"])


def test_geo_normal_is_the_face_normal_of_a_smooth_shaded_mesh(renderer, tmp_path):
    """A quad facing +z whose vertex normals lean towards +x: ``normal`` is the interpolated
    (shading) normal, ``geo_normal`` the face's own +z (seed 001 §1.2.1's geometry normal)."""
    from dbench.datasets.sequence.psr import psr_integrator

    mi = renderer
    lean = np.array([0.3, 0.0, 1.0]) / np.linalg.norm([0.3, 0.0, 1.0])
    obj = tmp_path / "quad.obj"
    obj.write_text("v -3 -3 0\nv 3 -3 0\nv 3 3 0\nv -3 3 0\n"
                   f"vn {lean[0]} {lean[1]} {lean[2]}\n"
                   "f 1//1 2//1 3//1\nf 1//1 3//1 4//1\n")
    d = _scene(mi, {"type": "diffuse"})
    del d["mirror"], d["wall"]
    d["quad"] = {"type": "obj", "filename": str(obj), "face_normals": False,
                 "bsdf": {"type": "diffuse"}}
    b = _buffers(_render(mi, d, psr_integrator({"type": "path", "max_depth": 4})))
    c = RES // 2
    np.testing.assert_allclose(b["normal"][c, c], lean, atol=1e-4)
    np.testing.assert_allclose(b["geo_normal"][c, c], [0, 0, 1], atol=1e-5)
    np.testing.assert_allclose(b["reflected_normal"][c, c], lean, atol=1e-4)


def test_conductor_demodulation_stays_bounded_and_glass_is_seen_through(renderer):
    """Mitsuba's albedo AOV is 0 on a smooth conductor: the colour divided by the fallback
    a_eff = 1 keeps the wall's texture, and any small albedo amplifies it. The PSR albedo is the
    Fresnel reflectance × the wall's albedo, so the demodulated mirror pixels carry the wall's
    illumination, the same range as the wall seen directly."""
    from dbench.datasets.sequence.psr import psr_integrator
    from dbench.datasets.sequence.frames import _matched_integrator

    mi = renderer
    path = {"type": "path", "max_depth": 4}
    d = _scene(mi, {"type": "conductor", "material": "Cr"})
    plain = _buffers(_render(mi, d, _matched_integrator(path)))
    psr = _buffers(_render(mi, d, psr_integrator(path)))
    c = RES // 2
    mirror = np.zeros((RES, RES), bool)
    mirror[c - 2:c + 2, c - 2:c + 2] = True
    assert plain["albedo"][mirror].max() < 1e-6            # the problem
    fresnel = psr["albedo"][mirror] / 0.5
    assert (fresnel > 0.4).all() and (fresnel < 1.0).all()  # chromium reflects 55-65 %
    np.testing.assert_allclose(psr["normal"][mirror], np.tile([-1, 0, 0], (mirror.sum(), 1)),
                               atol=1e-3)
    T = mi.ScalarTransform4f
    backdrop = {"backdrop": {"type": "rectangle", "to_world": T().translate([0, 0, -3]).scale(8),
                             "bsdf": {"type": "diffuse",
                                      "reflectance": {"type": "rgb", "value": 0.5}}}}
    glass = _buffers(_render(mi, _scene(mi, {"type": "thindielectric"}, backdrop),
                             psr_integrator(path)))
    plain_glass = _buffers(_render(mi, _scene(mi, {"type": "thindielectric"}, backdrop),
                                   _matched_integrator(path)))
    assert plain_glass["albedo"][mirror].max() < 1e-6
    assert (glass["albedo"][mirror] > 0.01).all()          # seen through (or reflected), not 0


def test_a_lamp_in_a_mirror_is_an_emitter_pixel(renderer):
    from dbench.datasets.sequence.psr import psr_integrator

    mi = renderer
    T = mi.ScalarTransform4f
    lamp = {"lamp": {"type": "rectangle", "to_world": T().translate([2.9, 0, 0])
                     .rotate([0, 1, 0], -90).scale(0.3),
                     "emitter": {"type": "area", "radiance": {"type": "rgb", "value": 10.0}}}}
    d = _scene(mi, {"type": "conductor", "material": "none"}, lamp)
    b = _buffers(_render(mi, d, psr_integrator({"type": "path", "max_depth": 4})))
    c = RES // 2
    np.testing.assert_allclose(b["emission"][c, c], [10, 10, 10], rtol=1e-4)
    assert b["emission"][0, 0].max() == 0


def test_chrome_sphere_albedo_is_never_near_zero_and_normals_are_reflected(renderer):
    """A chrome sphere in a closed diffuse room (issue 16's check: the demodulated signal of a
    conductor stays bounded). Mitsuba's AOV gives the sphere albedo 0, and values just above the
    1e-3 cut-off amplify a reflection up to 1000×. With PSR every sphere pixel has albedo
    Fresnel(Cr) × 0.5 ≥ 0.2 (at most 5× amplification), the normal of the wall it reflects
    (axis-aligned), and a demodulated illumination of the order of the walls' own."""
    from dbench.datasets.sequence.psr import psr_integrator

    mi = renderer
    T = mi.ScalarTransform4f
    d = {"type": "scene",
         "sensor": {"type": "perspective", "fov": 40,  # the sphere fills the central 60 %
                    "to_world": T().look_at(origin=[0, 0, 4.4], target=[0, 0, 0], up=[0, 1, 0]),
                    "film": {"type": "hdrfilm", "width": RES, "height": RES,
                             "rfilter": {"type": "box"}, "pixel_format": "rgb"}},
         "room": {"type": "cube", "flip_normals": True, "to_world": T().scale(4.5),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.5}}},
         "sphere": {"type": "sphere", "radius": 1.0, "bsdf": {"type": "conductor",
                                                               "material": "Cr"}},
         "light": {"type": "point", "position": [1.5, 3.0, 2.5],
                   "intensity": {"type": "rgb", "value": 40.0}}}
    scene = mi.load_dict(d, optimize=False)
    integ = mi.load_dict(psr_integrator({"type": "path", "max_depth": 6}), optimize=False)
    b = _buffers(np.array(mi.render(scene, spp=64, seed=1, integrator=integ), np.float64))
    c = RES // 2
    sphere = np.zeros((RES, RES), bool)
    sphere[c - 3:c + 3, c - 3:c + 3] = True       # well inside the sphere's silhouette
    wall = np.zeros((RES, RES), bool)
    wall[:2] = True                               # the room's back wall above it
    a = b["albedo"]
    assert (a[sphere] > 0.2).all() and (a[sphere] < 0.5).all()   # Fresnel(Cr) × 0.5
    # one sample per pixel: the reflected wall's own normal
    normal = _buffers(np.array(mi.render(scene, spp=1, seed=1, integrator=integ), np.float64))[
        "normal"]
    np.testing.assert_allclose(np.abs(normal[sphere]).max(-1), 1.0, atol=1e-3)
    illum = (b["color"] - b["emission"]) / np.maximum(a, 1e-3)
    assert np.isfinite(illum[sphere]).all()
    # the sphere shows walls nearer the light than the back wall: same order, not amplified
    assert illum[sphere].max() < 10 * illum[wall].max()


@pytest.mark.parametrize("bsdf,reflected", [
    ({"type": "roughplastic", "alpha": 0.1,
      "diffuse_reflectance": {"type": "rgb", "value": 0.2}}, True),
    ({"type": "roughconductor", "alpha_u": 0.05, "alpha_v": 0.15}, True),
    ({"type": "roughplastic", "alpha": 0.6}, False),
    ({"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.3}}, False)])
def test_glossy_rule_gives_low_roughness_surfaces_the_reflected_normal(renderer, bsdf, reflected):
    """glossy_alpha = 0.4: the 45° glossy plane's normal becomes the wall's (−x), which its
    mirror direction hits, when its roughness (isotropic α or the mean of α_u, α_v) is below
    0.4; rougher or diffuse surfaces keep their own normal; the colour and the other buffers are
    those of the plain PSR render."""
    from dbench.datasets.sequence.psr import GLOSSY_ALPHA, psr_integrator

    mi = renderer
    path = {"type": "path", "max_depth": 4}
    d = _scene(mi, bsdf)
    plain = _render(mi, d, psr_integrator(path))
    rule = _render(mi, d, psr_integrator(path, GLOSSY_ALPHA))
    pb, rb = _buffers(plain), _buffers(rule)
    c = RES // 2
    own = np.array([np.sqrt(0.5), 0.0, np.sqrt(0.5)])  # the plane rotated 45° about y
    np.testing.assert_allclose(pb["normal"][c, c], own, atol=1e-4)
    np.testing.assert_allclose(rb["normal"][c, c], [-1, 0, 0] if reflected else own, atol=1e-4)
    # every PSR render carries the rule's normal as ``reflected_normal`` and the plane's face
    # normal as ``geo_normal``, whatever its ``normal`` is
    for b in (pb, rb):
        np.testing.assert_array_equal(b["reflected_normal"], rb["normal"])
        np.testing.assert_allclose(b["geo_normal"][c, c], own, atol=1e-4)
    for name in ("color", "albedo", "depth", "position", "emission"):
        if name in pb:
            np.testing.assert_array_equal(rb[name], pb[name])


def test_sequences_offer_the_glossy_rule_as_a_gbuffer(renderer, tmp_path):
    """load_sequence(gbuffer="psr-glossy") on `orbit` (a rough-plastic sphere, α = 0.08): the same
    colour, albedo, depth and position as the default PSR G-buffer, other normals on the
    sphere only, and its own cache entries."""
    from dbench import datasets
    from dbench.datasets.cache import Cache
    from dbench.datasets.sequence.load import load_sequence

    cache = Cache(tmp_path)
    kw = dict(spp=1, res=24, seed=0, frames=2, cache=cache, progress=False,
              needs={"color", "albedo", "normal", "depth", "position"})
    sc = datasets.get_scene("orbit")
    plain = load_sequence(sc, gbuffer="psr", **kw)
    glossy = load_sequence(sc, gbuffer="psr-glossy", **kw)
    for a, b in zip(plain, glossy):
        for name in ("color", "albedo", "depth", "position"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    changed = np.any(plain[0].normal != glossy[0].normal, axis=-1)
    assert 0 < changed.mean() < 0.5  # the glossy sphere's pixels, not the diffuse room
    # rendered, not read from the default G-buffer's cache entries
    assert {"frame0", "frame1"} <= set(glossy.meta["rendered"])


def test_the_gbuffer_is_a_scene_parameter_of_every_sequence(renderer, tmp_path):
    """``--scene-param gbuffer=psr-glossy`` (what `dbench run` and `sweep` pass): a scene of its
    own identity whose frames carry the glossy rule's normals, sharing the references and
    emitter buffers of the default G-buffer; a bad value or a second, different choice is
    refused naming the parameter."""
    from dbench import datasets
    from dbench.datasets.cache import Cache
    from dbench.datasets.sequence.load import load_sequence
    from dbench.errors import DbenchInputError

    for name in ("orbit", "flicker", "mirror-pan"):
        assert [p.name for p in datasets.get_scene(name).declared] == ["gbuffer"]
    orbit = datasets.get_scene("orbit")
    bound = datasets.get_scene("orbit", {"gbuffer": "psr-glossy"})
    assert bound.params == {"gbuffer": "psr-glossy"} and bound.name == "orbit"
    assert datasets.get_scene("orbit", {"gbuffer": "psr"}) is orbit
    assert datasets.scene_fingerprint(bound, 24) != datasets.scene_fingerprint(orbit, 24)
    with pytest.raises(DbenchInputError, match="gbuffer.*psr\\|psr-glossy"):
        datasets.get_scene("orbit", {"gbuffer": "shiny"})
    cache = Cache(tmp_path)
    kw = dict(spp=1, res=24, seed=0, frames=2, cache=cache, progress=False, ref_spp=4,
              needs={"color", "normal", "reference"})
    direct = load_sequence(orbit, gbuffer="psr-glossy", **kw)
    via = datasets.load(bound, **kw)
    assert via.meta["gbuffer"] == "psr-glossy"
    for a, b in zip(direct, via):
        np.testing.assert_array_equal(a.normal, b.normal)
        np.testing.assert_array_equal(a.reference, b.reference)
    assert "reference0" in direct.meta["rendered"]
    # the same frames, references and emitter buffers: nothing rendered twice
    assert via.meta["rendered"] == [] and "reference0" in via.meta["cache_hits"]
    with pytest.raises(DbenchInputError, match="gbuffer"):
        load_sequence(bound, gbuffer="psr", **kw)


def test_methods_needing_the_psr_normals_are_skipped_on_other_gbuffers():
    """``geo_normal`` and ``reflected_normal`` come with the PSR render only: a BMFR preset or an
    SVGF ``normal_buffer`` that reads them needs them, and is skipped on `matched` and
    `supersampled` scenes before anything is rendered; the default PSR scene provides them."""
    from dbench import datasets, registry

    psr = datasets.get_scene("orbit")
    assert {"geo_normal", "reflected_normal"} <= set(psr.provides)
    for gbuffer in ("matched", "supersampled"):
        other = datasets.get_scene("orbit", {"gbuffer": gbuffer})
        assert not {"geo_normal", "reflected_normal"} & set(other.provides)
        for name, params, buffer in (("bmfr", {"features": "reflected"}, "reflected_normal"),
                                     ("bmfr", {"features": "paper+geo"}, "geo_normal"),
                                     ("svgf", {"normal_buffer": "geo_normal"}, "geo_normal"),
                                     ("asvgf", {"normal_buffer": "reflected_normal"},
                                      "reflected_normal")):
            m = registry.get(name, **params)
            ok, why = m.applies_to(other.kind, set(other.provides))
            assert not ok and buffer in why
            assert m.applies_to(psr.kind, set(psr.provides))[0]
        assert registry.get("bmfr").applies_to(other.kind, set(other.provides))[0]
    assert datasets.get_scene("orbit", {"gbuffer": "psr-glossy"}).provides == psr.provides


def test_reshaded_mirror_passes_aim_at_their_own_virtual_points(renderer):
    """Above 1 spp each pass of a mirror pixel is re-shaded towards its own PSR virtual point
    (docs/temporal.md §2): from an unchanged camera, under unchanged lights, the re-shaded
    passes are the frame's own passes, whatever position the G-buffer holds (here zeros, where
    the mean over the passes used to be the target)."""
    from dbench.datasets.sequence.reshade import render_reshade

    mi = renderer
    d = _scene(mi, {"type": "conductor", "material": "none"})
    path = {"type": "path", "max_depth": 4}
    seeds = [3, 4, 5]
    scene = mi.load_dict(d, optimize=False)
    integ = mi.load_dict(path, optimize=False)
    passes = np.mean([np.array(mi.render(scene, spp=1, seed=s, integrator=integ), np.float64)
                      for s in seeds], axis=0)
    selected = np.ones((RES, RES), bool)
    got = render_reshade(d, path, (0.0, 0.0, 5.0), np.zeros((RES, RES, 3), np.float32),
                         selected, seeds)
    c = RES // 2
    assert passes[c, c].max() > 0.01  # the mirror shows the lit wall
    np.testing.assert_allclose(got, passes, rtol=1e-4, atol=1e-6)


def _glass_scene(mi):
    """:func:`_scene` with a glass pane (a dielectric rectangle) at 45° and a diffuse backdrop
    behind it, lit by a second light behind the pane: a camera ray either reflects to the wall
    at x = 3 (normal −x) or goes through to the backdrop at z = −3 (normal +z), so the normal
    says which lobe a pass drew."""
    T = mi.ScalarTransform4f
    backdrop = {"backdrop": {"type": "rectangle", "to_world": T().translate([0, 0, -3]).scale(8),
                             "bsdf": {"type": "diffuse",
                                      "reflectance": {"type": "rgb", "value": 0.5}}},
                "light2": {"type": "point", "position": [-1.0, 1.0, -2.0],
                           "intensity": {"type": "rgb", "value": 10.0}}}
    return _scene(mi, {"type": "dielectric"}, backdrop)


def test_psr_lobe_at_glass_is_a_function_of_the_camera_ray(renderer):
    """PSR draws the reflection/refraction choice at glass from a hash of the camera ray
    (psr.replayable_draw), not from the sampler after the colour's path: the G-buffer of a pass
    is the same whatever the colour integrator consumed (here path depths 2 and 8; it differed
    when the draws followed the colour's), while another seed (other rays) draws otherwise on
    some pixels, and both lobes occur."""
    from dbench.datasets.sequence.psr import psr_integrator

    mi = renderer
    d = _glass_scene(mi)
    short = _buffers(_render(mi, d, psr_integrator({"type": "path", "max_depth": 2}), seed=7))
    deep = _buffers(_render(mi, d, psr_integrator({"type": "path", "max_depth": 8}), seed=7))
    for name in ("depth", "position", "albedo", "normal"):
        np.testing.assert_array_equal(short[name], deep[name])
    c = RES // 2
    pane = np.zeros((RES, RES), bool)
    pane[c - 3:c + 3, c - 3:c + 3] = True
    refracted = np.abs(short["normal"][..., 2] - 1.0) < 1e-3  # the backdrop faces +z
    reflected = np.abs(short["normal"][..., 0] + 1.0) < 1e-3  # the wall faces −x
    other = _buffers(_render(mi, d, psr_integrator({"type": "path", "max_depth": 2}), seed=8))
    assert (refracted | reflected)[pane].all()
    changed = ((np.abs(other["normal"][..., 0] + 1.0) < 1e-3) != reflected)[pane].sum()
    assert 0 < changed < pane.sum()
    # the Fresnel reflectance of glass at 45° is about 5 %: reflections are the rare lobe
    many = [_buffers(_render(mi, d, psr_integrator({"type": "path", "max_depth": 2}), seed=s))
            for s in range(12)]
    share = np.mean([(np.abs(b["normal"][..., 0] + 1.0) < 1e-3)[pane].mean() for b in many])
    assert 0.01 < share < 0.15


def test_reshaded_glass_passes_aim_at_their_own_virtual_points(renderer):
    """Behind glass too, each pass is re-shaded towards its own PSR virtual point (PSR_VERSION
    4, RESHADE_VERSION 6): from an unchanged camera, under unchanged lights, the re-shaded
    passes equal the frame's own passes whatever position the G-buffer holds (zeros here;
    before, glass pixels aimed at that position)."""
    from dbench.datasets.sequence.reshade import render_reshade

    mi = renderer
    d = _glass_scene(mi)
    path = {"type": "path", "max_depth": 6}
    seeds = [3, 4, 5, 6]
    scene = mi.load_dict(d, optimize=False)
    integ = mi.load_dict(path, optimize=False)
    passes = np.mean([np.array(mi.render(scene, spp=1, seed=s, integrator=integ), np.float64)
                      for s in seeds], axis=0)
    got = render_reshade(d, path, (0.0, 0.0, 5.0), np.zeros((RES, RES, 3), np.float32),
                         np.ones((RES, RES), bool), seeds)
    c = RES // 2
    assert passes[c, c].max() > 0.01
    np.testing.assert_allclose(got, passes, rtol=1e-4, atol=1e-6)
