"""Loaded Mitsuba scenes are dropped when a load moves to another scene (docs/mitsuba.md §3:
each live scene's objects make every later render trace its virtual calls over them too)."""
import pytest

from cli_args import lamp_scene

from dbench import datasets
from dbench.datasets import Cache, mitsuba_env
from dbench.datasets import render as R
from dbench.datasets.scene_files import load as file_load
from dbench.datasets.scenes import catalogue
from dbench.datasets.transient import load as transient_load
from dbench.datasets.transient import render as transient_render

pytestmark = pytest.mark.mitsuba


def _load(name, tmp_path, **kw):
    return datasets.load(name, spp=4, res=8, ref_spp=16, cache=Cache(tmp_path), progress=False,
                         needs={"color", "stats", "reference"}, **kw)


def _kept(cached, *args) -> bool:
    """Whether ``cached(*args)`` is answered from its cache (calling it, which loads it if not;
    a cleared cache counts from 0 again)."""
    hits = cached.cache_info().hits
    cached(*args)
    return cached.cache_info().hits == hits + 1


def test_a_load_of_another_scene_drops_the_last_ones_loaded_objects(renderer, tmp_path):
    cornell, res = catalogue.get("cornell"), R.parse_res(8)
    _load("cornell", tmp_path)
    assert _kept(R.loaded_scene, cornell, res)  # a second load of the same scene reuses them
    _load("cornell", tmp_path / "again", seed=1)
    assert _kept(R.loaded_scene, cornell, res)
    _load("caustic", tmp_path)
    assert not _kept(R.loaded_scene, cornell, res)


def test_a_video_s_scene_and_collector_go_when_an_image_is_loaded(renderer, tmp_path):
    _load("cornell-transient", tmp_path, bins=8)
    assert transient_render.loaded_transient.cache_info().currsize
    assert transient_load._collector.cache_info().currsize
    _load("cornell", tmp_path)
    assert transient_render.loaded_transient.cache_info().currsize == 0
    assert transient_load._collector.cache_info().currsize == 0


def test_each_loader_keeps_at_most_live_scenes(renderer):
    res = R.parse_res(8)
    for name in ("cornell", "caustic", "textured", "mirrors"):
        R.loaded_scene(catalogue.get(name), res)
    assert R.loaded_scene.cache_info().currsize == mitsuba_env.LIVE_SCENES


def test_a_scene_file_is_loaded_once_though_another_scene_came_before(renderer, tmp_path,
                                                                     monkeypatch):
    """Its objects are loaded where the file is read (they are checked by rendering) and kept
    for its renders: loading the file again would cost as much and repeat its warnings."""
    loads = []
    real = file_load._load_xml
    monkeypatch.setattr(file_load, "_load_xml", lambda *a: loads.append(a) or real(*a))
    _load("cornell", tmp_path)
    path = tmp_path / "lamp.xml"
    path.write_text(lamp_scene("5"))
    _load(str(path), tmp_path)
    _load(str(path), tmp_path / "again", seed=1)
    assert len(loads) == 1


def test_the_record_of_loads_keeps_no_loaded_scene_alive(renderer):
    """A collector's argument is a loaded scene: the record by which a repeated load's warnings
    are dropped (mitsuba_env.scene_cache) must not keep it, or the scene would outlive focus."""
    import sys

    scene, res = catalogue.get("cornell-transient"), R.parse_res(8)
    mitsuba_env.focus(("a test's scene",))
    sc = transient_render.loaded_transient(scene, res, scene.window(8), 1)
    transient_load._collector(sc, scene.integrator, "identity", 0.5, scene.max_depth,
                              scene.rr_depth, scene.camera_unwarp, 1)
    mitsuba_env.focus(("another scene",))
    assert sys.getrefcount(sc) == 2  # ``sc`` and the call's argument


@pytest.mark.parametrize("first", [True, False])
def test_a_sweep_loads_a_scene_file_beside_cornell_twice_at_most(renderer, tmp_path,
                                                                 monkeypatch, first):
    """Checked with the scenes, then its reference and its group: the references are rendered
    so that the file's objects serve the next of them in either order of --scenes (the third
    load came when the references went in the order of the names)."""
    from dbench.cli import main

    loads = []
    real = file_load._load_xml
    monkeypatch.setattr(file_load, "_load_xml", lambda *a: loads.append(a) or real(*a))
    monkeypatch.chdir(tmp_path)
    (tmp_path / "lamp.xml").write_text(lamp_scene("5"))
    scenes = "lamp.xml,cornell" if first else "cornell,lamp.xml"
    assert main(["sweep", "--scenes", scenes, "--methods", "noisy", "--spp", "2", "--res", "8",
                 "--ref-spp", "16", "--repeats", "1", "--quiet", "--cache",
                 str(tmp_path / "cache"), "--out", str(tmp_path / "S")]) == 0
    assert len(loads) == 2
