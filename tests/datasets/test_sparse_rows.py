"""Arrays stored by their non-zero rows (dbench/datasets/sparse_rows.py): bit for bit back,
through the cache too, with entries written before packing still read."""

import numpy as np
import pytest

from dbench.datasets import sparse_rows
from dbench.datasets.cache import CHECKSUM_FORMAT, FORMATS, Cache


def _same_bits(a, b):
    return a.dtype == b.dtype and a.shape == b.shape and \
        np.array_equal(np.ascontiguousarray(a).view(np.uint8),
                       np.ascontiguousarray(b).view(np.uint8))


def _hostile(rng, shape=(5, 6, 40, 3)):
    """A mostly empty float64 video with -0.0, NaN (with a payload), ±inf and a subnormal in
    rows that are otherwise zero, a float32 one, and integer counts."""
    rows = (rng.random(shape[:-1]) < 0.15)[..., None]  # the (pixel, bin) rows a path reached
    mean = np.where(rows, rng.normal(size=shape), 0.0)
    mean[0, 0, 0, 1] = -0.0
    mean[1, 2, 3, 0] = np.float64(np.frombuffer(np.uint64(0x7FF8000000000123).tobytes(),
                                                np.float64)[0])
    mean[2, 2, 2, 2] = np.inf
    mean[3, 3, 3, 0] = -np.inf
    mean[4, 4, 4, 1] = 5e-324
    colour = np.where(rows, rng.random(shape), 0).astype(np.float32)
    colour[0, 1, 5, 2] = np.float32(-0.0)
    counts = np.where(rows, rng.integers(1, 64, shape), 0).astype(np.int32)
    return {"mean": mean, "color": colour, "non_zero": counts}


def test_unpack_of_pack_is_the_input_bit_for_bit():
    rng = np.random.default_rng(3)
    arrays = {**_hostile(rng), "steady": rng.random((5, 6, 3))}
    stored = sparse_rows.pack(arrays, ("mean", "color", "non_zero"))
    assert "mean" not in stored and "steady" in stored  # steady is stored as given
    back = sparse_rows.unpack(stored)
    assert set(back) == set(arrays)
    for name, value in arrays.items():
        assert _same_bits(back[name], value), name
    # only the rows where some array is non-zero (in its bits) are kept
    keep = np.zeros((5, 6, 40), bool)
    for name in ("mean", "color", "non_zero"):
        a = arrays[name]
        keep |= (a.reshape(-1, 3).view(f"u{a.itemsize}") != 0).any(1).reshape(5, 6, 40)
    assert stored["rows~mean"].shape == (int(keep.sum()), 3) and keep.sum() < keep.size / 2
    assert keep[0, 0, 0] and keep[0, 1, 5]  # the -0.0 rows


@pytest.mark.parametrize("fill", [0.0, 1.0])
def test_all_empty_and_all_full(fill):
    a = np.full((3, 4, 2), fill)
    back = sparse_rows.unpack(sparse_rows.pack({"a": a}, ("a",)))
    assert _same_bits(back["a"], a)


def test_pack_refuses_arrays_of_other_shapes_and_passes_the_rest():
    with pytest.raises(ValueError, match="share every axis but the last"):
        sparse_rows.pack({"a": np.zeros((2, 3, 3)), "b": np.zeros((2, 4, 3))}, ("a", "b"))
    plain = {"x": np.arange(3.0)}
    assert sparse_rows.pack(plain, ("not-there",)) == plain
    assert sparse_rows.unpack(plain) == plain


def _data_bytes(entry):
    return sum(f.stat().st_size for f in entry.path.rglob("*") if f.is_file() and
               f.name != "meta.json")


@pytest.mark.parametrize("compress", [False, True])
def test_cache_stores_packed_rows_and_reads_them_back(tmp_path, compress):
    rng = np.random.default_rng(4)
    arrays = {**_hostile(rng), "total_var": rng.random((5, 6, 3))}
    cache = Cache(tmp_path)
    put = cache.put("transient-stats", {"w": 1}, arrays=arrays, compress=compress,
                    sparse=("mean", "color", "non_zero"))
    # a format earlier code does not read (it would misread packed rows), the layout told
    # apart by the files
    assert put.meta["cache_format"] == CHECKSUM_FORMAT == max(FORMATS)
    assert (put.path / "arrays.npz").is_file() == compress
    assert (put.path / "arrays" / "rows~mask.npy").is_file() == (not compress)
    for got in (cache.get("transient-stats", {"w": 1}).arrays(), put.arrays()):
        for name, value in arrays.items():
            assert _same_bits(got[name], value), name
    dense = cache.put("transient-stats", {"w": 2}, arrays=arrays, compress=compress)
    assert dense.meta["cache_format"] == CHECKSUM_FORMAT
    assert _same_bits(cache.get("transient-stats", {"w": 2}).arrays()["mean"], arrays["mean"])
    # a packed entry is smaller: most rows are empty
    assert _data_bytes(put) < _data_bytes(dense)


def test_rows_given_by_the_caller_are_the_rows_stored(tmp_path):
    # the transient collector finds the rows on the device (cache.put's rows): a superset of
    # the non-zero rows stores the extra ones as zeros and reads back bit for bit
    rng = np.random.default_rng(5)
    arrays = _hostile(rng)
    found = np.unpackbits(sparse_rows.pack(arrays, ("mean",))[sparse_rows.MASK],
                          count=5 * 6 * 40).astype(bool).reshape(5, 6, 40)
    wider = found | (rng.random(found.shape) < 0.3)
    packed = sparse_rows.pack(arrays, ("mean",))
    given = {k: v.array() if isinstance(v, sparse_rows.Rows) else v
             for k, v in sparse_rows.layout(arrays, ("mean",), keep=wider).items()}
    assert given["rows~mean"].shape[0] == wider.sum() > packed["rows~mean"].shape[0]
    assert _same_bits(sparse_rows.unpack(given)["mean"], arrays["mean"])
    entry = Cache(tmp_path).put("k", {"a": 1}, arrays=arrays, compress=False, sparse=("mean",),
                                rows=wider)
    assert _same_bits(Cache(tmp_path).get("k", {"a": 1}).arrays()["mean"], arrays["mean"])
    assert np.load(entry.path / "arrays" / "rows~mean.npy").shape[0] == wider.sum()
    for bad in (wider[..., :-1], wider.astype(np.uint8)):
        with pytest.raises(ValueError, match="rows to keep must be bool"):
            sparse_rows.layout(arrays, ("mean",), keep=bad)


@pytest.mark.parametrize("compress", [False, True])
def test_rows_gathered_by_the_caller_are_stored_as_the_host_gathers_them(tmp_path, monkeypatch,
                                                                         compress):
    # the transient collector gathers the kept rows on the device (cache.put's kept): the
    # entry's files are byte for byte those of the host's gather, a narrowed integer array
    # included, over several chunks
    monkeypatch.setattr(sparse_rows, "CHUNK_ROWS", 7)
    rng = np.random.default_rng(6)
    arrays = {**_hostile(rng), "total_var": rng.random((5, 6, 3))}
    names = ("mean", "color", "non_zero")
    keep = np.unpackbits(sparse_rows.pack(arrays, names)[sparse_rows.MASK],
                         count=5 * 6 * 40).astype(bool).reshape(5, 6, 40)
    kept = {n: arrays[n].reshape(-1, 3)[keep.reshape(-1)] for n in names}
    entries = [Cache(tmp_path / d).put("k", {"a": 1}, arrays=arrays, compress=compress,
                                       sparse=names, rows=keep, kept=k)
               for d, k in (("host", None), ("given", kept))]
    assert entries[0].meta["files"] == entries[1].meta["files"]
    got = Cache(tmp_path / "given").get("k", {"a": 1}).arrays()
    assert all(_same_bits(got[n], arrays[n]) for n in arrays)
    # what the caller gathered is what is stored (its rows are the caller's to get right)
    other = {"mean": np.ones_like(kept["mean"])}
    layout = sparse_rows.layout(arrays, names, keep=keep, kept=other)
    assert np.array_equal(layout["rows~mean"].array(), other["mean"])
    for bad in ({"mean": kept["mean"][:-1]}, {"non_zero": kept["non_zero"].astype(np.uint8)}):
        with pytest.raises(ValueError, match="kept rows must be"):
            sparse_rows.layout(arrays, names, keep=keep, kept=bad)
    for keep_, bad in ((None, kept), (keep, {"total_var": kept["mean"]})):
        with pytest.raises(ValueError, match="gathered rows"):
            sparse_rows.layout(arrays, names, keep=keep_, kept=bad)


@pytest.mark.parametrize("values, stored", [
    ((0, 64), np.uint8), ((-3, 100), np.int8), ((0, 300), np.uint16), ((-1, 40000), np.int32),
    ((0, 2 ** 31 - 1), np.int32)])
def test_integers_are_stored_narrow_and_given_back_in_their_own_type(values, stored):
    counts = np.zeros((4, 5, 3), np.int32)
    counts[1, 2] = values[0]
    counts[3, 4] = values[1]
    counts[0, 0, 1] = 1
    packed = sparse_rows.pack({"non_zero": counts}, ("non_zero",))
    assert packed["rows~non_zero"].dtype == stored
    assert (sparse_rows.DTYPE + "non_zero" in packed) == (stored != np.int32)
    assert _same_bits(sparse_rows.unpack(packed)["non_zero"], counts)


def test_floats_and_bools_keep_their_type():
    a = {"f": np.ones((2, 2, 3), np.float32), "b": np.ones((2, 2, 3), bool)}
    packed = sparse_rows.pack(a, ("f", "b"))
    assert packed["rows~f"].dtype == np.float32 and packed["rows~b"].dtype == bool
    assert not any(k.startswith(sparse_rows.DTYPE) for k in packed)


@pytest.mark.parametrize("chunk", [1, 7, 1 << 16])
def test_save_streams_rows_in_chunks_and_np_load_reads_what_pack_gives(tmp_path, monkeypatch,
                                                                       chunk):
    monkeypatch.setattr(sparse_rows, "CHUNK_ROWS", chunk)
    rng = np.random.default_rng(5)
    arrays = {**_hostile(rng), "steady": rng.random((5, 6, 3))}
    names = ("mean", "color", "non_zero")
    with open(tmp_path / "a.npz", "wb") as fh:
        sparse_rows.save(fh, arrays, names)
    expected = sparse_rows.pack(arrays, names)
    with np.load(tmp_path / "a.npz") as z:
        assert set(z.files) == set(expected)
        for k in z.files:
            assert _same_bits(z[k], np.asarray(expected[k])), k
        back = sparse_rows.unpack({k: z[k] for k in z.files})
    for name, value in arrays.items():
        assert _same_bits(back[name], value), name


def test_save_writes_every_kind_of_plain_array_as_np_savez_does(tmp_path):
    arrays = {"scalar": np.asarray(3.5), "text": np.asarray("<i4"), "empty": np.zeros((0, 3)),
              "strided": np.arange(24.0).reshape(4, 6)[:, ::2], "flags": np.eye(3, dtype=bool),
              "big": np.arange(200_000, dtype=np.int64)}
    with open(tmp_path / "a.npz", "wb") as fh:
        sparse_rows.save(fh, arrays)
    with np.load(tmp_path / "a.npz") as z:
        for name, value in arrays.items():
            assert z[name].shape == value.shape and z[name].dtype == value.dtype, name
            assert np.array_equal(z[name], value), name
    with pytest.raises(ValueError, match="object array"):
        with open(tmp_path / "b.npz", "wb") as fh:
            sparse_rows.save(fh, {"o": np.array([None])})
