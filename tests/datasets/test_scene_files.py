"""Scenes from files (Mitsuba XML, Python), any resolution, renders from folders, export."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from dbench.cli import main
from dbench.errors import DbenchInputError
from dbench.resolution import Res, parse_res

XML = """<scene version="3.0.0">
  <default name="light" value="8"/>
  <integrator type="path"><integer name="max_depth" value="5"/></integrator>
  <sensor type="perspective">
    <float name="fov" value="50"/>
    <transform name="to_world"><lookat origin="0,1.2,4" target="0,0.3,0" up="0,1,0"/></transform>
    <film type="hdrfilm"><integer name="width" value="80"/><integer name="height" value="48"/>
    </film>
  </sensor>
  <shape type="rectangle">
    <transform name="to_world"><rotate x="1" angle="-90"/><scale value="3"/></transform>
    <bsdf type="diffuse"><texture type="bitmap" name="reflectance">
      <string name="filename" value="tex/checker.exr"/></texture></bsdf>
  </shape>
  <shape type="sphere"><point name="center" x="0" y="0.5" z="0"/><float name="radius" value="0.5"/>
    <bsdf type="roughconductor"><string name="material" value="Au"/></bsdf></shape>
  <shape type="rectangle">
    <transform name="to_world"><rotate x="1" angle="90"/><translate y="2.5"/></transform>
    <emitter type="area"><rgb name="radiance" value="$light"/></emitter></shape>
  <emitter type="constant"><rgb name="radiance" value="0.05"/></emitter>
</scene>
"""

PY_SCENE = '''
description = "a lamp over a ball (Python scene file)"

def build(mi, width, height):
    T = mi.ScalarTransform4f
    return {"type": "scene",
            "sensor": {"type": "perspective", "fov": 45,
                       "to_world": T().look_at(origin=[0, 1, 4], target=[0, 0.3, 0], up=[0, 1, 0])},
            "floor": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale(3),
                      "bsdf": {"type": "diffuse"}},
            "ball": {"type": "sphere", "center": [0, 0.5, 0], "radius": 0.5},
            "lamp": {"type": "rectangle",
                     "to_world": T().translate([0, 1.0, -1.0]).scale(0.3),
                     "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [6, 6, 6]}}},
            "integrator": {"type": "path", "max_depth": 4}}
'''


def _write_xml(folder: Path) -> Path:
    (folder / "tex").mkdir(parents=True, exist_ok=True)
    y, x = np.mgrid[0:16, 0:16]
    checker = np.where(((x // 4 + y // 4) % 2)[..., None] == 0, 0.8, 0.2) * np.ones(3)
    _write_rgb(folder / "tex" / "checker.exr", checker)
    path = folder / "scene.xml"
    path.write_text(XML)
    return path


def _write_rgb(path: Path, rgb: np.ndarray) -> None:
    from dbench.datasets.folders import exr_layers
    exr_layers.write_channels(path, {c: rgb[..., i].astype(np.float32)
                                     for i, c in enumerate("RGB")})


def test_parse_res_forms_and_refusals():
    assert parse_res(64) == Res(64, 64) and parse_res("64").key == 64
    assert parse_res("160x90") == Res(160, 90) and parse_res((160, 90)).key == "160x90"
    assert parse_res("1280X720").text == "1280×720"
    for bad in ("0x3", "abc", "64x", -1, True, 1.5, (1, 2, 3), "5000x10"):
        with pytest.raises(DbenchInputError, match="res"):
            parse_res(bad)


def test_catalogue_keeps_square_keys_and_widens_non_square_views(renderer):
    from dbench.datasets.scenes import catalogue as scenes
    mi = renderer
    square = scenes.get("mirrors").scene_dict(mi, 32)["sensor"]
    assert square["fov_axis"] == "x" and square["film"]["width"] == 32
    wide = scenes.get("mirrors").scene_dict(mi, "48x32")["sensor"]
    assert wide["fov_axis"] == "smaller"
    assert (wide["film"]["width"], wide["film"]["height"]) == (48, 32)


def test_xml_scene_keeps_its_view_and_max_depth_and_keys_its_assets(renderer, tmp_path):
    from dbench import datasets
    from dbench.datasets.scenes import catalogue as scenes
    mi = renderer
    path = _write_xml(tmp_path)
    sc = scenes.get(str(path), {"light": "6"})
    assert sc.max_depth == 5 and sc.name == "scene.xml"
    assert datasets.default_res(sc) == Res(128, 77)
    # at the file's own size, dbench's camera sees what the file's camera sees
    frame = datasets.load(sc, spp=32, res="80x48", needs={"color"}, progress=False,
                          cache=datasets.Cache(tmp_path / "c"))
    own = np.array(mi.render(mi.load_file(str(path), light="6"), spp=256))
    assert frame.color.shape == (48, 80, 3)
    assert abs(frame.color.mean() - own.mean()) < 0.05 * own.mean()
    key = datasets.scene_fingerprint(sc, "40x24")
    assert key == datasets.scene_fingerprint(scenes.get(str(path), {"light": "6"}), "40x24")
    assert key != datasets.scene_fingerprint(scenes.get(str(path), {"light": "7"}), "40x24")
    assert key != datasets.scene_fingerprint(sc, "40x25")
    _write_rgb(path.parent / "tex" / "checker.exr", np.full((16, 16, 3), 0.5))  # edit a texture
    assert datasets.scene_fingerprint(sc, "40x24") != key


def test_xml_scene_runs_every_steady_method_at_a_non_square_size(renderer, tmp_path):
    from dbench import io, registry
    from dbench.registry import method_class
    path = _write_xml(tmp_path)
    out = tmp_path / "run"
    assert main(["run", "--method", "all", "--scene", str(path), "--scene-param", "light=5",
                 "--spp", "4", "--res", "40x24", "--ref-spp", "32", "--repeats", "1",
                 "--quiet", "--cache", str(tmp_path / "c"), "--out", str(out)]) == 0
    table = pd.read_csv(out / "metrics.csv")
    steady = [m for m in registry.available() if "steady" in method_class(m).kinds]
    assert set(steady) <= set(table["base_method"])
    assert set(table["res"].astype(str)) == {"40x24"}
    for m in table["method"]:
        assert io.read_exr(out / "images" / f"{m}.exr")["color"].shape == (24, 40, 3)


def test_bad_scene_files_exit_2_naming_the_file(renderer, tmp_path, capsys):
    bad = tmp_path / "broken.xml"
    bad.write_text("<scene version='3.0.0'><shape type='nosuchshape'/></scene>")
    assert main(["run", "--method", "noisy", "--scene", str(bad), "--quiet",
                 "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "broken.xml" in err and "Mitsuba could not load it" in err
    assert main(["run", "--method", "noisy", "--scene", str(tmp_path / "none.xml")]) == 2
    assert "no such file" in capsys.readouterr().err
    path = _write_xml(tmp_path)
    assert main(["run", "--method", "noisy", "--scene", "cornell", "--scene-param",
                 "light=1"]) == 2
    assert main(["run", "--method", "noisy", "--scene", str(path), "--scene-param",
                 "no-equals"]) == 2


def test_python_scene_files_steady_and_sequence(renderer, tmp_path):
    from dbench import datasets
    from dbench.datasets.scenes import catalogue as scenes
    steady = tmp_path / "lamp.py"
    steady.write_text(PY_SCENE)
    sc = scenes.get(str(steady))
    assert sc.kind == "steady" and sc.max_depth == 4
    frame = datasets.load(sc, spp=2, res="36x20", needs={"color", "albedo", "emitter"},
                          progress=False, cache=datasets.Cache(tmp_path / "c"))
    assert frame.color.shape == (20, 36, 3) and frame.emitter.max() > 0.5
    seq = tmp_path / "orbit_lamp.py"
    seq.write_text(PY_SCENE + '''
kind = "sequence"
frames = 3

def camera(i):
    return (4 * __import__("math").sin(0.1 * i), 1.0, 4 * __import__("math").cos(0.1 * i)), (0, 0.3, 0)
''')
    s = datasets.load(scenes.get(str(seq)), spp=1, res="24x16",
                      needs={"color", "motion", "albedo"}, progress=False,
                      cache=datasets.Cache(tmp_path / "c"))
    assert len(s) == 3 and s[2].motion.shape == (16, 24, 2)
    empty = tmp_path / "empty.py"
    empty.write_text("x = 1\n")
    with pytest.raises(DbenchInputError, match="empty.py.*build"):
        scenes.get(str(empty))
    # the suffix is matched in any case: "LAMP.PY" was taken and ended in an internal error
    # (importlib finds no loader for it)
    upper = tmp_path / "LAMP.PY"
    upper.write_text(PY_SCENE)
    assert scenes.get(str(upper)).max_depth == 4


def _oidn_folder(folder: Path, tmp_path: Path) -> Path:
    """A folder in OIDN's layout (hdr, alb, nrm and a reference; non-square) made from a
    render, as another renderer would write it."""
    from dbench import datasets
    cache = datasets.Cache(tmp_path / "c")
    folder.mkdir()
    for spp in (4, 16):
        f = datasets.load("cornell", spp=spp, res="40x24", ref_spp=64, progress=False,
                          cache=cache, needs={"color", "albedo", "normal", "reference"})
        _write_rgb(folder / f"view_{spp:04d}.hdr.exr", f.color)
        _write_rgb(folder / f"view_{spp:04d}.alb.exr", f.albedo)
        _write_rgb(folder / f"view_{spp:04d}.nrm.exr", f.normal)
    _write_rgb(folder / "view_ref.hdr.exr", f.reference)
    return folder


def test_oidn_folder_runs_noisy_jbf_and_oidn(renderer, tmp_path, capsys):
    folder = _oidn_folder(tmp_path / "renders", tmp_path)
    out = tmp_path / "run"
    assert main(["run", "--method", "noisy,jbf,oidn,statistical", "--scene", str(folder),
                 "--spp", "4", "--repeats", "1", "--quiet", "--out", str(out)]) == 0
    table = pd.read_csv(out / "metrics.csv")
    assert list(table["base_method"]) == ["noisy", "jbf", "oidn"]  # statistical: no stats
    assert set(table["res"].astype(str)) == {"40x24"}
    assert "statistical" in json.loads((out / "run.json").read_text())["skipped"]
    assert table.loc[table.base_method == "jbf", "rmse"].item() < \
        table.loc[table.base_method == "noisy", "rmse"].item()
    # several spp: --spp is required; sizes and seeds that cannot apply are refused
    assert main(["run", "--method", "noisy", "--scene", str(folder), "--quiet"]) == 2
    assert "choose one" in capsys.readouterr().err
    assert main(["run", "--method", "noisy", "--scene", str(folder), "--spp", "4",
                 "--res", "32", "--quiet", "--out", str(tmp_path / "x")]) == 2
    assert "40x24" in capsys.readouterr().err


def test_export_round_trip_reproduces_the_direct_run(renderer, tmp_path):
    common = ["--ref-spp", "64", "--cache", str(tmp_path / "c")]
    folder = tmp_path / "exported"
    assert main(["export", "cornell", "--out", str(folder), "--spp", "4,16", "--res", "40x24",
                 "--quiet", *common]) == 0
    methods = "noisy,jbf,oidn,statistical"
    direct, again = tmp_path / "direct", tmp_path / "again"
    assert main(["run", "--method", methods, "--scene", "cornell", "--spp", "16", "--res",
                 "40x24", "--repeats", "1", "--quiet", "--out", str(direct), *common]) == 0
    assert main(["run", "--method", methods, "--scene", str(folder), "--spp", "16",
                 "--repeats", "1", "--quiet", "--out", str(again)]) == 0
    a, b = pd.read_csv(direct / "metrics.csv"), pd.read_csv(again / "metrics.csv")
    assert list(a["method"]) == list(b["method"]) == methods.split(",")
    for col in ("rmse", "relmse", "ssim", "flip", "rmse_surface", "rmse_unbiased"):
        np.testing.assert_allclose(b[col], a[col], rtol=1e-6, err_msg=col)


def test_sweep_over_a_scene_file_and_a_folder(renderer, tmp_path):
    """File scenes and folders are first-class in sweeps: cells under the file's name, the
    scene's own size when --res is not given, and a finished sweep resumes."""
    from dbench.run.sweep import load_cells
    path = _write_xml(tmp_path)
    folder = _oidn_folder(tmp_path / "renders", tmp_path)
    out = tmp_path / "sweep"
    args = ["sweep", "--methods", "noisy,jbf", "--scenes", f"{path},{folder}", "--spp", "4",
            "--ref-spp", "16", "--repeats", "1", "--quiet", "--cache", str(tmp_path / "c"),
            "--out", str(out)]
    assert main(args) == 0
    cells = load_cells(out)
    by_scene = {(c["scene"], c["method"]): c for c in cells}
    assert by_scene[("scene.xml", "jbf")]["res"] == "128x77"
    assert by_scene[("view", "jbf")]["res"] == "40x24"
    assert all(c["status"] == "ok" for c in cells)
    # --ref-spp is the file's; the folder's reference states no spp and stays unknown
    assert by_scene[("scene.xml", "jbf")]["ref_spp"] == 16
    assert by_scene[("view", "jbf")]["ref_spp"] is None
    assert main(args) == 0  # resumes: nothing to compute


def test_exported_sequence_reads_back_as_a_sequence(renderer, tmp_path):
    from dbench import datasets, registry
    from dbench.run.harness import run_sequence_cell
    from dbench.datasets.scenes import catalogue as scenes
    folder = tmp_path / "seq"
    assert main(["export", "orbit", "--out", str(folder), "--spp", "4", "--res", "24x16",
                 "--frames", "3", "--ref-spp", "16", "--quiet",
                 "--cache", str(tmp_path / "c")]) == 0
    sc = scenes.get(str(folder))
    assert sc.kind == "sequence" and {"motion", "stats", "reference"} <= set(sc.provides)
    seq = datasets.load(sc, spp=4, res=None, needs={"color", "motion", "normal", "depth",
                                                  "position", "reference"})
    direct = datasets.load("orbit", spp=4, res="24x16", frames=3, ref_spp=16,
                           cache=datasets.Cache(tmp_path / "c"), progress=False,
                           needs={"color", "motion", "reference"})
    assert len(seq) == 3
    for a, b in zip(seq, direct):
        np.testing.assert_array_equal(a.color, b.color)
        np.testing.assert_array_equal(a.reference, b.reference)
        np.testing.assert_array_equal(a.motion, b.motion)
    result = run_sequence_cell(registry.get("accumulate"), [seq], warmup=1)
    assert not result.skipped and np.isfinite(result.metrics["rmse"])


def test_cornell_written_as_xml_renders_the_catalogue_cornell(renderer, tmp_path):
    """The scene-file benchmark's XML Cornell box is the catalogue's scene: same image up to
    Monte Carlo noise (independent samples), through the same sample loop."""
    from dbench.speed.files import cornell_xml
    from dbench.datasets import render
    from dbench.datasets.scenes import catalogue as scenes
    path = tmp_path / "cornell.xml"
    path.write_text(cornell_xml(renderer))
    # at 1024 spp the two means agree within 0.5 %; at 256 spp the noise allows ~3 %
    a = render.render_passes(scenes.get("cornell"), 16, 256, seed=1, progress=False)[0]
    b = render.render_passes(scenes.get(str(path)), 16, 256, seed=2, progress=False)[0]
    assert abs(a.mean() - b.mean()) < 0.05 * a.mean()
    np.testing.assert_allclose(b.mean(axis=(0, 1)), a.mean(axis=(0, 1)), rtol=0.08)
