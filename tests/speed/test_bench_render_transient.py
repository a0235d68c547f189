"""``dbench bench render`` on transient scenes (dbench/speed/transient_render.py) and the
uncompressed transient cache entries it measures (README.md, "How renders work")."""
from __future__ import annotations

import zipfile

import numpy as np


def test_bench_render_transient_shape(tr, tmp_path, monkeypatch):
    import tempfile

    from dbench.speed.transient_render import RATIOS, bench_render_transient, format_result

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))  # its fresh caches go here
    r = bench_render_transient("cornell-transient", res=8, spp=4, bins=10, repeats=1)
    assert r["benchmark"] == "render-transient" and r["scene"] == "cornell-transient"
    assert (r["res"], r["spp"], r["bins"], r["rounds"]) == (8, 4, 10, 1)
    assert r["integrator"] == "transient_path" and r["collector"] == "b"
    assert r["sums_layout"] == "packets"  # an 8² video's copies fit on any machine
    assert "collector b (packets layout)" in format_result(r)
    for name, ratio in RATIOS.items():
        assert r[f"{name}_s"] > 0 and r[ratio] > 0
    assert r["plain_s"] > 0
    # the first call of a fresh process, once each (rounds ≤ repeats)
    assert r["first_rounds"] == 1 and r["first_plain_s"] > 0 and r["first_color_stats_s"] > 0
    assert r["ratio_first_stats_vs_plain"] == r["first_color_stats_s"] / r["first_plain_s"]
    assert "x plain" in format_result(r) and "statistics, cached" in format_result(r)
    assert "first call in a fresh process (1 each)" in format_result(r)
    assert r["cached_hits"] == ["color", "stats"]  # the cached way reads, never renders
    assert r["memory"].startswith("NumPy")  # how the process asked for memory (dbench/memory.py)
    assert list(tmp_path.iterdir()) == []  # the fresh caches are removed afterwards


def test_bench_render_cli_transient_and_bins_refused_on_steady(tr, tmp_path, capsys):
    from dbench.cli import main
    from dbench.speed.transient_render import is_transient

    assert is_transient("fog-transient") and not is_transient("cornell")
    out = tmp_path / "bench.jsonl"
    assert main(["bench", "render", "--scene", "cornell-transient", "--res", "8", "--spp",
                 "2", "--bins", "8", "--repeats", "1", "--out", str(out)]) == 0
    assert "transient render benchmark" in capsys.readouterr().out
    assert '"render-transient"' in out.read_text()
    assert main(["bench", "render", "--scene", "cornell", "--bins", "8"]) == 2
    assert "--bins" in capsys.readouterr().err


def test_transient_cache_entries_are_stored_uncompressed_and_read_back_exactly(tr, tmp_cache):
    kw = dict(spp=4, res=8, bins=12, needs={"color", "stats"}, cache=tmp_cache,
              progress=False)
    first = tr.load_transient("cornell-transient", **kw)
    again = tr.load_transient("cornell-transient", **kw)
    assert set(again.meta["cache_hits"]) == {"color", "stats"}
    for name in ("color", "steady", "non_zero", "total_var"):
        np.testing.assert_array_equal(getattr(again, name), getattr(first, name))
    for name in ("mean", "var_mean", "m3"):
        np.testing.assert_array_equal(getattr(again.stats, name), getattr(first.stats, name))
    # one plain .npy per stored array (datasets/array_files.py), no zip archive
    assert not list(tmp_cache.root.glob("transient-*/*/arrays.npz"))
    folders = list(tmp_cache.root.glob("transient-*/*/arrays"))
    assert len(folders) == 2
    for folder in folders:
        for f in folder.iterdir():
            assert f.suffix == ".npy" and np.load(f) is not None


def test_cache_put_compresses_only_when_asked(tmp_cache):
    a = {"x": np.zeros(1000)}
    for compress in (True, False, None):  # None: the default, uncompressed
        kw = {} if compress is None else {"compress": compress}
        entry = tmp_cache.put("k", {"c": compress}, arrays=a, **kw)
        if compress:
            with zipfile.ZipFile(entry.path / "arrays.npz") as z:
                assert {i.compress_type for i in z.infolist()} == {zipfile.ZIP_DEFLATED}
        else:
            assert not (entry.path / "arrays.npz").exists()
            np.testing.assert_array_equal(np.load(entry.path / "arrays" / "x.npy"), a["x"])
        np.testing.assert_array_equal(tmp_cache.get("k", {"c": compress}).arrays()["x"], a["x"])


def test_bench_render_bins_must_be_a_count(capsys):
    from dbench.cli import main

    assert main(["bench", "render", "--scene", "fog-transient", "--bins", "0"]) == 2
    assert capsys.readouterr().err.startswith("dbench: --bins")
