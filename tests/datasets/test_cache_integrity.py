"""Cache integrity: a swapped, truncated or deleted file, a broken
meta.json or a folder copied under another key is a miss with one warning, and the entry is
rendered again and replaced; stale temporary folders are removed."""
import os
import shutil
import time

import numpy as np
import pytest

from dbench import datasets, io
from dbench.datasets.cache import Cache, make_key
from dbench.datasets.checksums import file_record


def _put(cache, what, value):
    img = np.full((4, 5, 3), value, np.float32)
    cache.put("noisy", {"what": what}, images={"color": img}, arrays={"m": np.arange(3.0)},
              compress=True)  # (arrays.npz: the files of arrays/ are damaged further down)
    return cache._dir("noisy", make_key({"what": what}))


@pytest.mark.parametrize("damage", ["swap", "truncate", "delete", "meta", "copy"])
def test_damaged_entries_are_misses_and_get_replaced(tmp_path, capsys, damage):
    cache = Cache(tmp_path)
    a = _put(cache, "a", 1.0)
    b = _put(cache, "b", 2.0)
    if damage == "swap":
        shutil.copy(b / "buffers.exr", a / "buffers.exr")
    elif damage == "truncate":
        data = (a / "arrays.npz").read_bytes()
        (a / "arrays.npz").write_bytes(data[: len(data) // 2])
    elif damage == "delete":
        (a / "buffers.exr").unlink()
    elif damage == "meta":
        (a / "meta.json").write_text("{broken")
    elif damage == "copy":  # another entry's folder under this key
        shutil.rmtree(a)
        shutil.copytree(b, a)
    assert cache.get("noisy", {"what": "a"}) is None
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "damaged" in err and make_key({"what": "a"}) in err
    _put(cache, "a", 1.0)  # the caller renders again: the damaged folder is replaced
    entry = cache.get("noisy", {"what": "a"})
    assert entry is not None and entry.images()["color"].mean() == 1.0
    assert capsys.readouterr().err == ""
    assert cache.get("noisy", {"what": "b"}).images()["color"].mean() == 2.0


def _put_files(cache, what, value):
    """An entry whose arrays are files of arrays/ (uncompressed), one of them packed."""
    video = np.zeros((4, 5, 6, 3))
    video[1, 2, 3] = value
    cache.put("transient-stats", {"what": what}, arrays={"m": np.full(3, value), "v": video},
              compress=False, sparse=("v",))
    return cache._dir("transient-stats", make_key({"what": what}))


@pytest.mark.parametrize("damage", ["swap", "flip", "header", "truncate", "delete", "extra"])
def test_damaged_array_files_are_misses_and_get_replaced(tmp_path, capsys, damage):
    # the files of arrays/ are checked in the same pass that reads them (cache.read_arrays)
    cache = Cache(tmp_path)
    a = _put_files(cache, "a", 1.0)
    b = _put_files(cache, "b", 2.0)
    f = a / "arrays" / "rows~v.npy"
    if damage == "swap":  # the same size, another entry's values
        shutil.copy(b / "arrays" / "rows~v.npy", f)
    elif damage == "flip":
        data = bytearray(f.read_bytes())
        data[-1] ^= 1
        f.write_bytes(bytes(data))
    elif damage == "header":
        data = bytearray(f.read_bytes())
        data[:6] = b"XXXXXX"
        f.write_bytes(bytes(data))
    elif damage == "truncate":
        f.write_bytes(f.read_bytes()[:-8])
    elif damage == "delete":
        f.unlink()
    elif damage == "extra":  # a file no checksum covers would be read unchecked
        shutil.copy(a / "arrays" / "m.npy", a / "arrays" / "w.npy")
    assert cache.get("transient-stats", {"what": "a"}) is None
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "damaged" in err and "rows~v.npy" in err or \
        damage == "extra" and "w.npy has no checksum" in err
    _put_files(cache, "a", 1.0)
    got = cache.get("transient-stats", {"what": "a"}).arrays()
    assert got["v"][1, 2, 3, 0] == 1.0 and got["v"].sum() == 3.0 and got["m"].tolist() == [1.0] * 3
    assert capsys.readouterr().err == ""


def _as_sha256_entry(path, fmt):
    """Rewrite the entry at ``path`` as an earlier format wrote it: sha256 records."""
    meta = io.read_json(path / "meta.json")
    meta["cache_format"] = fmt
    meta["files"] = {n: file_record(path / n, "sha256") for n in meta["files"]}
    io.write_json(path / "meta.json", meta)


@pytest.mark.parametrize("fmt", [1, 4])
def test_entries_of_earlier_formats_are_checked_with_their_sha256(tmp_path, capsys, fmt):
    # entries before format 5 record sha256 (datasets/checksums.py): still hits, still checked
    cache = Cache(tmp_path)
    a = _put(cache, "a", 1.0) if fmt == 1 else _put_files(cache, "a", 1.0)
    kind = "noisy" if fmt == 1 else "transient-stats"
    _as_sha256_entry(a, fmt)
    entry = cache.get(kind, {"what": "a"})
    assert entry is not None and capsys.readouterr().err == ""
    if fmt == 1:
        assert entry.images()["color"].mean() == 1.0
        target = a / "buffers.exr"
    else:
        assert entry.arrays()["v"][1, 2, 3, 0] == 1.0
        target = a / "arrays" / "rows~v.npy"
    data = bytearray(target.read_bytes())
    data[-1] ^= 1
    target.write_bytes(bytes(data))
    assert cache.get(kind, {"what": "a"}) is None
    assert "checksum differs" in capsys.readouterr().err
    # an xxh3 record under an earlier format's number is not taken for a sha256 one
    b = _put(cache, "b", 2.0)
    meta = io.read_json(b / "meta.json")
    meta["cache_format"] = 4
    io.write_json(b / "meta.json", meta)
    assert cache.get("noisy", {"what": "b"}) is None


def test_entries_without_checksums_are_misses_even_when_they_read(tmp_path):
    cache = Cache(tmp_path)
    a = _put(cache, "a", 1.0)
    meta = io.read_json(a / "meta.json")
    del meta["files"]
    io.write_json(a / "meta.json", meta)
    assert cache.get("noisy", {"what": "a"}) is None  # never adopted on trust
    assert "files" not in io.read_json(a / "meta.json")


def test_stale_temporary_folders_are_removed_but_fresh_ones_kept(tmp_path):
    cache = Cache(tmp_path)
    old = tmp_path / "noisy" / ".tmp-old"
    new = tmp_path / "noisy" / ".tmp-new"
    for d in (old, new):
        d.mkdir(parents=True)
    past = time.time() - 2 * 86400
    os.utime(old, (past, past))
    _put(cache, "a", 1.0)
    assert not old.exists() and new.exists()


@pytest.mark.mitsuba
def test_a_damaged_render_is_rendered_again_with_the_same_numbers(renderer, tmp_path):
    cache = Cache(tmp_path / "cache")
    kw = dict(spp=4, res=12, needs={"reference", "albedo"}, ref_spp=16, cache=cache,
              progress=False)
    clean = datasets.load("cornell", **kw)
    other = datasets.load("textured", **kw)
    entry = next(p.parent for p in (tmp_path / "cache" / "noisy").glob("*/meta.json")
                 if io.read_json(p)["description"]["scene"] == "cornell")
    donor = next(p.parent for p in (tmp_path / "cache" / "noisy").glob("*/meta.json")
                 if io.read_json(p)["description"]["scene"] == "textured")
    shutil.copy(donor / "buffers.exr", entry / "buffers.exr")
    again = datasets.load("cornell", **kw)
    assert "color" in again.meta["rendered"]
    np.testing.assert_array_equal(again.color, clean.color)
    assert not np.array_equal(again.color, other.color)
    third = datasets.load("cornell", **kw)
    assert "color" in third.meta["cache_hits"]
