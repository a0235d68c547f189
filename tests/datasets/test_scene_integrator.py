"""Mitsuba XML scene files render with the file's own integrator and settings (wherever they are
set), say how the render differs from the file, and key their renders on it."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dbench.cli import main
from dbench.errors import DbenchInputError

SENSOR = """
  <sensor type="perspective">
    <float name="fov" value="40"/>
    <transform name="to_world"><lookat origin="0,0,3.6" target="0,0,0" up="0,1,0"/></transform>
    <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/>
      <rfilter type="box"/></film>
  </sensor>"""

# a Cornell-like box of rectangles lit by one small area light under the ceiling
BOX = """
  <bsdf type="diffuse" id="white"><rgb name="reflectance" value="0.75"/></bsdf>
  <shape type="rectangle"><transform name="to_world"><rotate x="1" angle="-90"/>
    <translate y="-1"/></transform><ref id="white"/></shape>
  <shape type="rectangle"><transform name="to_world"><rotate x="1" angle="90"/>
    <translate y="1"/></transform><ref id="white"/></shape>
  <shape type="rectangle"><transform name="to_world"><translate z="-1"/></transform>
    <ref id="white"/></shape>
  <shape type="rectangle"><transform name="to_world"><rotate y="1" angle="90"/>
    <translate x="-1"/></transform>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.63,0.065,0.05"/></bsdf></shape>
  <shape type="rectangle"><transform name="to_world"><rotate y="1" angle="-90"/>
    <translate x="1"/></transform>
    <bsdf type="diffuse"><rgb name="reflectance" value="0.14,0.45,0.091"/></bsdf></shape>
  <shape type="rectangle"><transform name="to_world"><rotate x="1" angle="90"/>
    <scale value="0.25"/><translate y="0.99"/></transform>
    <bsdf type="diffuse"><rgb name="reflectance" value="0"/></bsdf>
    <emitter type="area"><rgb name="radiance" value="17,12,4"/></emitter></shape>"""


def _scene(folder: Path, name: str, body: str) -> Path:
    """A scene file ``name`` in ``folder``: ``body`` (integrator, defaults, extra shapes), the
    camera and the box."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    path.write_text(f'<scene version="3.0.0">\n{body}\n{SENSOR}\n{BOX}\n</scene>\n')
    return path


def _integrator(kind: str, depth: int | None = None, inner: str = "") -> str:
    depth_xml = f'<integer name="max_depth" value="{depth}"/>' if depth is not None else ""
    return f'<integrator type="{kind}">{depth_xml}{inner}</integrator>'


def _fragment(folder: Path, depth: int) -> None:
    (folder / "fragments").mkdir(parents=True, exist_ok=True)
    (folder / "fragments" / "integrator.xml").write_text(
        f'<scene version="3.0.0">{_integrator("path", depth)}</scene>\n')


def _load(sc, cache, spp: int = 4, seed: int = 0):
    from dbench import datasets
    return datasets.load(sc, spp=spp, res=16, needs={"color"}, seed=seed, progress=False,
                         cache=cache)


def test_max_depth_in_an_include_is_honoured_and_keys_the_render(renderer, tmp_path, tmp_cache):
    from dbench import datasets
    from dbench.datasets.scene_files import load as scene_files
    path = _scene(tmp_path, "box.xml", '<include filename="fragments/integrator.xml"/>')
    _fragment(tmp_path, 6)
    sc6 = scene_files.resolve(path)
    assert sc6.max_depth == 6 and sc6.integrator_plan.render == {"type": "path", "max_depth": 6}
    first = _load(sc6, tmp_cache)
    rec = first.meta["scene_file"]
    assert (rec["integrator"], rec["file_integrator"], rec["max_depth"]) == ("path", "path", 6)
    assert rec["replaced"] is None and rec["filter"] == "box" and rec["file_filter"] == "box"
    assert first.meta["scene_file_settings"]["max_depth"].startswith("6 ")
    assert "color" in first.meta["rendered"]
    assert "color" in _load(sc6, tmp_cache).meta["cache_hits"]
    key6 = datasets.scene_fingerprint(sc6, 16)

    _fragment(tmp_path, 2)  # the same scene file, only the fragment edited
    sc2 = scene_files.resolve(path)
    assert sc2.max_depth == 2 and sc2.frame_meta["scene_file"]["max_depth"] == 2
    assert datasets.scene_fingerprint(sc2, 16) != key6
    second = _load(sc2, tmp_cache)
    assert "color" in second.meta["rendered"]  # re-rendered, not the max_depth 6 entry
    assert second.color.mean() < first.color.mean()  # fewer bounces, less light


def test_defaults_and_parameters_set_max_depth_and_minus_one_is_unlimited(renderer, tmp_path,
                                                                          tmp_cache):
    from dbench.datasets.scene_files import load as scene_files
    path = _scene(tmp_path, "box.xml", '<default name="depth" value="3"/>'
                  + _integrator("path", "$depth"))
    assert scene_files.resolve(path).max_depth == 3
    assert scene_files.resolve(path, {"depth": "5"}).max_depth == 5
    unlimited = scene_files.resolve(path, {"depth": "-1"})
    assert unlimited.max_depth == -1 and unlimited.integrator_plan.render["max_depth"] == -1
    frame = _load(unlimited, tmp_cache)
    assert frame.meta["scene_file"]["max_depth"] == -1
    assert frame.meta["scene_file_settings"]["max_depth"].startswith("-1 (unlimited")
    assert np.isfinite(frame.color).all() and frame.color.mean() > 0


def test_direct_is_kept_and_renders_direct_lighting(renderer, tmp_path, tmp_cache):
    """dbench's render of a ``direct`` file agrees with Mitsuba's own render of the file and is
    clearly darker than the same box with ``path`` (the walls' indirect light is missing)."""
    from dbench.datasets.scene_files import load as scene_files
    mi = renderer
    direct = _scene(tmp_path, "direct.xml", _integrator("direct"))
    path = _scene(tmp_path, "path.xml", _integrator("path", 8))
    sc = scene_files.resolve(direct)
    frame = _load(sc, tmp_cache, spp=64)
    rec = frame.meta["scene_file"]
    assert (rec["integrator"], rec["file_integrator"], rec["replaced"]) == ("direct", "direct",
                                                                          None)
    assert rec["max_depth"] is None
    assert frame.meta["scene_file_settings"]["integrator"] == "direct (as in the file)"
    # the lower half: floor and walls, away from the lamp whose few hits dominate the noise
    own = np.array(mi.render(mi.load_file(str(direct)), spp=256, seed=5))[8:].mean()
    assert abs(frame.color[8:].mean() - own) < 0.03 * own
    lit = _load(scene_files.resolve(path), tmp_cache, spp=64).color[8:].mean()
    assert frame.color[8:].mean() < 0.85 * lit


def test_wrappers_are_unwrapped_and_a_light_tracer_is_replaced(renderer, tmp_path, tmp_cache):
    from dbench.datasets.scene_files import load as scene_files
    moment = scene_files.resolve(_scene(tmp_path, "moment.xml", _integrator(
        "moment", inner=_integrator("path", -1))))
    rec = moment.frame_meta["scene_file"]
    assert (rec["integrator"], rec["file_integrator"], rec["max_depth"]) == (
        "path", "moment(path)", -1)
    assert rec["replaced"] is None and "moment unwrapped" in rec["integrator_notes"][0]
    assert _load(moment, tmp_cache).color.mean() > 0
    aov = scene_files.resolve(_scene(tmp_path, "aov.xml", _integrator(
        "aov", inner='<string name="aovs" value="dd:depth"/>' + _integrator("volpath", 3))))
    assert aov.integrator_plan.render == {"type": "volpath", "max_depth": 3}
    ptracer = scene_files.resolve(_scene(tmp_path, "ptracer.xml", _integrator("ptracer", 5)))
    rec = ptracer.frame_meta["scene_file"]
    assert (rec["integrator"], rec["file_integrator"], rec["max_depth"]) == ("path", "ptracer", 5)
    assert "one sample" in rec["replaced"]
    line = ptracer.frame_meta["scene_file_settings"]["integrator"]
    assert line.startswith("path (file: ptracer) — replaced because ptracer")


def test_shapegroup_instances_render_where_the_spheres_are(renderer, tmp_path, tmp_cache):
    """Two instances of a shapegroup render as two plain spheres at the same places do."""
    from dbench.datasets.scene_files import load as scene_files
    integ = _integrator("path", 4)
    group = ('<shape type="shapegroup" id="ball"><shape type="sphere">'
             '<float name="radius" value="0.3"/><ref id="white"/></shape></shape>')
    places = [(-0.45, -0.7), (0.45, -0.7)]
    instanced = "".join(f'<shape type="instance"><ref id="ball"/><transform name="to_world">'
                        f'<translate x="{x}" y="{y}"/></transform></shape>' for x, y in places)
    plain = "".join(f'<shape type="sphere"><point name="center" x="{x}" y="{y}" z="0"/>'
                    f'<float name="radius" value="0.3"/><ref id="white"/></shape>'
                    for x, y in places)
    # the groups are declared after the box's shared BSDF, which they refer to
    a = _scene(tmp_path, "instanced.xml", integ)
    a.write_text(a.read_text().replace("</scene>", group + instanced + "</scene>"))
    b = _scene(tmp_path, "plain.xml", integ)
    b.write_text(b.read_text().replace("</scene>", plain + "</scene>"))
    with_instances = _load(scene_files.resolve(a), tmp_cache, spp=16).color
    with_spheres = _load(scene_files.resolve(b), tmp_cache, spp=16).color
    empty = _load(scene_files.resolve(_scene(tmp_path / "e", "empty.xml", integ)), tmp_cache,
                  spp=16).color
    scale = np.abs(with_spheres - empty).mean()  # what the two balls add to the image
    assert np.abs(with_instances - with_spheres).mean() < 0.01 * scale


def test_polarized_and_spectral_files_render_in_rgb_with_their_conversions(renderer, tmp_path,
                                                                           tmp_cache):
    from dbench.datasets.scene_files import load as scene_files
    extra = ('<shape type="sphere"><float name="radius" value="0.3"/><bsdf type="pplastic"/>'
             '</shape><shape type="sphere"><point name="center" x="0.5" y="-0.6" z="0"/>'
             '<float name="radius" value="0.2"/><bsdf type="diffuse"><spectrum name="reflectance"'
             ' value="400:0.1, 500:0.5, 600:0.8, 700:0.2"/></bsdf></shape>')
    sc = scene_files.resolve(_scene(tmp_path, "stokes.xml", _integrator(
        "stokes", inner=_integrator("path", 4)) + extra))
    rec = sc.frame_meta["scene_file"]
    assert (rec["integrator"], rec["file_integrator"], rec["max_depth"]) == (
        "path", "stokes(path)", 4)
    assert "without polarization" in rec["integrator_notes"][0]
    conversions = sc.frame_meta["scene_file_settings"]["conversions"]
    assert "per wavelength converted to RGB" in conversions and "pplastic" in conversions
    assert _load(sc, tmp_cache).color.mean() > 0


def test_constructs_without_an_rgb_form_exit_2_before_rendering(renderer, tmp_path, tmp_cache,
                                                                capsys):
    from dbench.datasets.scene_files import load as scene_files
    hot = ('<emitter type="constant"><spectrum type="blackbody" name="radiance">'
           '<float name="temperature" value="3000"/></spectrum></emitter>')
    bad = _scene(tmp_path, "blackbody.xml", _integrator("path", 4) + hot)
    with pytest.raises(DbenchInputError, match='blackbody.*no RGB form'):
        scene_files.resolve(bad)
    assert main(["run", "--method", "noisy", "--scene", str(bad), "--quiet",
                 "--cache", str(tmp_path / "c"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and 'spectrum type="blackbody"' in err[0]
    # refused before any object of the file was made: other scenes still render
    ok = scene_files.resolve(_scene(tmp_path, "ok.xml", _integrator("path", 2)))
    assert _load(ok, tmp_cache).color.mean() > 0
    two = _scene(tmp_path, "two.xml", _integrator("path") + _integrator("direct"))
    with pytest.raises(DbenchInputError, match="one integrator"):
        scene_files.resolve(two)


def test_the_terminal_says_what_the_render_changed_and_the_parameters(renderer, tmp_path,
                                                                       capsys):
    """A replaced integrator and the --scene-param values are printed under the reference line
    of `dbench run` and stated in report.md; a file rendered as it is adds no such line."""
    light = '<default name="power" value="17"/>' + _integrator("ptracer", 5)
    changed = _scene(tmp_path, "ptracer.xml", light)
    changed.write_text(changed.read_text().replace('value="17,12,4"', 'value="$power"'))
    common = ["--method", "noisy", "--spp", "2", "--res", "8", "--ref-spp", "8",
              "--cache", str(tmp_path / "c")]
    assert main(["run", "--scene", str(changed), "--scene-param", "power=20",
                 "--out", str(tmp_path / "a"), *common]) == 0
    out = capsys.readouterr().out
    assert "scene file changed: integrator path (file: ptracer) — replaced because" in out
    assert "scene parameters: power=20" in out
    report = (tmp_path / "a" / "report.md").read_text()
    assert "power=20" in report and "replaced because" in report
    kept = _scene(tmp_path / "k", "kept.xml", _integrator("path", 3))
    assert main(["run", "--scene", str(kept), "--out", str(tmp_path / "b"), *common]) == 0
    out = capsys.readouterr().out
    assert "scene file changed" not in out and "scene parameters" not in out
    # another shape than the file's film, and a second sensor, are said
    two = _scene(tmp_path / "s", "two.xml", _integrator("path", 3) + SENSOR)
    assert main(["run", "--scene", str(two), "--out", str(tmp_path / "w"), *common[:4],
                 "--res", "8x6", *common[6:]]) == 0
    out = " ".join(capsys.readouterr().out.split())
    assert ("scene file changed: film 8×6 (file: 16×16) — the requested size; the field of "
            "view is kept along the smaller side") in out
    report = (tmp_path / "w" / "report.md").read_text()
    assert "the first of its 2 sensors" in report and "film: 8×6 (file: 16×16) — the requested " \
        "size" in report


def test_a_max_depth_of_0_is_refused_before_anything_renders(renderer, tmp_path, capsys):
    """max_depth 0 gathers no light at all: the reference was rendered, found black and
    refused afterwards, blaming the lights ("no light of its emitters reaches the camera")."""
    from dbench.datasets.scene_files.load import resolve
    path = _scene(tmp_path, "dark.xml", '<integrator type="path">'
                                        '<integer name="max_depth" value="0"/></integrator>')
    with pytest.raises(DbenchInputError, match=r"dark\.xml: max_depth 0 \(path\) gathers no "
                                               r"light.*give max_depth -1 \(unlimited\) or 1"):
        resolve(path)
    # through a <default> and a wrapper alike, and a Python file's module max_depth
    wrapped = _scene(tmp_path, "wrapped.xml", '<default name="d" value="0"/><integrator '
                     'type="aov"><string name="aovs" value="dd.y:depth"/><integrator '
                     'type="volpath"><integer name="max_depth" value="$d"/></integrator>'
                     '</integrator>')
    with pytest.raises(DbenchInputError, match=r"max_depth 0 \(volpath\)"):
        resolve(wrapped)
    py = tmp_path / "dark.py"
    py.write_text("max_depth = 0\n\ndef build(mi, width, height):\n    d = mi.cornell_box()\n"
                  "    d['sensor']['film'].update(width=width, height=height)\n    return d\n")
    with pytest.raises(DbenchInputError, match=r"dark\.py: max_depth 0 \(path\)"):
        resolve(py)
    rc = main(["run", "--method", "noisy", "--scene", str(path), "--res", "8", "--spp", "1",
               "--ref-spp", "8", "--out", str(tmp_path / "out"),
               "--cache", str(tmp_path / "cache")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "max_depth 0" in err[-1], err
    assert not (tmp_path / "out").exists() and not (tmp_path / "cache").exists()
