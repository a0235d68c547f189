"""Cache entries whose meta.json records no checksums (written before checksums existed) are
never adopted on trust: they are misses, rendered again and replaced (dbench/datasets/cache.py).
A file that loads is not thereby the right file: another scene's buffers.exr copied into such
an entry loads just as well."""
import shutil

import numpy as np
import pytest

from dbench import datasets, io
from dbench.datasets.cache import Cache, make_key


def _put(cache, what, value):
    img = np.full((4, 5, 3), value, np.float32)
    cache.put("noisy", {"what": what}, images={"color": img}, arrays={"m": np.arange(3.0)})
    return cache._dir("noisy", make_key({"what": what}))


def _strip_checksums(entry):
    meta = io.read_json(entry / "meta.json")
    del meta["files"]
    io.write_json(entry / "meta.json", meta)


def test_an_unchecked_entry_holding_another_entrys_buffers_is_a_miss_and_replaced(
        tmp_path, capsys):
    cache = Cache(tmp_path)
    a = _put(cache, "a", 1.0)
    b = _put(cache, "b", 2.0)
    shutil.copy(b / "buffers.exr", a / "buffers.exr")
    _strip_checksums(a)
    assert cache.get("noisy", {"what": "a"}) is None
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cannot be trusted" in err
    assert make_key({"what": "a"}) in err and "Traceback" not in err
    # the miss does not seal the wrong pixels with a checksum
    assert "files" not in io.read_json(a / "meta.json")
    _put(cache, "a", 1.0)  # the caller renders again: the entry is replaced
    assert "files" in io.read_json(a / "meta.json")
    entry = cache.get("noisy", {"what": "a"})
    assert entry is not None and entry.images()["color"].mean() == 1.0
    assert capsys.readouterr().err == ""


def test_an_unchecked_entry_is_a_miss_even_when_its_files_are_its_own(tmp_path):
    cache = Cache(tmp_path)
    a = _put(cache, "a", 1.0)
    _strip_checksums(a)
    assert cache.get("noisy", {"what": "a"}) is None
    assert cache.get("noisy", {"what": "a"}) is None  # still not adopted on a second look


@pytest.mark.parametrize("files", [{}, None, "x", {"buffers.exr": "x"}])
def test_checksums_that_leave_a_file_out_or_are_malformed_are_a_miss(tmp_path, capsys, files):
    cache = Cache(tmp_path)
    a = _put(cache, "a", 1.0)
    meta = io.read_json(a / "meta.json")
    meta["files"] = files
    io.write_json(a / "meta.json", meta)
    assert cache.get("noisy", {"what": "a"}) is None
    assert capsys.readouterr().err.count("\n") == 1


@pytest.mark.mitsuba
def test_an_unchecked_render_with_another_scenes_buffers_is_rendered_again(renderer, tmp_path):
    kw = dict(spp=4, res=12, needs={"reference", "albedo"}, ref_spp=16, progress=False)
    cache = Cache(tmp_path / "cache")
    datasets.load("cornell", cache=cache, **kw)
    other = datasets.load("textured", cache=cache, **kw)
    by_scene = {}
    for p in (tmp_path / "cache").glob("*/*/meta.json"):
        scene = io.read_json(p)["description"].get("scene")
        by_scene.setdefault(scene, []).append(p.parent)
    noisy = {s: next(e for e in es if e.parent.name == "noisy") for s, es in by_scene.items()}
    shutil.copy(noisy["textured"] / "buffers.exr", noisy["cornell"] / "buffers.exr")
    for entry in by_scene["cornell"]:  # every cornell entry as an older dbench wrote it
        _strip_checksums(entry)
    again = datasets.load("cornell", cache=cache, **kw)
    fresh = datasets.load("cornell", cache=Cache(tmp_path / "fresh"), **kw)
    assert "color" in again.meta["rendered"]
    np.testing.assert_array_equal(again.color, fresh.color)
    np.testing.assert_array_equal(again.reference, fresh.reference)
    assert not np.array_equal(again.color, other.color)
    assert "files" in io.read_json(noisy["cornell"] / "meta.json")
    third = datasets.load("cornell", cache=cache, **kw)
    assert "color" in third.meta["cache_hits"]
    np.testing.assert_array_equal(third.color, fresh.color)
