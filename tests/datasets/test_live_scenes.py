"""Loaded Mitsuba scenes are dropped when a load moves to another scene (docs/mitsuba.md §3:
each live scene's objects make every later render trace its virtual calls over them too)."""
import pytest

from dbench import datasets
from dbench.datasets import Cache, mitsuba_env
from dbench.datasets import render as R
from dbench.datasets.scenes import catalogue
from dbench.datasets.transient import load as transient_load
from dbench.datasets.transient import render as transient_render

pytestmark = pytest.mark.mitsuba


def _load(name, tmp_path, **kw):
    return datasets.load(name, spp=4, res=8, ref_spp=16, cache=Cache(tmp_path), progress=False,
                         needs={"color", "stats", "reference"}, **kw)


def _kept(cached, *args) -> bool:
    """Whether ``cached(*args)`` is answered from its cache (calling it, which loads it if not)."""
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
