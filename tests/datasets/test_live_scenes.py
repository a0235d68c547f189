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
