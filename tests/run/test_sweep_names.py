"""Scenes of one name in a sweep (issue 44, second case): ``a/cbox.xml`` and ``b/cbox.xml`` keep
their own cells under their own labels, and catalogue scenes keep the cell names they had."""
from __future__ import annotations

from pathlib import Path

import pytest

from dbench.run import sweep
from dbench.run.sweep_names import scene_labels

SCENE = """<scene version="3.0.0">
  <sensor type="perspective">
    <transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>
    <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/>
    </film>
  </sensor>
  <shape type="sphere"><bsdf type="diffuse"><rgb name="reflectance" value="{albedo}"/></bsdf>
  </shape>
  <emitter type="constant"><rgb name="radiance" value="1"/></emitter>
</scene>
"""


def _scenes(root: Path) -> tuple[str, str]:
    for sub, albedo in (("a", "0.2"), ("b", "0.8")):
        (root / sub).mkdir(parents=True)
        (root / sub / "cbox.xml").write_text(SCENE.format(albedo=albedo))
    return str(root / "a" / "cbox.xml"), str(root / "b" / "cbox.xml")


def _config(tmp_path, scenes, **kw):
    return sweep.SweepConfig(methods=["noisy"], scenes=list(scenes), spp=[1], res=8, ref_spp=4,
                             repeats=1, cache=str(tmp_path / "cache"), **kw)


def _cell_files(out: Path) -> list[Path]:
    return sorted(p for p in out.glob("cells/*/*/*.json") if not p.name.startswith("."))


def test_labels_keep_names_and_part_same_named_scenes(tmp_path):
    a, b = _scenes(tmp_path / "x")
    c = tmp_path / "y" / "a" / "cbox.xml"  # ends like a: labelled by a longer end
    c.parent.mkdir(parents=True)
    c.write_text(SCENE.format(albedo="0.5"))
    again = str(Path(a).parent / ".." / "a" / "cbox.xml")  # a, spelled otherwise
    cfg = _config(tmp_path, ["cornell", a, b, str(c), again])
    assert scene_labels(cfg) == {"cornell": "cornell", a: "cbox.xml", b: "b/cbox.xml",
                                 str(c): "y/a/cbox.xml", again: "cbox.xml"}
    # catalogue scenes and unshared names keep their cell files and identities
    out = tmp_path / "out"
    assert sweep.cell_path(out, "cornell", 4, "jbf") == out / "cells/cornell/00004spp/jbf.json"
    assert sweep.cell_path(out, "cbox.xml", 4, "jbf") == out / "cells/cbox.xml/00004spp/jbf.json"
    folder = sweep.cell_path(out, "b/cbox.xml", 4, "jbf").relative_to(out / "cells").parts[0]
    assert "/" not in folder and folder not in ("cbox.xml", "b")
    scene = cfg.scene("cornell")
    assert sweep.cell_identity(cfg, scene, 4, "noisy", "fp")["scene"] == "cornell"


@pytest.mark.mitsuba
def test_same_named_scene_files_keep_both_sets_of_cells(renderer, tmp_path):
    a, b = _scenes(tmp_path / "scenes")
    out = tmp_path / "sweep"
    counts = sweep.run_sweep(_config(tmp_path, [a, b, a]), out, progress=False)
    assert counts["computed"] == 2 and counts["errors"] == 0
    cells = {c["scene"]: c for c in sweep.load_cells(out)}
    assert set(cells) == {"cbox.xml", "b/cbox.xml"} and len(_cell_files(out)) == 2
    assert cells["cbox.xml"]["identity"]["scene_fingerprint"] != \
        cells["b/cbox.xml"]["identity"]["scene_fingerprint"]
    assert (out / "cells" / "cbox.xml" / "00001spp" / "noisy.json").is_file()
    assert cells["cbox.xml"]["rmse"] != cells["b/cbox.xml"]["rmse"]
    before = {p: p.stat().st_mtime_ns for p in _cell_files(out)}
    # the same sweep again plans nothing, whatever the order the scenes come in
    groups, done, _ = sweep.plan(_config(tmp_path, [b, a]), out)
    assert groups == [] and done == 2
    again = sweep.run_sweep(_config(tmp_path, [a, b]), out, progress=False)
    assert again["computed"] == 0 and again["finished_before"] == 2
    assert {p: p.stat().st_mtime_ns for p in _cell_files(out)} == before


@pytest.mark.mitsuba
def test_a_sweep_extended_with_a_same_named_scene_adds_its_cells(renderer, tmp_path):
    a, b = _scenes(tmp_path / "scenes")
    out = tmp_path / "sweep"
    assert sweep.run_sweep(_config(tmp_path, [a]), out, progress=False)["computed"] == 1
    first = (out / "cells" / "cbox.xml" / "00001spp" / "noisy.json").read_bytes()
    # b alone: the folder's sweep.json names a first, so b takes another label, no refusal
    assert sweep.run_sweep(_config(tmp_path, [b]), out, progress=False)["computed"] == 1
    assert {c["scene"] for c in sweep.load_cells(out)} == {"cbox.xml", "b/cbox.xml"}
    assert (out / "cells" / "cbox.xml" / "00001spp" / "noisy.json").read_bytes() == first
    assert sweep.run_sweep(_config(tmp_path, [b, a]), out, progress=False)["computed"] == 0
