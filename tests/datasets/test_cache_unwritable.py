"""A render cache that cannot be written (full disk, read-only or unwritable folder) costs time,
not the run: Cache.put leaves no partial entry, warns once per process naming the folder and the
system's reason, and hands back the buffers from memory (dbench/datasets/cache.py; README.md,
"How renders work")."""
import errno
import os
from pathlib import Path

import numpy as np
import pytest

from dbench import cli, datasets, io
from dbench.datasets import cache as cache_mod
from dbench.datasets.cache import Cache
from dbench.datasets.checksums import DigestingWriter

ENOSPC = os.strerror(errno.ENOSPC)


@pytest.fixture(autouse=True)
def _fresh_process_state(monkeypatch):
    """Each test is a process that has not yet found a cache folder unwritable."""
    monkeypatch.setattr(cache_mod, "_UNWRITABLE", {}, raising=False)


def _warning(root) -> str:
    return (f"dbench: cache at {root} is not writable ({ENOSPC}); carrying on without storing "
            f"renders")


def _disk_full_under(monkeypatch, root: Path) -> None:
    """Writes under ``root`` fail as on a full disk: the arrays' stream (a raw OSError, made an
    OutputError by dbench.io) and the EXR write (a raw OSError), each after writing a part."""
    write, write_exr = DigestingWriter.write, io.write_exr

    def full_write(self, data):
        write(self, data[:10])
        raise OSError(errno.ENOSPC, ENOSPC)

    def full_exr(path, buffers, **kw):
        if Path(root) not in Path(path).parents:
            return write_exr(path, buffers, **kw)
        Path(path).write_bytes(b"partial")
        raise OSError(errno.ENOSPC, ENOSPC)

    monkeypatch.setattr(DigestingWriter, "write", full_write)
    monkeypatch.setattr(io, "write_exr", full_exr)


def _leftovers(root: Path) -> list[Path]:
    return [p for p in root.rglob("*")] if root.exists() else []


def test_a_full_disk_leaves_no_entry_warns_once_and_keeps_the_buffers(tmp_path, monkeypatch,
                                                                       capsys):
    root = tmp_path / "cache"
    _disk_full_under(monkeypatch, root)
    cache = Cache(root)
    img = np.random.default_rng(0).random((4, 5, 3)).astype(np.float32)
    stats = {"mean": np.arange(6.0).reshape(2, 3)}
    entry = cache.put("stats", {"what": "a"}, arrays=stats, meta={"stats_s": 1.0})
    np.testing.assert_array_equal(entry.arrays()["mean"], stats["mean"])
    assert entry.meta["stats_s"] == 1.0 and "files" not in entry.meta
    assert [p for p in _leftovers(root) if p.is_file()] == []  # no partial file or entry
    assert cache.get("stats", {"what": "a"}) is None
    entry = cache.put("noisy", {"what": "b"}, images={"color": img})
    np.testing.assert_array_equal(entry.images()["color"], img)
    # another Cache of the same folder in the same process neither writes nor warns again
    found = cache_mod._UNWRITABLE
    monkeypatch.undo()  # writes work again
    monkeypatch.setattr(cache_mod, "_UNWRITABLE", found)
    again = Cache(root).put("noisy", {"what": "c"}, images={"color": img})
    np.testing.assert_array_equal(again.images()["color"], img)
    assert [p for p in _leftovers(root) if p.is_file()] == []
    err = capsys.readouterr().err.splitlines()
    assert err == [_warning(root)]


def test_an_image_write_failing_with_a_raw_oserror_is_the_same(tmp_path, monkeypatch, capsys):
    root = tmp_path / "cache"
    _disk_full_under(monkeypatch, root)
    img = np.ones((2, 2, 3), np.float32)
    entry = Cache(root).put("features", {"what": "f"}, images={"albedo": img},
                            arrays={"m": np.zeros(3)})
    assert entry.images()["albedo"] is img and set(entry.arrays()) == {"m"}
    assert [p for p in _leftovers(root) if p.is_file()] == []
    assert capsys.readouterr().err.splitlines() == [_warning(root)]


def test_a_cache_root_that_cannot_be_created_is_the_same(tmp_path, monkeypatch, capsys):
    root = tmp_path / "read-only" / "cache"
    mkdir = Path.mkdir

    def read_only(self, *args, **kwargs):
        if self == root or root in self.parents:
            raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(self))
        return mkdir(self, *args, **kwargs)

    monkeypatch.setattr(Path, "mkdir", read_only)
    img = np.ones((2, 2, 3), np.float32)
    entry = Cache(root).put("reference", {"what": "r"}, images={"reference": img})
    assert entry.images()["reference"] is img and not root.exists()
    assert capsys.readouterr().err.splitlines() == [
        f"dbench: cache at {root} is not writable ({os.strerror(errno.EROFS)}); carrying on "
        f"without storing renders"]


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() == 0,
                    reason="root writes through folder permissions")
def test_a_read_only_cache_folder_is_the_same(tmp_path, capsys):
    root = tmp_path / "cache"
    root.mkdir()
    root.chmod(0o500)
    try:
        img = np.ones((2, 2, 3), np.float32)
        entry = Cache(root).put("noisy", {"what": "n"}, images={"color": img})
        assert entry.images()["color"] is img and list(root.iterdir()) == []
    finally:
        root.chmod(0o700)
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith(f"dbench: cache at {root} is not writable (")


@pytest.mark.mitsuba
def test_a_run_on_a_full_cache_disk_carries_on_with_the_same_numbers(renderer, tmp_path,
                                                                     monkeypatch, capsys):
    root = tmp_path / "cache"
    needs = {"color", "stats", "albedo", "normal", "reference"}
    kw = dict(spp=2, res=8, ref_spp=16, needs=needs, progress=False)
    uncached = datasets.load("cornell", cache=Cache(root, enabled=False), **kw)
    _disk_full_under(monkeypatch, root)
    frame = datasets.load("cornell", cache=Cache(root), **kw)
    for name in ("color", "albedo", "normal", "reference", "reference_var"):
        np.testing.assert_array_equal(getattr(frame, name), getattr(uncached, name))
    np.testing.assert_array_equal(frame.stats.var_mean, uncached.stats.var_mean)
    assert capsys.readouterr().err.splitlines() == [_warning(root)]
    # the command, in a process that has not warned yet: exit 0, its outputs, one warning
    monkeypatch.setattr(cache_mod, "_UNWRITABLE", {}, raising=False)
    monkeypatch.setenv("DBENCH_CACHE", str(root))
    out = tmp_path / "run"
    rc = cli.main(["run", "--method", "noisy", "--scene", "cornell", "--spp", "2", "--res", "8",
                   "--ref-spp", "16", "--repeats", "1", "--out", str(out), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 0, err
    assert (out / "report.md").is_file() and err.splitlines().count(_warning(root)) == 1
    assert list(root.glob("*/*")) == []  # no entry, whole or partial
