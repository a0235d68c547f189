"""A scene file's cache key covers exactly the files Mitsuba reads: assets found through
``<path>`` and through ``<include>`` fragments in other folders (issue 44, first case), a missing
one refused before rendering, and Mitsuba's resolver left as it was."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dbench import io
from dbench.cli import main
from dbench.errors import DbenchInputError

pytestmark = pytest.mark.mitsuba

SCENE = """<scene version="3.0.0">
  <default name="sky" value="1"/>
  <path value="../assets"/>
  <include filename="../fragments/room.xml"/>
  <sensor type="perspective">
    <float name="fov" value="40"/>
    <transform name="to_world"><lookat origin="0,0,3" target="0,0,0" up="0,1,0"/></transform>
    <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/>
    </film>
  </sensor>
  <emitter type="constant"><rgb name="radiance" value="$sky"/></emitter>
</scene>
"""
# a fragment in another folder: Mitsuba finds its textures and meshes through the scene's
# resolver (the scene's folder and its <path>s), not next to the fragment
FRAGMENT = """<scene version="3.0.0">
  <shape type="obj">
    <string name="filename" value="meshes/back.obj"/>
    <bsdf type="diffuse"><texture type="bitmap" name="reflectance">
      <string name="filename" value="textures/wood.png"/></texture></bsdf>
  </shape>
</scene>
"""


def _quad(path: Path, half: float = 1.0) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    h = half
    path.write_text(f"v {-h} {-h} 0\nv {h} {-h} 0\nv {h} {h} 0\nv {-h} {h} 0\n"
                    "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n")


def _texture(path: Path, rgb) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    io.write_png(path, np.ones((4, 4, 3)) * np.asarray(rgb, np.float32))


def _project(root: Path) -> Path:
    """scene/cbox.xml with assets/ (through <path>) and fragments/room.xml (an include), and
    decoys where a guess relative to the fragment would look."""
    (root / "scene").mkdir(parents=True)
    (root / "scene" / "cbox.xml").write_text(SCENE)
    (root / "fragments").mkdir()
    (root / "fragments" / "room.xml").write_text(FRAGMENT)
    _quad(root / "assets" / "meshes" / "back.obj")
    _texture(root / "assets" / "textures" / "wood.png", (0.8, 0.5, 0.2))
    _quad(root / "fragments" / "meshes" / "back.obj", 0.5)         # decoys: never read
    _texture(root / "fragments" / "textures" / "wood.png", (0.1, 0.1, 0.1))
    return root / "scene" / "cbox.xml"


def _fingerprint(path: Path) -> str:
    from dbench import datasets
    from dbench.datasets.scenes import catalogue as scenes
    return datasets.scene_fingerprint(scenes.get(str(path)), 8)


def test_key_covers_every_file_mitsuba_reads_and_nothing_else(renderer, tmp_path):
    from dbench.datasets.scene_files.assets import asset_hashes
    mi = renderer
    path = _project(tmp_path)
    root = tmp_path.resolve()
    sources = asset_hashes(path)
    assert set(sources) == {"(the scene file)", "../fragments/room.xml",
                            "../assets/meshes/back.obj", "../assets/textures/wood.png"}
    assert "missing" not in sources.values()
    # the files hashed are the files Mitsuba loads (not the decoys next to the fragment)
    shape = mi.load_file(str(path)).shapes()[0]
    assert np.abs(np.array(mi.traverse(shape)["vertex_positions"])).max() == pytest.approx(1.0)
    key = _fingerprint(path)
    for edit in (lambda: _texture(root / "assets" / "textures" / "wood.png", (0, 0, 1)),
                 lambda: _quad(root / "assets" / "meshes" / "back.obj", 0.9),
                 lambda: (root / "fragments" / "room.xml").write_text(FRAGMENT + "\n"),
                 lambda: path.write_text(SCENE.replace('value="1"', 'value="2"'))):
        edit()
        assert _fingerprint(path) != key
        key = _fingerprint(path)
    _texture(root / "fragments" / "textures" / "wood.png", (1, 1, 1))  # a decoy: same key
    _quad(root / "fragments" / "meshes" / "back.obj", 0.3)
    assert _fingerprint(path) == key


def test_the_same_tree_elsewhere_is_the_same_scene(renderer, tmp_path):
    """The fingerprint is a content hash: a scene tree copied to another folder keeps it (and
    its cache entries and sweep cells), the same file name with other content does not."""
    import shutil
    first = _project(tmp_path / "here")
    shutil.copytree(tmp_path / "here", tmp_path / "there" / "deeper")
    moved = tmp_path / "there" / "deeper" / "scene" / "cbox.xml"
    assert _fingerprint(moved) == _fingerprint(first)
    renamed = moved.with_name("other-name.xml")  # its name is not its identity either
    shutil.copy(moved, renamed)
    assert _fingerprint(renamed) == _fingerprint(first)
    _texture(tmp_path / "there" / "deeper" / "assets" / "textures" / "wood.png", (0, 1, 0))
    assert _fingerprint(moved) != _fingerprint(first)


def test_an_edited_texture_renders_again(renderer, tmp_path):
    """The issue's case: a texture replaced by solid blue is a cache miss, not old numbers."""
    from dbench import datasets
    from dbench.datasets.scenes import catalogue as scenes
    path = _project(tmp_path)
    cache = datasets.Cache(tmp_path / "cache")

    def color():
        f = datasets.load(scenes.get(str(path)), spp=1, res=8, needs={"color"}, cache=cache,
                          progress=False)
        return f.color.mean(axis=(0, 1)), f.meta["cache_hits"]

    before, _ = color()
    assert color()[1] == ["color"]  # unchanged: a hit
    _texture(tmp_path / "assets" / "textures" / "wood.png", (0, 0, 1))
    after, hits = color()
    assert hits == [] and after[2] > after[0] and before[0] > before[2]


def test_a_missing_asset_is_refused_before_rendering(renderer, tmp_path, capsys):
    from dbench.datasets.scenes import catalogue as scenes
    path = _project(tmp_path)
    (tmp_path / "assets" / "textures" / "wood.png").unlink()
    with pytest.raises(DbenchInputError) as err:
        scenes.get(str(path))
    text = str(err.value)
    assert "textures/wood.png" in text and "room.xml" in text
    assert str((tmp_path / "assets").resolve()) in text and str(path.parent) in text
    # each folder named once, also the scene's own when Mitsuba's resolver holds it already
    # (it starts with the working directory of the process)
    glob = renderer.file_resolver()
    glob.prepend(str(path.parent))
    try:
        with pytest.raises(DbenchInputError) as err:
            scenes.get(str(path))
    finally:
        del glob[0]
    searched = str(err.value).split("Mitsuba searches: ")[1].split("; ")
    assert str(path.parent) in searched and len(searched) == len(set(searched)), searched
    out = tmp_path / "run"
    assert main(["run", "--method", "noisy", "--scene", str(path), "--spp", "1", "--res", "8",
                 "--quiet", "--cache", str(tmp_path / "c"), "--out", str(out)]) == 2
    assert "textures/wood.png" in capsys.readouterr().err and not (tmp_path / "c").exists()
    _texture(tmp_path / "assets" / "textures" / "wood.png", (0.5, 0.5, 0.5))
    (tmp_path / "fragments" / "room.xml").unlink()
    with pytest.raises(DbenchInputError, match="room.xml"):
        scenes.get(str(path))
    (tmp_path / "fragments" / "room.xml").write_text(FRAGMENT)
    path.write_text(SCENE.replace("../assets", "../nowhere"))
    with pytest.raises(DbenchInputError, match="nowhere"):
        scenes.get(str(path))
    path.write_text(SCENE.replace('value="$sky"', 'value="$sun"'))
    with pytest.raises(DbenchInputError, match=r"\$sun.*--scene-param sun=VALUE"):
        scenes.get(str(path))
    # "$1" can be no --scene-param (names start with a letter or _): the hint says so
    path.write_text(SCENE.replace('value="$sky"', 'value="$1"'))
    with pytest.raises(DbenchInputError) as err:
        scenes.get(str(path))
    assert "--scene-param 1=" not in str(err.value) and "starts with a letter" in str(err.value)


def test_resolution_follows_mitsuba(renderer, tmp_path):
    """Rules checked against mi.load_file: a <path> further down still applies to filename
    strings; a fragment's own <path> and folder do not; a nested include is found next to the
    fragment that includes it; one scene's folder never supplies another's assets."""
    from dbench.datasets.scenes import catalogue as scenes
    from dbench.datasets.scene_files.assets import asset_hashes
    mi = renderer
    root = tmp_path.resolve()
    path = _project(root)
    late = root / "scene" / "late.xml"
    late.write_text(SCENE.replace('<path value="../assets"/>', "").replace(
        "</scene>", '<path value="../assets"/></scene>').replace("../fragments/room.xml",
                                                                    "../fragments/outer.xml"))
    (root / "fragments" / "outer.xml").write_text(
        '<scene version="3.0.0"><include filename="room.xml"/></scene>')
    mi.load_file(str(late))
    assert "../fragments/room.xml" in asset_hashes(late)
    assert "../assets/meshes/back.obj" in asset_hashes(late)
    own = root / "scene" / "own.xml"  # the fragment's <path> is its own
    own.write_text(SCENE.replace('<path value="../assets"/>', "").replace(
        "../fragments/room.xml", "../fragments/own.xml"))
    (root / "fragments" / "own.xml").write_text(
        FRAGMENT.replace("<shape", '<path value="../assets"/><shape'))
    with pytest.raises(RuntimeError):
        mi.load_file(str(own))
    with pytest.raises(DbenchInputError, match="meshes/back.obj"):
        asset_hashes(own)
    resolver = [str(p) for p in mi.file_resolver()]
    scenes.get(str(path))
    assert [str(p) for p in mi.file_resolver()] == resolver


def test_a_file_only_mitsubas_lenient_reader_takes_is_walked_as_mitsuba_reads_it(renderer,
                                                                                tmp_path):
    """pugixml, Mitsuba's XML reader, loads what a strict parser refuses: a Latin-1 comment,
    a bare "&" in a file name, an attribute given twice (the first counts), text after the
    root element. Such a file was refused as "not well-formed"; it loads, its key covers the
    files Mitsuba reads, and a file whose tags do not match is still refused."""
    from dbench.datasets.scene_files.assets import asset_hashes
    from dbench.datasets.scenes import catalogue as scenes
    mi = renderer
    path = _project(tmp_path)
    root = tmp_path.resolve()
    rock = root / "assets" / "textures" / "rock&moss.png"
    _texture(rock, (0.2, 0.6, 0.2))
    text = (SCENE.replace("<sensor", "<!-- caf\xe9 \xa9 -->\n  <sensor")
            # the second name is never read: fragments/absent.xml does not exist
            .replace('filename="../fragments/room.xml"',
                     'filename="../fragments/room.xml" filename="../fragments/absent.xml"')
            .replace("</scene>", '<shape type="rectangle"><bsdf type="diffuse"><texture '
                     'type="bitmap" name="reflectance"><string name="filename" '
                     'value="textures/rock&moss.png"/></texture></bsdf></shape>\n</scene>')
            + "<!-- written by hand --> the end\n")
    path.write_bytes(text.encode("latin-1"))
    mi.load_file(str(path))  # Mitsuba's own load takes it
    assert set(asset_hashes(path)) == {"(the scene file)", "../fragments/room.xml",
                                       "../assets/meshes/back.obj",
                                       "../assets/textures/wood.png",
                                       "../assets/textures/rock&moss.png"}
    key = _fingerprint(path)
    _texture(rock, (0.9, 0.1, 0.1))
    assert _fingerprint(path) != key
    path.write_bytes(text.replace("</scene>", "</shape>").encode("latin-1"))
    with pytest.raises(DbenchInputError, match="not well-formed XML"):
        scenes.get(str(path))
