"""``--scene-param SCENE:NAME=VALUE``: a value for one scene of a sweep (or of ``render``,
``run``, ``export``), beside ``NAME=VALUE`` for every scene (dbench/datasets/scenes/scoped.py;
README.md, "Usage"). A scene file that needs a ``$parameter`` could not be swept beside
``cornell``: the value went to every scene, and cornell, which has none, refused it."""
from __future__ import annotations

import json

import pytest
from cli_args import lamp_scene, refused  # tests/cli_args.py

from dbench import cli
from dbench.datasets.scenes import scoped
from dbench.errors import DbenchInputError
from dbench.run import sweep


@pytest.fixture
def lamp(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "lamp.xml").write_text(lamp_scene())
    return "lamp.xml"


def _sweep(tmp_path, *extra, scenes="cornell,lamp.xml"):
    return ["sweep", "--methods", "noisy", "--scenes", scenes, "--spp", "2", "--res", "8",
            "--ref-spp", "16", "--repeats", "1", "--quiet", "--cache", str(tmp_path / "cache"),
            "--out", str(tmp_path / "S"), *extra]


@pytest.mark.parametrize("items, scenes, every, own", [
    (["g=1"], ["cornell"], {"g": "1"}, {}),
    (["cornell:g=1"], ["cornell", "a.xml"], {}, {"cornell": {"g": "1"}}),
    # a path holding ':' (a Windows drive) is read against the scenes as written
    (["C:\\s\\a.xml:light=2"], ["cornell", "C:\\s\\a.xml"], {}, {"C:\\s\\a.xml": {"light": "2"}}),
    # a value holding ':' and '=' is a value, where no scene of the command begins the item
    (["x=1.xml:r=2"], ["cornell"], {"x": "1.xml:r=2"}, {}),
    (["g=1", "cornell:g=1"], ["cornell"], {"g": "1"}, {"cornell": {"g": "1"}}),
])
def test_an_item_is_read_against_the_scenes_as_written(items, scenes, every, own):
    assert scoped.split(items, scenes, "--scenes") == (every, own)


@pytest.mark.parametrize("items, scenes, said", [
    (["x=1.xml:r=2"], ["x=1.xml"], "--scene-param x=1.xml:r=2: reads two ways, 'x=1.xml:r=2' "
     "for every scene or 'r=2' for x=1.xml; write that scene another way in --scenes"),
    (["a:b=c.xml:g=1"], ["a", "a:b=c.xml"], "reads two ways, 'b=c.xml:g=1' for a or 'g=1' for "
     "a:b=c.xml"),
    (["cornel:g=1"], ["cornell", "lamp.xml"], "--scene-param cornel:g=1: 'cornel' is not a scene "
     "of --scenes (cornell, lamp.xml); SCENE:NAME=VALUE names SCENE as written there"),
    (["garbage"], ["cornell"], "--scene-param: expected NAME=VALUE or SCENE:NAME=VALUE, got "
     "'garbage'"),
    (["g=1", "cornell:g=2"], ["cornell"], "--scene-param: g given twice for cornell, '1' (every "
     "scene) and '2' (cornell:g=2); give it once"),
    (["cornell:g=1", "cornell:g=2"], ["cornell"], "--scene-param cornell: g given twice, '1' and "
     "'2'; give it once"),
    (["cornell:g=nan"], ["cornell"], "--scene-param cornell:g=nan: 'nan' is not a finite number"),
])
def test_an_item_that_reads_two_ways_or_names_no_scene_is_refused(items, scenes, said):
    with pytest.raises(DbenchInputError) as err:
        scoped.split(items, scenes, "--scenes")
    assert said in str(err.value) and "\n" not in str(err.value)


def test_a_sweep_refuses_a_scope_before_anything_renders(lamp, tmp_path, capsys):
    # today's refusal stays: a value for every scene goes to cornell too, which has none
    said = refused(capsys, _sweep(tmp_path, "--scene-param", "light=5"),
                   "--scene-param: cornell is a catalogue scene without parameters")
    assert said.endswith("; --scene-param SCENE:NAME=VALUE gives a value to one scene only\n")
    refused(capsys, _sweep(tmp_path, "--scene-param", "textured:light=5"),
            "'textured' is not a scene of --scenes (cornell, lamp.xml)")
    # a scope names the scene as written: ./lamp.xml is another spelling
    refused(capsys, _sweep(tmp_path, "--scene-param", "./lamp.xml:light=5"),
            "'./lamp.xml' is not a scene of --scenes")
    # the refusals of a scene's parameters name the scene and its valid ones, scoped too
    refused(capsys, _sweep(tmp_path, "--scene-param", "fog-transient:nope=1",
                           scenes="cornell,fog-transient"),
            "--scene-param nope: fog-transient has no parameter 'nope'; valid: ", "sigma_s")
    refused(capsys, _sweep(tmp_path, "--scene-param", "cornell:light=5"),
            "--scene-param: cornell is a catalogue scene without parameters")
    assert not (tmp_path / "S").exists() and not (tmp_path / "cache").exists()


def test_a_config_built_in_python_refuses_a_scope_of_no_scene(tmp_path):
    config = sweep.SweepConfig(methods=["noisy"], scenes=["cornell"], spp=[2],
                               scene_params_by_scene={"lamp.xml": {"light": "5"}})
    with pytest.raises(DbenchInputError, match=r"'lamp.xml' is not a scene of --scenes "
                                               r"\(cornell\)"):
        sweep.run_sweep(config, tmp_path / "S", progress=False)
    config = sweep.SweepConfig(methods=["noisy"], scenes=["cornell"], spp=[2],
                               scene_params={"g": "1"},
                               scene_params_by_scene={"cornell": {"g": "2"}})
    with pytest.raises(DbenchInputError, match="g given twice for cornell"):
        config.validate()
    assert not (tmp_path / "S").exists()


@pytest.mark.mitsuba
def test_a_scene_file_is_swept_beside_cornell_with_its_own_value(renderer, lamp, tmp_path,
                                                                 capsys):
    assert cli.main(_sweep(tmp_path, "--scene-param", "lamp.xml:light=5")) == 0
    capsys.readouterr()
    stored = json.loads((tmp_path / "S" / "sweep.json").read_text())
    # the recorded config holds each scene's own values; cornell has none
    assert stored["config"]["scene_params"] == {}
    assert stored["config"]["scene_params_by_scene"] == {"lamp.xml": {"light": "5"}}
    assert stored["runs"][0]["request"]["scene_params_by_scene"] == {"lamp.xml": {"light": "5"}}
    cells = {c["scene"]: c for c in sweep.load_cells(tmp_path / "S")}
    assert {s: c["status"] for s, c in cells.items()} == {"cornell": "ok", "lamp.xml": "ok"}
    # another value for that scene is another scene: a resume with it is refused, as a value
    # given for every scene is, before anything renders
    refused(capsys, _sweep(tmp_path, "--scene-param", "lamp.xml:light=6"),
            "1 finished cell(s) under the same label were computed with other settings or "
            "code: cells/lamp.xml/00002spp/noisy.json (differs in scene_fingerprint)")
    # the same value given for every scene of a sweep of the file alone is the same cell
    assert cli.main(_sweep(tmp_path, "--scene-param", "light=5", scenes="lamp.xml")) == 0
    assert "sweep S: 0 cells computed, 0 not applicable, 1 already finished" in \
        capsys.readouterr().out.replace(str(tmp_path / "S"), "S")
    again = json.loads((tmp_path / "S" / "sweep.json").read_text())["config"]
    assert again["scene_params_by_scene"] == {"lamp.xml": {"light": "5"}}


@pytest.mark.mitsuba
def test_run_takes_the_scoped_form_naming_its_one_scene(renderer, lamp, tmp_path, capsys):
    run = ["run", "--method", "noisy", "--scene", lamp, "--spp", "2", "--res", "8", "--ref-spp",
           "16", "--repeats", "1", "--quiet", "--cache", str(tmp_path / "cache"), "--out"]
    refused(capsys, run + [str(tmp_path / "R0"), "--scene-param", "cornell:light=5"],
            "--scene-param cornell:light=5: 'cornell' is not a scene of --scene (lamp.xml)")
    assert not (tmp_path / "R0").exists()
    assert cli.main(run + [str(tmp_path / "R"), "--scene-param", "lamp.xml:light=5"]) == 0
    assert "- scene parameters: light=5" in (tmp_path / "R" / "report.md").read_text()


def test_a_missing_value_names_the_scoped_form_too(tmp_path, lamp, capsys):
    # beside cornell, the unscoped form alone would be refused by cornell: the line says both
    refused(capsys, _sweep(tmp_path), "lamp.xml: undefined parameter $light",
            "--scene-param light=VALUE (SCENE:light=VALUE for this scene alone")
    assert not (tmp_path / "S").exists()
