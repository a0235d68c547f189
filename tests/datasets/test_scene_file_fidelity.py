"""What a scene file's render cannot honour is refused or stated (README.md, "Mitsuba scene
files"): a scene with no emitter (black images every method would match) exits 2 naming the
file before anything renders, and a film's crop window, which dbench does not apply, is named
in the record and its report line (dbench/datasets/scene_files/fidelity.py)."""
from __future__ import annotations

import pytest

from dbench.cli import main
from dbench.errors import DbenchInputError


def _xml(tmp_path, name: str, extra: str = "", film: str = "", size=(16, 16)):
    path = tmp_path / name
    path.write_text(f'''<scene version="3.0.0">
  <sensor type="perspective">
    <transform name="to_world"><lookat origin="0,1,4" target="0,0,0" up="0,1,0"/></transform>
    <film type="hdrfilm"><integer name="width" value="{size[0]}"/>
      <integer name="height" value="{size[1]}"/>{film}</film>
  </sensor>
  <shape type="sphere"><bsdf type="diffuse"/></shape>{extra}
</scene>
''')
    return path


NO_LIGHT_PY = '''
def build(mi, width, height):
    T = mi.ScalarTransform4f
    return {"type": "scene",
            "sensor": {"type": "perspective", "fov": 45,
                       "to_world": T().look_at(origin=[0, 1, 4], target=[0, 0, 0], up=[0, 1, 0])},
            "ball": {"type": "sphere", "bsdf": {"type": "diffuse"}}%s}
'''
CROP = ('<integer name="crop_offset_x" value="4"/><integer name="crop_offset_y" value="2"/>'
        '<integer name="crop_width" value="8"/><integer name="crop_height" value="6"/>')


def test_a_scene_without_an_emitter_exits_2_before_rendering(renderer, tmp_path, capsys):
    from dbench.datasets.scene_files.load import resolve
    dark = _xml(tmp_path, "noemit.xml")
    with pytest.raises(DbenchInputError, match=r"noemit\.xml: the scene has no emitter, so "
                                               r"every image is black .*; add a light$"):
        resolve(dark)
    rc = main(["run", "--method", "noisy", "--scene", str(dark), "--res", "8", "--spp", "1",
               "--out", str(tmp_path / "out"), "--cache", str(tmp_path / "cache")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "no emitter" in err[0] and "noemit.xml" in err[0]
    assert not (tmp_path / "out").exists() and not (tmp_path / "cache").exists()
    py = tmp_path / "noemit.py"
    py.write_text(NO_LIGHT_PY % "")
    with pytest.raises(DbenchInputError, match=r"noemit\.py: the scene has no emitter"):
        resolve(py)
    # an environment (a constant emitter) or an area light is a light
    resolve(_xml(tmp_path, "sky.xml", '<emitter type="constant"/>'))
    resolve(_xml(tmp_path, "lamp.xml", '<shape type="sphere"><point name="center" x="0" y="3" '
                                       'z="0"/><emitter type="area"/></shape>'))
    (tmp_path / "sky.py").write_text(NO_LIGHT_PY % ', "sky": {"type": "constant"}')
    resolve(tmp_path / "sky.py")


def test_a_plugin_scene_without_an_emitter_is_refused(renderer):
    from dbench import datasets
    from dbench.datasets.scenes.build import plugin_build
    from dbench.datasets.scenes.record import Scene

    def build(mi, res):
        d = mi.cornell_box()
        d["sensor"]["film"].update(width=res.width, height=res.height)
        d["light"].pop("emitter")
        return d

    sc = Scene(name="dark-box", kind="steady", description="x",
               build=plugin_build(build, "dark-box"))
    with pytest.raises(DbenchInputError, match=r"scene dark-box: the scene has no emitter"):
        datasets.load(sc, spp=1, res=8, needs={"color"}, progress=False)


def test_an_xml_films_crop_window_is_stated_as_not_applied(renderer, tmp_path):
    from dbench import datasets
    from dbench.datasets.scene_files.fidelity import report_lines
    from dbench.datasets.scene_files.load import resolve
    sc = resolve(_xml(tmp_path, "crop.xml", '<emitter type="constant"/>', CROP))
    rec = sc.frame_meta["scene_file"]
    assert rec["file_crop"] == {"size": [8, 6], "offset": [4, 2]}
    frame = datasets.load(sc, spp=1, res=8, needs={"color"}, progress=False,
                          cache=datasets.Cache(tmp_path / "c"))
    film = frame.meta["scene_file_settings"]["film"]
    assert film == ("8×8 (file: 16×16, the same shape, with a crop window) — the file's crop "
                    "window 8×6 at (4, 2) is not applied: dbench renders the whole view")
    wide = report_lines(rec, "16x8")["film"]
    assert wide.startswith("16×8 (file: 16×16 with a crop window) — the requested size;")
    assert wide.endswith("; the file's crop window 8×6 at (4, 2) is not applied: dbench "
                         "renders the whole view")
    # without a crop the film line is as before
    plain = resolve(_xml(tmp_path, "plain.xml", '<emitter type="constant"/>'))
    assert plain.frame_meta["scene_file"]["file_crop"] is None
    assert report_lines(plain.frame_meta["scene_file"], 8)["film"] == \
        "8×8 (the file's 16×16, the same shape)"


def test_a_python_dictionarys_crop_window_is_stated(renderer, tmp_path):
    from dbench.datasets.scene_files.fidelity import report_lines
    from dbench.datasets.scene_files.load import resolve
    path = tmp_path / "crop.py"
    path.write_text((NO_LIGHT_PY % ', "sky": {"type": "constant"}').replace(
        '"type": "perspective",',
        '"type": "perspective", "film": {"type": "hdrfilm", "width": width, "height": height, '
        '"crop_width": 4, "crop_height": 4},'))
    rec = resolve(path).frame_meta["scene_file"]
    assert rec["file_crop"] == {"keys": ["crop_width", "crop_height"]}
    assert report_lines(rec, 8)["film"] == (
        "8×8 (file: the same size, with a crop window) — the file's film sets crop_width, "
        "crop_height, a crop window dbench does not apply: it renders the whole view")


def test_the_fov_of_a_focal_length_is_mitsubas(renderer):
    """dbench.resolution.focal_fov: the fov along x Mitsuba makes of a 35 mm-equivalent focal
    length on a film (diagonal angle, then x for the film's aspect), checked against the
    x_fov of Mitsuba's own sensor."""
    from dbench.datasets.mitsuba_env import mitsuba
    from dbench.resolution import focal_fov

    mi = mitsuba()
    for focal, ours, (w, h) in (("35mm", "35mm", (64, 48)), ("50mm", 50, (768, 576)),
                                ("20mm", "20mm", (32, 64))):
        sensor = mi.load_dict({"type": "perspective", "focal_length": focal,
                               "film": {"type": "hdrfilm", "width": w, "height": h}})
        assert focal_fov(ours, {"width": w, "height": h}) == pytest.approx(
            mi.traverse(sensor)["x_fov"][0], rel=1e-6)
    with pytest.raises(DbenchInputError, match="focal_length 'wide'"):
        focal_fov("wide", {})


@pytest.mark.parametrize("sensor, said", [
    ('"focal_length": "35mm"', "its focal_length 35mm is read as the fov along x"),
    ("", "its focal_length 50mm (Mitsuba's default) is read as the fov along x"),
])
def test_a_python_sensor_without_a_fov_renders_and_says_how(renderer, tmp_path, sensor, said):
    """A perspective sensor given a focal length, or no fov at all (Mitsuba's 50 mm), used to
    fail inside Mitsuba ("unreferenced property fov_axis"); it renders with the fov Mitsuba
    makes of it, and the record says so."""
    from dbench import datasets
    from dbench.datasets.scenes import catalogue as scenes

    path = tmp_path / "lens.py"
    path.write_text(NO_LIGHT_PY.replace('"fov": 45,', sensor + ("," if sensor else ""))
                    % ', "sky": {"type": "constant"}')
    frame = datasets.load(scenes.get(str(path)), spp=2, res=16, needs={"color"},
                          progress=False, cache=datasets.Cache(enabled=False))
    assert frame.color.shape == (16, 16, 3) and frame.color.mean() > 0
    assert said in frame.meta["scene_file_settings"]["sensor"]


@pytest.mark.parametrize("sensor", ["irradiancemeter", "orthographic"])
def test_a_sensor_dbench_cannot_render_through_is_refused_before_the_load(renderer, tmp_path,
                                                                          capfd, sensor):
    """One line, exit 2, from the parse alone: the scene was loaded first, so an irradiance
    meter (which warns about the film's gaussian filter while it is built) printed Mitsuba's
    warning above the refusal."""
    from dbench.datasets.scene_files import load
    # the file's first sensor; a perspective one follows, which Mitsuba would not render
    path = _xml(tmp_path, f"{sensor}.xml", '<emitter type="constant"/>')
    path.write_text(path.read_text().replace('<sensor type="perspective">',
                                             f'<sensor type="{sensor}"/><sensor '
                                             f'type="perspective">'))
    before = load._loaded_xml.cache_info().misses
    rc = main(["run", "--method", "noisy", "--scene", str(path), "--res", "8", "--spp", "1",
               "--quiet", "--out", str(tmp_path / "out"), "--cache", str(tmp_path / "cache")])
    captured = capfd.readouterr()
    err = (captured.err + captured.out).strip().splitlines()
    assert rc == 2 and len(err) == 1, err
    assert f"sensor {sensor} at {path}" in err[0] and "perspective or thinlens" in err[0]
    assert load._loaded_xml.cache_info().misses == before  # nothing of the file was built


LAMP = ('<shape type="sphere"><point name="center" x="0" y="3" z="0"/>'
        '<emitter type="area"><rgb name="radiance" value="{}"/></emitter></shape>')


@pytest.mark.parametrize("value, said", [("10, nan, 10", "[10., nan, 10.]"),
                                         ("$L", "[inf, inf, inf]")])
def test_a_number_of_the_file_that_is_not_finite_is_refused(renderer, tmp_path, capsys, value,
                                                            said):
    """A light of radiance (10, NaN, 10) rendered: dbench counts a NaN sample as 0, so the
    images and the reference were those of a light without its green, without a word (Mitsuba
    renders NaN there). A value of the file, or of a <default>, is refused as --scene-param
    L=nan already was, before anything renders."""
    path = _xml(tmp_path, "lamp.xml", '<default name="L" value="inf"/>' + LAMP.format(value))
    rc = main(["run", "--method", "noisy", "--scene", str(path), "--res", "8", "--spp", "1",
               "--quiet", "--out", str(tmp_path / "out"), "--cache", str(tmp_path / "cache")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1, err
    assert f"area radiance at {path} (line" in err[0] and said in err[0], err
    assert not (tmp_path / "out").exists() and not (tmp_path / "cache").exists()


def test_a_python_dictionary_value_that_is_not_finite_is_refused(renderer, tmp_path):
    from dbench.datasets.scene_files.load import resolve
    py = tmp_path / "lamp.py"
    py.write_text(NO_LIGHT_PY % ', "sky": {"type": "constant", "radiance": {"type": "rgb", '
                                '"value": [1, float("nan"), 1]}}')
    with pytest.raises(DbenchInputError, match=r"lamp\.py: build\(\)'s dictionary\['sky'\]"
                                               r"\['radiance'\]\['value'\] is \[1, nan, 1\]"):
        resolve(py)
    py.write_text(NO_LIGHT_PY % ', "sky": {"type": "constant", "radiance": {"type": "rgb", '
                                '"value": [1, 0.5, 1]}}')
    resolve(py)


def test_a_files_sample_count_and_seed_are_stated_where_the_run_differs(renderer, tmp_path,
                                                                        capsys):
    """dbench renders ``--spp`` samples with its own seeds: a sampler's ``sample_count`` of 64
    rendered at 2 spp, and its ``seed``, were left unread without a word ("independent (as
    in the file)"), where the film's size, replaced the same way, is stated."""
    from dbench import datasets
    from dbench.datasets.scene_files.fidelity import report_lines
    from dbench.datasets.scene_files.load import resolve
    sampler = ('<sampler type="independent"><integer name="sample_count" value="64"/>'
               '<integer name="seed" value="7"/></sampler>')
    path = _xml(tmp_path, "sampled.xml", '<emitter type="constant"/>')
    path.write_text(path.read_text().replace("<film ", sampler + "<film "))
    sc = resolve(path)
    rec = sc.frame_meta["scene_file"]
    assert rec["file_sampler_settings"] == {"sample_count": 64, "seed": 7}
    frame = datasets.load(sc, spp=2, res=8, needs={"color"}, progress=False, seed=3,
                          cache=datasets.Cache(tmp_path / "c"))
    assert frame.meta["scene_file_settings"]["sampler"] == (
        "independent, 2 spp, dbench's seeds from --seed 3 (file: independent, sample_count 64, "
        "seed 7) — the run's --spp sets the samples per pixel; dbench's seeds")
    # the file's own count, and no seed: as in the file
    same = _xml(tmp_path, "same.xml", '<emitter type="constant"/>')
    same.write_text(same.read_text().replace("<film ", sampler.replace(
        '<integer name="seed" value="7"/>', "").replace("64", "2") + "<film "))
    assert report_lines(resolve(same).frame_meta["scene_file"], 8, 2, 0)["sampler"] == \
        "independent (as in the file)"
    # a Python scene's dictionary sampler alike
    py = tmp_path / "sampled.py"
    py.write_text((NO_LIGHT_PY % ', "sky": {"type": "constant"}').replace(
        '"type": "perspective",',
        '"type": "perspective", "sampler": {"type": "independent", "sample_count": 64},'))
    line = report_lines(resolve(py).frame_meta["scene_file"], 8, 16, 0)["sampler"]
    assert line.startswith("independent, 16 spp (file: independent, sample_count 64)"), line
    rc = main(["run", "--method", "noisy", "--scene", str(path), "--res", "8", "--spp", "2",
               "--ref-spp", "8", "--out", str(tmp_path / "out"), "--cache", str(tmp_path / "c")])
    out = " ".join(capsys.readouterr().out.split())
    assert rc == 0 and "scene file changed: sampler independent, 2 spp" in out, out


def test_a_scene_whose_every_light_has_zero_area_exits_2_before_rendering(renderer, tmp_path,
                                                                          capsys):
    """An area light on a sphere of radius 0 or a rectangle scaled to a line emits nothing:
    the whole reference was rendered before its black image was refused, and the refusal
    blamed the camera's view."""
    from dbench.datasets.scene_files.load import resolve
    flat = ('<shape type="sphere"><float name="radius" value="0"/><point name="center" x="0" '
            'y="3" z="0"/><emitter type="area"/></shape><shape type="rectangle" id="strip">'
            '<transform name="to_world"><scale x="0" y="1" z="1"/><translate y="2"/>'
            '</transform><emitter type="area"/></shape>')
    dark = _xml(tmp_path, "flat.xml", flat)
    with pytest.raises(DbenchInputError, match=r"flat\.xml: every emitter is an area light on "
                                               r"a shape of zero surface area \(sphere, "
                                               r"rectangle 'strip'\)"):
        resolve(dark)
    rc = main(["run", "--method", "noisy", "--scene", str(dark), "--res", "8", "--spp", "1",
               "--ref-spp", "8", "--out", str(tmp_path / "out"),
               "--cache", str(tmp_path / "cache")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and "zero surface area" in err[-1], err
    assert not (tmp_path / "out").exists() and not (tmp_path / "cache").exists()
    # one light with an area is enough; a Python file's dictionary is read alike
    resolve(_xml(tmp_path, "lit.xml", flat + '<emitter type="constant"/>'))
    py = tmp_path / "flat.py"
    py.write_text(NO_LIGHT_PY % ', "lamp": {"type": "sphere", "radius": 0.0, "center": '
                                '[0, 3, 0], "emitter": {"type": "area"}}')
    with pytest.raises(DbenchInputError, match=r"flat\.py: every emitter is an area light"):
        resolve(py)
