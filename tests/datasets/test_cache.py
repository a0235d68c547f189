"""Dataset loading and the content-addressed cache."""

import numpy as np
import pytest

from dbench import datasets
from dbench.data import Frame
from dbench.datasets.cache import Cache, make_key
from dbench.datasets.checksums import DigestingWriter, file_record
from dbench.errors import DbenchInputError, UnknownNameError


def test_key_changes_with_anything_that_changes_pixels():
    base = {"scene": "a", "res": 8, "spp": 4, "dict": {"x": [1.0, 2.0]}}
    assert make_key(base) == make_key(dict(base))
    for change in ({"res": 9}, {"spp": 8}, {"dict": {"x": [1.0, 2.5]}}):
        assert make_key({**base, **change}) != make_key(base)


def test_put_get_roundtrip_and_interrupted_write(tmp_path):
    cache = Cache(tmp_path)
    desc = {"what": "x"}
    img = np.random.default_rng(0).random((4, 5, 3)).astype(np.float32)
    cache.put("noisy", desc, images={"color": img}, arrays={"m": np.arange(3.0)},
              meta={"a": 1})
    entry = cache.get("noisy", desc)
    np.testing.assert_array_equal(entry.images()["color"], img)
    np.testing.assert_array_equal(entry.arrays()["m"], np.arange(3.0))
    # A write killed half-way leaves a .tmp folder, which never looks like an entry.
    key = make_key({"what": "y"})
    half = tmp_path / "noisy" / f".tmp-{key}-dead"
    half.mkdir(parents=True)
    (half / "buffers.exr").write_bytes(b"partial")
    assert cache.get("noisy", {"what": "y"}) is None
    assert cache.clean() == 1 and not half.exists()


@pytest.mark.parametrize("compress", [False, True])
def test_the_checksum_taken_while_writing_is_the_files(tmp_path, compress):
    # the arrays' files (arrays.npz, or each file of arrays/) are hashed as they are written
    # (no second read); verify() hashes the files themselves
    rng = np.random.default_rng(1)
    arrays = {"mean": rng.random((6, 7, 30, 3)), "non_zero": rng.integers(0, 9, (6, 7, 30, 3)),
              "empty": np.zeros((0, 3)), "scalar": np.asarray("<i4")}
    cache = Cache(tmp_path)
    entry = cache.put("transient-stats", {"what": compress}, arrays=arrays, compress=compress)
    names = ["arrays.npz"] if compress else [f"arrays/{n}.npy" for n in arrays]
    assert sorted(entry.meta["files"]) == sorted(names)
    for name in names:
        assert entry.meta["files"][name] == file_record(entry.path / name)
    if not compress:  # each is a plain .npy, named by its array
        np.testing.assert_array_equal(np.load(entry.path / "arrays/mean.npy"), arrays["mean"])
        for bad in ("a/b", "..", ""):
            with pytest.raises(ValueError, match="plain file names"):
                cache.put("transient-stats", {"bad": bad}, arrays={bad: np.zeros(2)},
                          compress=False)
    got = cache.get("transient-stats", {"what": compress}).arrays()
    for name, value in arrays.items():
        np.testing.assert_array_equal(got[name], value)
        assert got[name].dtype == value.dtype
    # a chunk is checksummed before write() returns: its buffer may change after that
    buf = bytearray(b"abcd")
    with open(tmp_path / "x.bin", "wb") as fh:
        writer = DigestingWriter(fh)
        writer.write(memoryview(buf))
        buf[:] = b"zzzz"
        record = writer.record()
    assert record == file_record(tmp_path / "x.bin")


def test_noisy_images_are_stored_uncompressed_where_asked(tmp_path):
    # noisy colour compresses by 8 % at 3× the write time (dbench/io.py.write_exr); features
    # by 3×: each entry says which it holds
    import OpenEXR
    img = np.random.default_rng(2).random((4, 5, 3)).astype(np.float32)
    cache = Cache(tmp_path)
    for what, kw, expected in (("zip", {}, OpenEXR.ZIP_COMPRESSION),
                               ("raw", {"compress_images": False}, OpenEXR.NO_COMPRESSION)):
        entry = cache.put("noisy", {"what": what}, images={"color": img}, **kw)
        with OpenEXR.File(str(entry.path / "buffers.exr")) as f:
            assert f.header()["compression"] == expected
        np.testing.assert_array_equal(cache.get("noisy", {"what": what}).images()["color"], img)


def test_raw_images_are_an_uncompressed_part_beside_the_others(tmp_path):
    # a sequence frame: noisy colour uncompressed beside its G-buffer, ZIP (dbench/io.py)
    import OpenEXR

    from dbench import io

    rng = np.random.default_rng(3)
    images = {"color": rng.random((4, 5, 3)).astype(np.float32),
              "depth": rng.random((4, 5, 1)).astype(np.float32),
              "normal": rng.random((4, 5, 3)).astype(np.float32)}
    cache = Cache(tmp_path)
    entry = cache.put("seq-frame", {"w": 1}, images=images, raw_images=("color",))
    with OpenEXR.File(str(entry.path / "buffers.exr")) as f:
        parts = {p.header["compression"]: sorted(p.channels) for p in f.parts}
    assert parts == {OpenEXR.NO_COMPRESSION: ["color"],
                     OpenEXR.ZIP_COMPRESSION: ["depth.Z", "normal"]}
    got = cache.get("seq-frame", {"w": 1}).images()
    assert sorted(got) == sorted(images)
    for name, value in images.items():
        assert got[name].tobytes() == value.tobytes(), name
    # uncompressed throughout, or every buffer raw: one part
    for kw in ({"compress": False, "raw": ("color",)}, {"raw": tuple(images)}):
        io.write_exr(tmp_path / "one.exr", images, **kw)
        with OpenEXR.File(str(tmp_path / "one.exr")) as f:
            assert len(f.parts) == 1
            assert f.parts[0].header["compression"] == OpenEXR.NO_COMPRESSION
    with pytest.raises(ValueError, match="no buffers"):
        io.write_exr(tmp_path / "none.exr", {})


def test_file_record_in_chunks_equals_one_read(tmp_path):
    import hashlib

    import xxhash

    data = np.random.default_rng(2).bytes(100_003)
    (tmp_path / "f.bin").write_bytes(data)
    (tmp_path / "empty.bin").write_bytes(b"")
    whole = {"xxh3_128": lambda b: xxhash.xxh3_128(b).hexdigest(),
             "sha256": lambda b: hashlib.sha256(b).hexdigest()}
    for name, digest in whole.items():
        for chunk in (7, 4096, 1 << 20):
            assert file_record(tmp_path / "f.bin", name, chunk=chunk) == {
                "size": len(data), name: digest(data)}
        assert file_record(tmp_path / "empty.bin", name) == {"size": 0, name: digest(b"")}
    assert "xxh3_128" in file_record(tmp_path / "f.bin")  # what entries record now


def test_digest_counts_an_arrays_bytes_not_its_length():
    import xxhash

    from dbench.datasets.checksums import Digest

    a = np.arange(12.0).reshape(4, 3)
    d = Digest()
    d.update(a)
    d.update(a[1:3])  # a contiguous view: its own bytes
    assert d.record() == {"size": 6 * 3 * 8,
                          "xxh3_128": xxhash.xxh3_128(a.tobytes() + a[1:3].tobytes()).hexdigest()}
    with pytest.raises(ValueError, match="xxh3_128 or sha256"):
        Digest("md5")


def test_disabled_cache_stores_nothing(tmp_path):
    cache = Cache(tmp_path, enabled=False)
    cache.put("noisy", {"a": 1}, images={"color": np.zeros((2, 2, 3))})
    assert cache.get("noisy", {"a": 1}) is None and not any(tmp_path.iterdir())


@pytest.mark.mitsuba
def test_second_load_renders_nothing(renderer, tmp_cache):
    needs = {"color", "albedo", "normal", "depth", "stats", "reference"}
    first = datasets.load("cornell", spp=4, res=12, needs=needs, ref_spp=16, cache=tmp_cache,
                          progress=False)
    assert set(first.meta["rendered"]) == {"color", "stats", "features", "reference"}
    second = datasets.load("cornell", spp=4, res=12, needs=needs, ref_spp=16, cache=tmp_cache,
                           progress=False)
    assert second.meta["rendered"] == []
    for name in ("color", "albedo", "normal", "depth", "reference"):
        np.testing.assert_array_equal(getattr(first, name), getattr(second, name))
    np.testing.assert_array_equal(first.stats.var_mean, second.stats.var_mean)
    # Only what is asked for is rendered or returned.
    third = datasets.load("cornell", spp=4, res=12, needs={"color"}, cache=tmp_cache,
                          progress=False)
    assert third.stats is None and third.albedo is None and third.reference is None
    # Stats in another transform reuse the cached color (same samples) but add a stats entry.
    fourth = datasets.load("cornell", spp=4, res=12, needs={"stats"}, transform="identity",
                           cache=tmp_cache, progress=False)
    assert fourth.meta["rendered"] == ["color", "stats"] or "stats" in fourth.meta["rendered"]
    np.testing.assert_array_equal(fourth.color, first.color)


def test_load_rejects_bad_arguments():
    with pytest.raises(UnknownNameError, match="available scenes"):
        datasets.load("nope", spp=4, res=8)
    with pytest.raises(DbenchInputError, match="spp"):
        datasets.load("cornell", spp=0, res=8)
    with pytest.raises(DbenchInputError, match="needs"):
        datasets.load("cornell", spp=4, res=8, needs={"motion"})


def test_frame_checks_shapes_and_names_the_buffer():
    with pytest.raises(DbenchInputError, match=r"albedo: expected shape \(4, 5, 3\)"):
        Frame(color=np.zeros((4, 5, 3)), albedo=np.zeros((4, 5)))
    with pytest.raises(DbenchInputError, match="color"):
        Frame(color=np.zeros((4, 5)))
    f = Frame(color=np.zeros((4, 5, 3), np.float64), depth=np.ones((4, 5)))
    assert f.color.dtype == np.float32 and f.depth.shape == (4, 5, 1)
