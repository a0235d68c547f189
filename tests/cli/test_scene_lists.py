"""A scene list (``sweep --scenes``, ``render --scene``) takes a path that exists whole, also when
its name holds a comma, refuses a list that reads as scenes two ways, and ``--scenes`` given more
than once adds each list's scenes (dbench/cli/scene_list.py; README.md, "Usage"):
``--scenes /tmp/my,scene.xml`` was refused as the unknown scene ``/tmp/my``, and ``--scenes
cornell --scenes textured`` swept textured alone without a word."""
from __future__ import annotations

import pytest

from dbench import cli
from dbench.cli.scene_list import readings, scene_names
from dbench.errors import DbenchInputError

SCENE = """<scene version="3.0.0">
  <sensor type="perspective">
    <transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>
    <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/>
    </film>
  </sensor>
  <shape type="sphere"><bsdf type="diffuse"/></shape>
  <emitter type="constant"><rgb name="radiance" value="1"/></emitter>
</scene>
"""


@pytest.fixture
def files(tmp_path, monkeypatch):
    """Scene files in the working directory: ``a.xml``, ``b.xml``, ``my,scene.xml`` and
    ``x,y/s.xml`` (a folder whose name holds a comma)."""
    monkeypatch.chdir(tmp_path)
    for name in ("a.xml", "b.xml", "my,scene.xml", "x,y/s.xml"):
        (tmp_path / name).parent.mkdir(exist_ok=True)
        (tmp_path / name).write_text(SCENE)
    return tmp_path


@pytest.mark.parametrize("text, items", [
    ("cornell,a.xml", ["cornell", "a.xml"]),
    ("my,scene.xml", ["my,scene.xml"]),
    ("cornell, my,scene.xml ,b.xml", ["cornell", "my,scene.xml", "b.xml"]),
    ("x,y/s.xml,textured", ["x,y/s.xml", "textured"]),
])
def test_a_path_that_exists_is_one_scene(files, text, items):
    assert scene_names(text, "--scenes") == items


def test_a_list_that_reads_as_scenes_two_ways_is_refused(files):
    (files / "a.xml,b.xml").write_text(SCENE)
    assert len(readings("a.xml,b.xml", {"cornell"})) == 2
    with pytest.raises(DbenchInputError, match=r"^--scenes: 'a.xml,b.xml' reads as scenes two "
                       r"ways, 'a.xml' \+ 'b.xml' or 'a.xml,b.xml'; rename"):
        scene_names("a.xml,b.xml", "--scenes")
    # in a longer list too, and whichever option gives it
    with pytest.raises(DbenchInputError, match=r"^--scene: 'cornell,a.xml,b.xml' reads"):
        scene_names("cornell,a.xml,b.xml", "--scene")


@pytest.mark.parametrize("text, said", [
    # the unknown name is the one refused, not a piece of the path beside it
    ("my,scene.xml,nosuch", "unknown scene 'nosuch'"),
    ("my, scene.xml", "unknown scene 'my'"),  # no such file: its pieces are the items
    ("my,scene.xml,,cornell", "--scenes: an empty item in 'my,scene.xml,,cornell'"),
])
def test_a_list_with_an_unknown_scene_names_it(files, capsys, text, said):
    rc = cli.main(["sweep", "--scenes", text, "--methods", "noisy", "--spp", "4",
                   "--out", str(files / "out")])
    err = capsys.readouterr().err
    assert rc == 2 and said in err and err.count("\n") == 1, err
    assert not (files / "out").exists()


@pytest.fixture
def swept(monkeypatch):
    """The scenes ``dbench sweep`` would run: run_sweep records its config and refuses."""
    from dbench.run import sweep

    seen = []

    def record(config, out, **kw):
        seen.append(list(config.scenes))
        raise DbenchInputError("stand-in: nothing is swept here")

    monkeypatch.setattr(sweep, "run_sweep", record)
    return seen


@pytest.mark.parametrize("argv, scenes", [
    (["--scenes", "cornell", "--scenes", "textured"], ["cornell", "textured"]),
    (["--scenes", "cornell,{d}/my,scene.xml", "--scenes", "a.xml"],
     ["cornell", "{d}/my,scene.xml", "a.xml"]),
])
def test_sweep_takes_every_scenes_option_and_paths_whole(files, swept, capsys, argv, scenes):
    argv = [a.format(d=files) for a in argv]
    assert cli.main(["sweep", *argv, "--methods", "noisy", "--spp", "4", "--out",
                     str(files / "out")]) == 2
    assert "stand-in" in capsys.readouterr().err
    assert swept == [[s.format(d=files) for s in scenes]]


@pytest.mark.parametrize("argv, said", [
    (["--scenes", "cornell", "--scenes", "cornell"], "--scenes: 'cornell' is given twice"),
    (["--scenes", "all", "--scenes", "cornell"], "'all' stands alone"),
])
def test_repeated_scenes_options_refuse_what_one_list_refuses(files, swept, capsys, argv, said):
    assert cli.main(["sweep", *argv, "--methods", "noisy", "--spp", "4", "--out",
                     str(files / "out")]) == 2
    err = capsys.readouterr().err
    assert said in err and err.count("\n") == 1 and swept == [], err


def test_render_takes_a_path_with_a_comma_whole(files, monkeypatch, capsys):
    from dbench import datasets

    loaded = []

    def load(scene, **kw):
        loaded.append(scene.name)
        raise DbenchInputError("stand-in: nothing is rendered here")

    monkeypatch.setattr(datasets, "load", load)
    assert cli.main(["render", "--scene", f"{files}/my,scene.xml", "--res", "8", "--cache",
                     str(files / "cache")]) == 2
    assert "stand-in" in capsys.readouterr().err and loaded == ["my,scene.xml"]


@pytest.mark.parametrize("argv, said", [
    (["--scenes", "a.xml,./a.xml"], "'a.xml' and './a.xml' name the same item"),
    (["--scenes", "a.xml", "--scenes", "{d}/x,y/../a.xml"],
     "'a.xml' and '{d}/x,y/../a.xml' name the same item"),
])
def test_one_scene_named_two_ways_is_refused(files, swept, capsys, argv, said):
    """It was swept once, under one label, as if given once."""
    argv = [a.format(d=files) for a in argv]
    assert cli.main(["sweep", *argv, "--methods", "noisy", "--spp", "4", "--out",
                     str(files / "out")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("dbench: --scenes: " + said.format(d=files)), err
    assert err.count("\n") == 1 and swept == []


@pytest.mark.parametrize("name, text, said", [
    ("nosensor.xml", SCENE.replace("<sensor", "<!-- ").replace("</sensor>", " -->"),
     "the file has no <sensor>"),
    ("nosuch.xml", None, "no such file")])
def test_a_scene_refused_in_a_sweep_names_the_scenes_option(files, capsys, name, text, said):
    # a scene file's refusal inside a sweep said "--scene X", an option sweep does not have
    if text is not None:
        (files / name).write_text(text)
    assert cli.main(["sweep", "--scenes", f"cornell,{name}", "--methods", "noisy", "--spp", "4",
                     "--out", str(files / "out")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("dbench: --scenes ") and f"{name}: {said}" in err \
        and err.count("\n") == 1, err
    assert not (files / "out").exists()


def test_sweep_and_render_take_the_spellings_of_each_other_and_of_run():
    """``sweep --scene`` was refused as ambiguous (``--scenes`` or ``--scene-param``), though
    ``run`` and ``render`` spell it so; each spelling is the same list option."""
    from dbench.cli.parser import build_parser

    parse = build_parser().parse_args
    sw = parse(["sweep", "--scene", "cornell", "--scenes", "textured", "--method", "jbf"])
    assert sw.scenes == ["cornell", "textured"] and sw.methods == ["jbf"]
    rp = parse(["render", "--scenes", "cornell", "--scene", "textured"])
    assert rp.scene == ["cornell", "textured"]
