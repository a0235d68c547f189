"""What a Python scene's renders and cells are keyed by: the files its dictionary names, the
previous frame behind a re-shaded gradient, the tone map's exposure (README.md, "Your scene,
your renders, any size"; dbench/datasets/file_refs.py)."""
from __future__ import annotations

import os

import numpy as np
import pytest

from dbench.datasets.cache import canonical
from dbench.errors import DbenchInputError

TEXTURED = '''
from pathlib import Path
HERE = Path(__file__).parent

def build(mi, width, height):
    T = mi.ScalarTransform4f
    return {"type": "scene",
            "sensor": {"type": "perspective", "fov": 45,
                       "to_world": T().look_at(origin=[0, 2, 3], target=[0, 0, 0], up=[0, 1, 0])},
            "floor": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale(2),
                      "bsdf": {"type": "diffuse", "reflectance": {
                          "type": "bitmap", "filename": str(HERE / "tex.exr")}}},
            "sky": {"type": "constant", "radiance": {"type": "rgb", "value": [1, 1, 1]}},
            "integrator": {"type": "path", "max_depth": 3}}
'''


def _write_texture(path, value: float) -> None:
    from dbench.datasets.folders import exr_layers
    exr_layers.write_channels(path, {c: np.full((8, 8), value, np.float32) for c in "RGB"})


def _scene(path, text):
    from dbench.datasets.scenes import catalogue as scenes
    path.write_text(text)
    return scenes.get(str(path))


def test_a_filename_is_keyed_by_the_bytes_it_names(renderer, tmp_path, monkeypatch):
    (tmp_path / "a.exr").write_bytes(b"one")
    (tmp_path / "b.exr").write_bytes(b"two")
    monkeypatch.chdir(tmp_path)
    one = canonical({"t": {"type": "bitmap", "filename": "a.exr"}})
    assert one["t"]["filename"]["file"] == "a.exr"  # the name as written, not where it lies
    assert one != canonical({"t": {"type": "bitmap", "filename": "b.exr"}})
    os.rename("b.exr", "a.exr")
    assert canonical({"t": {"type": "bitmap", "filename": "a.exr"}}) != one
    assert canonical({"filename": "nowhere.exr"})["filename"] == {"file": "nowhere.exr",
                                                                "sha256": None}


def test_an_edited_texture_of_a_python_scene_renders_afresh(renderer, tmp_path):
    from dbench import datasets
    _write_texture(tmp_path / "tex.exr", 0.8)
    sc = _scene(tmp_path / "floor.py", TEXTURED)
    cache = datasets.Cache(tmp_path / "c")
    kw = dict(spp=2, res=16, needs={"color"}, progress=False, cache=cache)
    bright = datasets.load(sc, **kw)
    before = datasets.scene_fingerprint(sc, 16)
    assert datasets.load(sc, **kw).meta["cache_hits"]
    _write_texture(tmp_path / "tex.exr", 0.1)  # the .py file itself is unchanged
    from dbench.datasets.scenes import catalogue as scenes
    again = scenes.get(str(tmp_path / "floor.py"))
    assert again is not sc and datasets.scene_fingerprint(again, 16) != before
    dark = datasets.load(again, **kw)
    assert not dark.meta["cache_hits"]
    assert dark.color.mean() < 0.5 * bright.color.mean()
    # the object resolved before the edit is refused, never keyed by the new bytes while its
    # in-process scene still holds the old ones
    with pytest.raises(DbenchInputError, match="floor.py.*changed after the scene was resolved"):
        datasets.load(sc, **kw)


def test_a_texture_loaded_in_build_is_keyed_by_its_pixels(renderer, tmp_path):
    """A build that loads its texture as an object (``mi.load_dict``) names no file in its
    dictionary: the object is keyed by its pixels (mi.traverse), not its repr, which gives
    only the size and mean. The texture mirrored (same mean) renders afresh."""
    from dbench import datasets
    from dbench.datasets.folders import exr_layers

    half = np.full((8, 8), 0.05, np.float32)
    half[:, :4] = 0.9
    exr_layers.write_channels(tmp_path / "tex.exr", {c: half for c in "RGB"})
    text = TEXTURED.replace('{\n                          "type": "bitmap", "filename": '
                            'str(HERE / "tex.exr")}', 'mi.load_dict({"type": "bitmap", '
                            '"filename": str(HERE / "tex.exr")})')
    assert "mi.load_dict" in text
    sc = _scene(tmp_path / "loaded.py", text)
    cache = datasets.Cache(tmp_path / "c")
    kw = dict(spp=2, res=16, needs={"color"}, progress=False, cache=cache)
    first = datasets.load(sc, **kw)
    assert datasets.load(sc, **kw).meta["cache_hits"]
    exr_layers.write_channels(tmp_path / "tex.exr", {c: half[:, ::-1].copy() for c in "RGB"})
    from dbench.datasets.scenes import catalogue as scenes
    again = scenes.get(str(tmp_path / "loaded.py"))
    assert again is not sc  # a new scene object: the in-process caches hold the old pixels
    mirrored = datasets.load(again, **kw)
    assert not mirrored.meta["cache_hits"]
    assert not np.array_equal(mirrored.color, first.color)
    # the camera looks straight down the scene's mirror plane: the image is mirrored too
    flipped = np.abs(mirrored.color[:, ::-1] - first.color).mean()
    assert flipped < 0.5 * np.abs(mirrored.color - first.color).mean()
    with pytest.raises(DbenchInputError, match="loaded.py.*changed after the scene was resolved"):
        datasets.load(sc, **kw)  # the object resolved before the edit is refused


def test_a_mesh_loaded_in_build_is_keyed_by_its_uvs_and_its_bsdfs_textures(renderer, tmp_path):
    """A mesh a build loads from a ply was keyed by its positions, faces and repr: new UVs, or
    new pixels of its BSDF's texture (same mean), kept the old key and the old renders. Both
    now change the key and count among the content its scene was resolved with."""
    from dbench.datasets.cache import make_key, referenced
    from dbench.datasets.mitsuba_env import mitsuba

    mi = mitsuba()

    def ply(uv_scale: float) -> str:
        mesh = mi.Mesh("quad", 4, 2, has_vertex_texcoords=True)
        p = mi.traverse(mesh)
        p["vertex_positions"] = mi.Float([0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0])
        p["faces"] = mi.UInt32([0, 1, 2, 0, 2, 3])
        p["vertex_texcoords"] = mi.Float([0, 0, 1, 0, 1, 1, 0, 1]) * uv_scale
        p.update()
        mesh.write_ply(str(tmp_path / "quad.ply"))
        return str(tmp_path / "quad.ply")

    def loaded(uv_scale: float, flip: bool):
        texture = np.zeros((4, 4, 3), np.float32)
        texture[:, :2] = 1.0
        bitmap = mi.Bitmap(texture[:, ::-1].copy() if flip else texture)
        return {"quad": mi.load_dict({"type": "ply", "filename": ply(uv_scale), "bsdf": {
            "type": "diffuse", "reflectance": {"type": "bitmap", "bitmap": bitmap}}})}

    first = loaded(1.0, False)
    keys = {make_key(first), make_key(loaded(0.25, False)), make_key(loaded(1.0, True))}
    assert len(keys) == 3 and make_key(loaded(1.0, False)) == make_key(first)
    assert any(name.startswith("<loaded") for name, _ in referenced(first))


ORBIT = '''
kind = "sequence"
frames = 2

def build(mi, width, height):
    T = mi.ScalarTransform4f
    return {"type": "scene",
            "sensor": {"type": "perspective", "fov": 45,
                       "to_world": T().look_at(origin=[0, 1, 4], target=[0, 0.3, 0], up=[0, 1, 0])},
            "floor": {"type": "rectangle", "to_world": T().rotate([1, 0, 0], -90).scale(3),
                      "bsdf": {"type": "diffuse"}},
            "ball": {"type": "sphere", "center": [0, 0.5, 0], "radius": 0.5},
            "sky": {"type": "constant", "radiance": {"type": "rgb", "value": [1, 1, 1]}},
            "integrator": {"type": "path", "max_depth": 3}}

def camera(i):
    # the path of the first frame is read from a file beside the scene (as a camera track
    # would be): the .py file stays the same when it changes
    from pathlib import Path
    first = float((Path(__file__).parent / "first.txt").read_text())
    return ((first if i == 0 else 0.0), 1.0, 4.0), (0, 0.3, 0)
'''


def test_a_reshaded_gradient_is_keyed_by_the_frame_it_reshades(renderer, tmp_path):
    from dbench import datasets
    cache = datasets.Cache(tmp_path / "c")
    kw = dict(spp=1, res=12, needs={"color", "gradient"}, progress=False, cache=cache)
    (tmp_path / "first.txt").write_text("0.0")
    sc = _scene(tmp_path / "orbit.py", ORBIT)
    datasets.load(sc, **kw)
    assert "gradient1" in datasets.load(sc, **kw).meta["cache_hits"]
    # only frame 0's camera moves: frame 1's dictionary is the same, its gradient is not
    (tmp_path / "first.txt").write_text("2.0")
    moved = datasets.load(sc, **kw)
    assert "frame1" in moved.meta["cache_hits"] and "gradient1" in moved.meta["rendered"]


def test_the_exposure_is_part_of_a_scene_identity(renderer, tmp_path):
    """A plugin's scene or a folder's dataset.json can change ``ev`` alone (a Python file's
    bytes change with it anyway): the same content at another exposure is another cell."""
    from dataclasses import replace

    from dbench import datasets
    from dbench.datasets.scenes import catalogue as scenes
    cornell = scenes.get("cornell")
    assert cornell.ev == 0.0
    plain = datasets.scene_fingerprint(cornell, 16)
    assert datasets.scene_fingerprint(replace(cornell, ev=1.5), 16) != plain
    # at 0 EV the description is what it always was: cells made before keep their identity
    assert datasets.scene_fingerprint(replace(cornell, ev=0.0), 16) == plain


XML = """<scene version="3.0.0">
  <default name="light" value="8"/>
  <default name="glow" value="$light"/>
  <sensor type="perspective"><float name="fov" value="50"/>
    <transform name="to_world"><lookat origin="0,1,4" target="0,0.3,0" up="0,1,0"/></transform>
    <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/>
    </film></sensor>
  <shape type="sphere"><float name="radius" value="0.5"/>
    <emitter type="area"><rgb name="radiance" value="$glow"/></emitter></shape>
  <shape type="rectangle"><transform name="to_world"><translate y="2"/></transform>
    <emitter type="area"><rgb name="radiance" value="$light"/></emitter></shape>
</scene>
"""


def test_a_scene_parameter_equal_to_the_files_default_is_the_same_scene(renderer, tmp_path):
    """``--scene-param light=8`` where the file says ``<default name="light" value="8"/>``
    renders what no parameter renders: one scene object, one fingerprint, one cache entry."""
    from dbench import datasets
    from dbench.datasets.scene_files.load import resolve

    (tmp_path / "s.xml").write_text(XML)
    plain = resolve(tmp_path / "s.xml")
    key = datasets.scene_fingerprint(plain, 16)
    for same in ({"light": "8"}, {"light": "8", "glow": "8"}):
        scene = resolve(tmp_path / "s.xml", same)
        assert scene is plain and datasets.scene_fingerprint(scene, 16) == key, same
    # a default that follows another parameter is compared with what it becomes
    other = resolve(tmp_path / "s.xml", {"light": "9", "glow": "9"})
    assert other is resolve(tmp_path / "s.xml", {"light": "9"})
    assert datasets.scene_fingerprint(other, 16) != key
    assert datasets.scene_fingerprint(resolve(tmp_path / "s.xml", {"glow": "9"}), 16) not in (
        key, datasets.scene_fingerprint(other, 16))


@pytest.fixture(autouse=True)
def _own_dir(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)


RANDOM = '''
import random

def build(mi, width, height):
    T = mi.ScalarTransform4f
    return {"type": "scene",
            "sensor": {"type": "perspective", "fov": 45,
                       "to_world": T().look_at(origin=[0, 2, 3], target=[0, 0, 0], up=[0, 1, 0])},
            "ball": {"type": "sphere", "center": [random.uniform(-1, 1), 0, 0],
                     "bsdf": {"type": "diffuse"}},
            "sky": {"type": "constant"}}
'''


def test_a_build_that_returns_another_scene_at_each_call_is_refused(renderer, tmp_path,
                                                                    capsys):
    """build() is called for each render: with an unseeded random position the noisy image,
    the features and the reference showed three different scenes, each cached under its own
    key, and were scored against one another without a word."""
    from dbench.cli import main
    from dbench.datasets.scenes.build import check_plugin_scene
    from dbench.datasets.scenes.record import Scene
    path = tmp_path / "scatter.py"
    with pytest.raises(DbenchInputError, match=r"scatter\.py: build\(mi, 8, 8\) returned another "
                                               r"dictionary when called again \(at "
                                               r"'ball\.center\[0\]'\).*seed its random numbers"):
        _scene(path, RANDOM)
    rc = main(["run", "--method", "noisy", "--scene", str(path), "--res", "8", "--spp", "1",
               "--ref-spp", "8", "--out", str(tmp_path / "out"),
               "--cache", str(tmp_path / "cache")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "returned another dictionary" in err[0], err
    assert not (tmp_path / "out").exists() and not (tmp_path / "cache").exists()
    # seeded, the same file is one scene
    _scene(tmp_path / "seeded.py", RANDOM.replace("import random\n",
                                                  "import random\nrandom.seed(1)\n"
                                                  "X = random.uniform(-1, 1)\n")
           .replace("random.uniform(-1, 1), 0, 0", "X, 0, 0"))
    # a plugin's Scene alike
    namespace: dict = {}
    exec(RANDOM, namespace)
    with pytest.raises(DbenchInputError, match=r"scene scatter-plugin .*build returned another "
                                               r"dictionary"):
        check_plugin_scene(Scene(name="scatter-plugin", kind="steady", description="",
                                 build=lambda mi, res: namespace["build"](mi, res, res)))
