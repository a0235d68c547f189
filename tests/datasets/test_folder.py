"""Folders of EXR renders (dbench.datasets.folders.load) and the exporter writing them (export)."""
import json
import re
from pathlib import Path

import numpy as np
import pytest

from dbench.data import Frame, SampleStats
from dbench.datasets.folders.export import check_variance, export_frame, write_dataset_json
from dbench.datasets.folders.exr_layers import detect_normal_encoding, layers_of
from dbench.datasets.folders.load import (STATS_FROM_VARIANCE, is_folder_scene, load_folder,
                                    scan_folder)
from dbench.datasets.stats import PowerSums
from dbench.errors import DbenchInputError
from exr_files import write_exr as _exr, write_rgb as _rgb  # tests/exr_files.py

H, W = 24, 40  # non-square, so a transposed read cannot pass


def _img(seed, h=H, w=W, c=3, lo=0.0, hi=4.0):
    return np.random.default_rng(seed).uniform(lo, hi, (h, w, c)).astype(np.float32)


def _unit(seed, h=H, w=W):
    n = np.random.default_rng(seed).normal(size=(h, w, 3))
    return (n / np.linalg.norm(n, axis=-1, keepdims=True)).astype(np.float32)


def _frame(seed, spp):
    rng = np.random.default_rng(seed)
    acc = PowerSums((H, W, 3), "box-cox", 0.5)
    samples = rng.exponential(1.0, (spp, H, W, 3)).astype(np.float32)
    for s in samples:
        acc.add(s)
    motion = rng.normal(0, 2, (H, W, 2)).astype(np.float32)
    motion[:3] = np.nan  # no previous position there
    # the samples' mean is 1: the reference is 1 with the noise its variance states (a
    # reference its own noise check does not contradict)
    ref_var = _img(seed + 6, hi=1e-3)
    reference = (1.0 + rng.normal(size=(H, W, 3)) * np.sqrt(ref_var)).astype(np.float32)
    return Frame(color=samples.mean(axis=0), albedo=_img(seed + 1, hi=1.0), normal=_unit(seed + 2),
                 depth=_img(seed + 3, c=1, lo=0.5, hi=9.0), position=_img(seed + 4, lo=-5, hi=5),
                 emitter=(rng.random((H, W, 1)) < 0.1).astype(np.float32), stats=acc.finalize(),
                 reference=reference, reference_var=ref_var, motion=motion,
                 meta={"ref_spp": 256})


def _same_bits(a, b):
    assert a.dtype == b.dtype and a.shape == b.shape
    assert np.array_equal(a.view(np.uint8), b.view(np.uint8))


def test_export_then_load_is_bit_exact(tmp_path):
    frames = {4: _frame(0, 4), 16: _frame(10, 16)}
    frames[16].reference[...] = frames[4].reference  # one reference shared by both spp
    frames[16].reference_var[...] = frames[4].reference_var
    for spp, fr in frames.items():
        written = export_frame(fr, tmp_path, "room", spp)
        assert tmp_path / f"room_{spp:04d}.stats.npz" in written
    write_dataset_json(tmp_path, ref_spp=256, ev=1.5, description="synthetic")
    info = scan_folder(tmp_path)
    assert (info.name, info.width, info.height, info.spps) == ("room", W, H, (4, 16))
    assert (info.ref_spp, info.reference_from, info.ev, info.normals) == (256, "file", 1.5,
                                                                          "signed")
    assert info.stats_source == "dbench statistics (box-cox)" and info.frames is None
    assert info.buffers == {"color", "albedo", "normal", "depth", "position", "emitter",
                            "stats", "reference", "motion"}
    for spp, src in frames.items():
        got = load_folder(info, spp)
        for b in ("color", "albedo", "normal", "depth", "position", "emitter", "motion",
                  "reference"):
            _same_bits(getattr(got, b), getattr(src, b))
        for k in ("n", "mean", "var_mean", "m3"):
            _same_bits(getattr(got.stats, k), getattr(src.stats, k))
        assert (got.stats.transform, got.stats.lam) == ("box-cox", 0.5)
        assert got.stats.diagnostics == src.stats.diagnostics
        # var·256 and then ÷256 in float64 around one float32 rounding: within 1e-6 relative.
        np.testing.assert_allclose(got.reference_var, src.reference_var, rtol=1e-6, atol=0)
        m = got.meta
        assert m["ref_var_known"] and m["ref_spp"] == 256 and m["ref_seed"] is None
        assert m["ref_rmse"] == pytest.approx(np.sqrt(np.mean(src.reference_var, dtype=float)))
        assert m["files"]["color"] == f"room_{spp:04d}.hdr.exr"
        assert m["files"]["reference_var"] == "room_ref.var.exr"
        assert (m["source"], m["res"], m["spp"], m["kind"]) == ("folder", f"{W}x{H}", spp, "steady")
    only = load_folder(tmp_path, 4, needs=["albedo"])
    assert only.albedo is not None and only.normal is None and only.stats is None
    assert only.reference is None and only.emitter is None
    with_ref = load_folder(info, 4, needs={"reference"})
    assert with_ref.emitter is not None  # the reference brings the emitter mask


def test_hand_written_oidn_folder(tmp_path):
    h, w = 5, 7
    color, alb, nrm, ref = _img(1, h, w), _img(2, h, w, hi=1), _unit(3, h, w), _img(4, h, w)
    _rgb(tmp_path / "view_0004.hdr.exr", color)
    _rgb(tmp_path / "view_0004.alb.exr", alb)
    _rgb(tmp_path / "view_0004.nrm.exr", nrm)
    _rgb(tmp_path / "view_ref.hdr.exr", ref)
    _rgb(tmp_path / "view_0004.ldr.exr", np.clip(color, 0, 1))
    (tmp_path / "notes.txt").write_text("not a render")
    info = scan_folder(tmp_path)
    assert (info.width, info.height, info.spps, info.ref_spp) == (w, h, (4,), None)
    assert info.buffers == {"color", "albedo", "normal", "reference"}
    assert info.ignored == ("view_0004.ldr.exr",) and info.stats_source is None
    f = load_folder(info, 4)
    np.testing.assert_array_equal(f.color, color)
    np.testing.assert_array_equal(f.albedo, alb)
    np.testing.assert_array_equal(f.normal, nrm)
    np.testing.assert_array_equal(f.reference, ref)
    assert f.reference_var is None and f.meta["ref_var_known"] is False
    assert np.isnan(f.meta["ref_rmse"])  # unknown, never reported as 0
    assert f.meta["scene"] == f"{tmp_path.name}/view"
    with pytest.raises(DbenchInputError, match=r"no depth buffer; available: albedo, color"):
        load_folder(info, 4, needs={"depth"})
    with pytest.raises(DbenchInputError, match=r"spp 8 is not offered; expected one of \[4\]"):
        load_folder(info, 8)


def test_highest_spp_serves_as_reference(tmp_path):
    # two renders of one scene, of 4 and 64 spp, whose per-sample variance the file states
    truth, sigma2, rng = _img(1), _img(3, hi=0.5), np.random.default_rng(2)
    lo, hi = ((truth + rng.normal(size=truth.shape) * np.sqrt(sigma2 / n)).astype(np.float32)
              for n in (4, 64))
    _rgb(tmp_path / "v_4spp.hdr.exr", lo)
    _rgb(tmp_path / "v_64spp.hdr.exr", hi)
    _rgb(tmp_path / "v_64spp.var.exr", sigma2)
    info = scan_folder(tmp_path)
    assert (info.spps, info.ref_spp, info.reference_from) == ((4,), 64, "highest-spp")
    f = load_folder(info, 4)
    np.testing.assert_array_equal(f.reference, hi)
    np.testing.assert_allclose(f.reference_var, sigma2 / 64, rtol=1e-7)
    assert f.meta["reference_from"] == "highest-spp" and f.meta["ref_var_known"]
    with pytest.raises(DbenchInputError, match="spp 64 is not offered"):
        load_folder(info, 64)


def test_unsigned_normals_detected_and_declared(tmp_path):
    n = _unit(7)
    stored = n * 0.5 + 0.5
    stored[:2] = 0.0  # background: nothing hit
    _rgb(tmp_path / "v_0002.hdr.exr", _img(1))
    _rgb(tmp_path / "v_0002.nrm.exr", stored)
    _rgb(tmp_path / "v_ref.hdr.exr", _img(2))
    info = scan_folder(tmp_path)
    assert info.normals == "unsigned"
    f = load_folder(info, 2)
    np.testing.assert_allclose(f.normal[2:], n[2:], atol=1e-6)
    assert not f.normal[:2].any() and f.meta["normals"] == "unsigned"
    # Signed normals that all face one octant keep unit length as they are: stay signed.
    assert detect_normal_encoding(np.abs(n)) == "signed"
    (tmp_path / "dataset.json").write_text(json.dumps({"normals": "signed"}))
    declared = scan_folder(tmp_path)
    assert declared.normals == "signed"
    np.testing.assert_array_equal(load_folder(declared, 2).normal, stored)


def test_mitsuba_aov_multilayer(tmp_path):
    color, alb, nrm, pos = _img(1), _img(2, hi=1), _unit(3), _img(4, lo=-3, hi=3)
    depth = _img(5, c=1, lo=1, hi=8)
    ch = {c: color[..., i] for i, c in enumerate("RGB")}
    ch["A"] = np.ones((H, W))
    ch.update({f"albedo.{c}": alb[..., i] for i, c in enumerate("RGB")})
    ch.update({f"nn.{c}": nrm[..., i] for i, c in enumerate("XYZ")})
    ch.update({f"pp.{c}": pos[..., i] for i, c in enumerate("XYZ")})
    ch["dd.T"] = depth[..., 0]
    _exr(tmp_path / "cbox_0008.exr", ch)
    _exr(tmp_path / "cbox_ref.exr", {"R": color[..., 0], "G": color[..., 1],
                                     "B": color[..., 2], "A": np.ones((H, W))})
    info = scan_folder(tmp_path)
    assert info.buffers == {"color", "albedo", "normal", "depth", "position", "reference"}
    f = load_folder(info, 8)
    for got, want in ((f.color, color), (f.albedo, alb), (f.normal, nrm), (f.position, pos),
                      (f.depth, depth)):
        np.testing.assert_array_equal(got, want)
    assert f.meta["unused_channels"] == {"cbox_0008.exr": ["A"], "cbox_ref.exr": ["A"]}


def test_alias_table_on_channel_names():
    names = ["R", "G", "B", "A", "ALBEDO.r", "Albedo.g", "albedo.B", "dd.y.T", "Nx", "Ny", "Nz",
             "Ns.X", "Ns.Y", "Ns.Z", "P.X", "P.Y", "P.Z", "foo.X", "foo.Y", "foo.Z", "dzdx"]
    found, unused = layers_of(Path("x.exr"), names)
    assert {b: found[b].channels for b in found} == {
        "color": ("R", "G", "B"), "albedo": ("ALBEDO.r", "Albedo.g", "albedo.B"),
        "depth": ("dd.y.T",), "normal": ("Ns.X", "Ns.Y", "Ns.Z"), "position": ("P.X", "P.Y", "P.Z")}
    assert unused == ["A", "Nx", "Ny", "Nz", "dzdx", "foo.X", "foo.Y", "foo.Z"]
    with pytest.raises(DbenchInputError, match=r"x\.exr: channels nn\.X.*and Ns\.X.*normal"):
        layers_of(Path("x.exr"), ["nn.X", "nn.Y", "nn.Z", "Ns.X", "Ns.Y", "Ns.Z"])


def test_pbrt_gbuffer_multilayer_gives_stats_from_variance(tmp_path):
    truth, alb, ns, ng, pos, var = (_img(1), _img(2, hi=1), _unit(3), _unit(4),
                                    _img(5, lo=-2, hi=2), _img(6, hi=0.3))
    rng = np.random.default_rng(9)  # a 16-spp render and a 1024-spp reference of one scene
    color = (truth + rng.normal(size=truth.shape) * np.sqrt(var / 16)).astype(np.float32)
    ch = {c: color[..., i] for i, c in enumerate("RGB")}
    for prefix, img, comps in (("Albedo.", alb, "RGB"), ("Ns", ns, "xyz"), ("N", ng, "xyz"),
                               ("P", pos, "xyz"), ("Variance.", var, "RGB"),
                               ("RelativeVariance.", var, "RGB")):
        ch.update({f"{prefix}{c}": img[..., i] for i, c in enumerate(comps)})
    ch["dzdx"] = ch["dzdy"] = np.zeros((H, W))
    _exr(tmp_path / "pb_16.exr", ch)
    ref_var = _img(8, hi=0.1)
    ref = (truth + rng.normal(size=truth.shape) * np.sqrt(ref_var / 1024)).astype(np.float32)
    _exr(tmp_path / "pb_gt.exr", {**{c: ref[..., i] for i, c in enumerate("RGB")},
                                  **{f"Variance.{c}": ref_var[..., i]
                                     for i, c in enumerate("RGB")}})
    (tmp_path / "dataset.json").write_text(json.dumps({"ref_spp": 1024}))
    info = scan_folder(tmp_path)
    assert info.stats_source == STATS_FROM_VARIANCE and "stats" in info.buffers
    f = load_folder(info, 16)
    np.testing.assert_array_equal(f.normal, ns)  # the shading normal, not the geometric one
    np.testing.assert_array_equal(f.position, pos)
    s = f.stats
    assert s.transform == "identity" and not s.m3.any() and (s.n == 16).all()
    np.testing.assert_array_equal(s.mean, color.astype(np.float64))
    np.testing.assert_array_equal(s.var_mean, var.astype(np.float64) / 16)
    np.testing.assert_allclose(f.reference_var, ref_var / 1024, rtol=1e-7)
    assert f.meta["files"]["stats"] == "pb_16.exr"


def test_several_views_and_selection(tmp_path):
    for view in ("alpha", "beta"):
        _rgb(tmp_path / f"{view}_0004.hdr.exr", _img(1))
        _rgb(tmp_path / f"{view}_ref.hdr.exr", _img(2))
    with pytest.raises(DbenchInputError, match=r"several views \(alpha, beta\).*/NAME"):
        scan_folder(tmp_path)
    assert scan_folder(tmp_path / "beta").name == "beta"
    assert is_folder_scene(str(tmp_path)) and is_folder_scene(str(tmp_path / "beta"))
    assert not is_folder_scene(str(tmp_path / "gamma"))
    assert not is_folder_scene(str(tmp_path / "nowhere" / "beta"))
    with pytest.raises(DbenchInputError, match="views: alpha, beta"):
        scan_folder(tmp_path / "gamma")


def _bad(folder, build):
    """The message of the DbenchInputError that scanning or loading the folder raises."""
    folder.mkdir()
    build(folder)
    with pytest.raises(DbenchInputError) as err:
        load_folder(scan_folder(folder), 4)
    return str(err.value)


def test_bad_folders_name_the_file(tmp_path):
    def sizes(d):
        _rgb(d / "v_0004.hdr.exr", _img(1))
        _rgb(d / "v_ref.hdr.exr", _img(2, h=H + 1))
    msg = _bad(tmp_path / "sizes", sizes)
    assert "v_0004.hdr.exr" in msg and "v_ref.hdr.exr" in msg and f"{W}x{H + 1}" in msg

    def all_nan(d):
        _rgb(d / "v_0004.hdr.exr", np.full((H, W, 3), np.nan))
        _rgb(d / "v_ref.hdr.exr", _img(2))
    assert "v_0004.hdr.exr: color is NaN everywhere" in _bad(tmp_path / "nan", all_nan)

    def single(d):
        _rgb(d / "v_0004.hdr.exr", _img(1))
    assert "v_0004.hdr.exr: the only spp (4) and no reference" in _bad(tmp_path / "one",
                                                                       single)

    def unknown(d):
        _rgb(d / "picture.exr", _img(1))
    msg = _bad(tmp_path / "unknown", unknown)
    assert "picture.exr" in msg and "<name>_<spp>.<tag>.exr" in msg

    def corrupt(d):
        (d / "v_0004.hdr.exr").write_bytes(b"\x76\x2f\x31\x01 truncated")
        _rgb(d / "v_ref.hdr.exr", _img(2))
    assert "v_0004.hdr.exr: not a readable EXR file" in _bad(tmp_path / "corrupt", corrupt)

    def channels(d):
        _rgb(d / "v_0004.hdr.exr", _img(1))
        _rgb(d / "v_0004.depth.exr", _img(3))
        _rgb(d / "v_ref.hdr.exr", _img(2))
    assert "v_0004.depth.exr: depth needs 1 channel" in _bad(tmp_path / "chan", channels)

    def ref_inf(d):
        _rgb(d / "v_0004.hdr.exr", _img(1))
        ref = _img(2)
        ref[3, 4, 1] = np.inf
        _rgb(d / "v_ref.hdr.exr", ref)
    assert "v_ref.hdr.exr: reference contains NaN or Inf" in _bad(tmp_path / "inf", ref_inf)

    def duplicate(d):
        _rgb(d / "v_0004.hdr.exr", _img(1))
        _rgb(d / "v_0004.alb.exr", _img(3))
        _rgb(d / "v_0004.exr", _img(4), prefix="albedo.")
        _rgb(d / "v_ref.hdr.exr", _img(2))
    def npz(d):
        _rgb(d / "v_0004.hdr.exr", _img(1))
        (d / "v_0004.stats.npz").write_bytes(b"PK not really")
        _rgb(d / "v_ref.hdr.exr", _img(2))
    assert "v_0004.stats.npz: not a readable statistics file" in _bad(tmp_path / "npz", npz)

    def emitter(d):
        _rgb(d / "v_0004.hdr.exr", _img(1))
        _exr(d / "v_0004.emitter.exr", {"Y": np.full((H, W), 1.5)})
        _rgb(d / "v_ref.hdr.exr", _img(2))
    assert "v_0004.emitter.exr: emitter values" in _bad(tmp_path / "emit", emitter)

    msg = _bad(tmp_path / "dup", duplicate)
    assert "albedo" in msg and "v_0004.alb.exr" in msg and "v_0004.exr" in msg


def test_sequence_folder(tmp_path):
    for k in range(2):
        fr = Frame(color=_img(k), motion=_img(10 + k, c=2, lo=-3, hi=3),
                   reference=_img(20 + k), meta={})
        export_frame(fr, tmp_path, "walk", 4, frame_index=k)
    info = scan_folder(tmp_path)
    assert info.frames == (0, 1) and info.spps == (4,)
    assert info.buffers == {"color", "motion", "reference"}
    f = load_folder(info, 4, frame=1)
    np.testing.assert_array_equal(f.motion, _img(11, c=2, lo=-3, hi=3))
    np.testing.assert_array_equal(f.reference, _img(21))
    assert f.meta["frame"] == 1 and f.meta["files"]["motion"] == "walk_f0001_0004.mv.exr"
    with pytest.raises(DbenchInputError, match=r"frame None; expected one of \[0, 1\]"):
        load_folder(info, 4)
    (tmp_path / "walk_f0001_0004.mv.exr").unlink()
    with pytest.raises(DbenchInputError, match=r"walk_f0001_0004\.mv\.exr: missing; frame 1"):
        scan_folder(tmp_path)


def test_fingerprint_follows_file_bytes(tmp_path):
    _rgb(tmp_path / "v_0004.hdr.exr", _img(1))
    _rgb(tmp_path / "v_ref.hdr.exr", _img(2))
    first = scan_folder(tmp_path).fingerprint
    assert len(first) == 16 and int(first, 16) >= 0
    assert scan_folder(tmp_path).fingerprint == first
    changed = _img(2)
    changed[0, 0, 0] += 1.0
    _rgb(tmp_path / "v_ref.hdr.exr", changed)
    assert scan_folder(tmp_path).fingerprint != first
    second = scan_folder(tmp_path).fingerprint
    (tmp_path / "dataset.json").write_text(json.dumps({"ev": 1.0}))
    third = scan_folder(tmp_path).fingerprint
    assert third not in (first, second)
    # dataset.json counts by what it says: re-indented, the folder keeps its identity
    (tmp_path / "dataset.json").write_text(json.dumps({"ev": 1.0}, indent=4) + "\n\n")
    assert scan_folder(tmp_path).fingerprint == third
    (tmp_path / "dataset.json").write_text(json.dumps({"ev": 2.0}))
    assert scan_folder(tmp_path).fingerprint not in (first, second, third)


def test_stats_built_from_samples_survive_export(tmp_path):
    # Identity statistics also round-trip, and constructed SampleStats need no PowerSums.
    mean = _img(3).astype(np.float64)
    stats = SampleStats(n=np.full((H, W, 3), 8.0), mean=mean, var_mean=mean / 8,
                        m3=np.zeros((H, W, 3)), transform="identity", lam=0.5)
    fr = Frame(color=mean.astype(np.float32), stats=stats, reference=_img(4), meta={})
    export_frame(fr, tmp_path, "s", 8)
    export_frame(fr, tmp_path, "s", 2, write_reference=False)
    info = scan_folder(tmp_path)
    assert info.stats_source == "dbench statistics (identity)" and info.ref_spp is None
    got = load_folder(info, 8)
    _same_bits(got.stats.var_mean, stats.var_mean)
    assert got.meta["ref_var_known"] is False


def test_a_transform_other_than_the_folders_statistics_is_refused(tmp_path):
    """The statistics of a folder were gathered with their transform: --transform asks for
    them as they are, or is refused, never read under another name."""
    from dbench import datasets
    from dbench.datasets.scenes import catalogue

    mean = _img(3).astype(np.float64)
    stats = SampleStats(n=np.full((H, W, 3), 8.0), mean=mean, var_mean=mean / 8,
                        m3=np.zeros((H, W, 3)), transform="box-cox", lam=0.25)
    export_frame(Frame(color=mean.astype(np.float32), stats=stats, reference=_img(4), meta={}),
                 tmp_path, "s", 8)
    scene = catalogue.get(str(tmp_path))
    for transform, lam in ((None, 0.5), ("box-cox", 0.25)):
        got = datasets.load(scene, spp=8, res=None, transform=transform, lam=lam)
        assert (got.stats.transform, got.stats.lam) == ("box-cox", 0.25)
    for transform, lam, asked in (("yeo-johnson", 0.25, "yeo-johnson (λ 0.25)"),
                                  ("box-cox", 0.5, "box-cox (λ 0.5)"),
                                  ("identity", 0.5, "identity was")):
        with pytest.raises(DbenchInputError, match=r"--transform: .* gathered with box-cox "
                                                   r"\(λ 0.25\); " + re.escape(asked)):
            datasets.load(scene, spp=8, res=None, transform=transform, lam=lam)


def test_statistics_of_another_spp_are_refused(tmp_path):
    """A .stats.npz whose sample count is the same at every pixel and not its name's spp holds
    other samples than the colour beside it (another spp's file copied over): refused, naming
    the file. A count that varies per pixel (adaptive sampling) is read as it is."""
    mean = _img(3).astype(np.float64)

    def frame(n):
        st = SampleStats(n=n, mean=mean, var_mean=mean / 8, m3=np.zeros((H, W, 3)),
                         transform="identity", lam=0.5)
        return Frame(color=mean.astype(np.float32), stats=st, reference=_img(4), meta={})

    export_frame(frame(np.full((H, W, 3), 4.0)), tmp_path, "s", 16)
    export_frame(frame(np.full((H, W, 3), 4.0)), tmp_path, "s", 4, write_reference=False)
    info = scan_folder(tmp_path)
    assert load_folder(info, 4).stats.n[0, 0, 0] == 4
    with pytest.raises(DbenchInputError, match=r"s_0016\.stats\.npz: statistics of 4 samples "
                                               r"at every pixel in a file named for 16 spp"):
        load_folder(info, 16)
    adaptive = np.full((H, W, 3), 16.0)
    adaptive[0, 0] = 9.0
    export_frame(frame(adaptive), tmp_path, "s", 16)
    assert load_folder(scan_folder(tmp_path), 16).stats.n[0, 0, 0] == 9


def test_a_lam_other_than_the_folders_statistics_is_refused(tmp_path):
    """--lam without --transform is compared with the λ the folder's statistics were gathered
    with; on identity statistics (a variance image) nothing reads it."""
    import argparse

    from dbench.cli.args import check_lam
    from dbench.datasets.scenes import catalogue

    mean = _img(3).astype(np.float64)
    stats = SampleStats(n=np.full((H, W, 3), 8.0), mean=mean, var_mean=mean / 8,
                        m3=np.zeros((H, W, 3)), transform="box-cox", lam=0.25)
    export_frame(Frame(color=mean.astype(np.float32), stats=stats, reference=_img(4), meta={}),
                 tmp_path / "bc", "s", 8)
    bc = catalogue.get(str(tmp_path / "bc"))
    args = argparse.Namespace(lam=0.25, transform=None)
    check_lam(args, [bc], ["bc"], [8])
    assert args.lam == 0.25
    with pytest.raises(DbenchInputError, match=r"--lam: .* gathered with box-cox \(λ 0.25\); "
                                               r"box-cox \(λ 0.5\) was asked for"):
        check_lam(argparse.Namespace(lam=0.5, transform=None), [bc], ["bc"], [8])
    # each spp is compared: one of λ 0.5 beside the λ 0.25 one does not hide it
    stats.lam = 0.5
    export_frame(Frame(color=mean.astype(np.float32), stats=stats, reference=_img(4), meta={}),
                 tmp_path / "bc", "s", 16, write_reference=False)
    bc = catalogue.get(str(tmp_path / "bc"))
    for spps in ([8, 16], [16, 8]):
        with pytest.raises(DbenchInputError, match=r"--lam: .* gathered with box-cox "
                                                   r"\(λ 0.25\); box-cox \(λ 0.5\) was asked"):
            check_lam(argparse.Namespace(lam=0.5, transform=None), [bc], ["bc"], spps)
    (tmp_path / "v").mkdir()
    _rgb(tmp_path / "v" / "v_0004.hdr.exr", _img(2))
    _rgb(tmp_path / "v" / "v_0004.var.exr", _img(3, hi=0.5))
    _rgb(tmp_path / "v" / "v_ref.hdr.exr", _img(1))
    v = catalogue.get(str(tmp_path / "v"))
    with pytest.raises(DbenchInputError, match=r"no scene here uses one: v \(identity\)"):
        check_lam(argparse.Namespace(lam=0.3, transform=None), [v], ["v"], [4])


def test_a_variance_that_is_negative_or_not_finite_is_refused(tmp_path):
    """A variance image (noisy or reference) or statistics holding a negative or NaN variance
    are refused naming the file; a NaN variance of a non-finite value is what such a
    pixel has, and +inf (an overflowed variance) says unknown: both are read."""
    ref, noisy, sigma2 = _img(1), _img(2), _img(3, hi=0.5)
    _rgb(tmp_path / "v_0004.hdr.exr", noisy)
    _rgb(tmp_path / "v_ref.hdr.exr", ref)
    for bad in (-0.5, np.nan):
        broken = sigma2.copy()
        broken[2, 3, 1] = bad
        _rgb(tmp_path / "v_0004.var.exr", broken)
        with pytest.raises(DbenchInputError, match=r"v_0004\.var\.exr: 1 values negative or "
                                                   r"NaN \(the first at \(2, 3, 1\)"):
            load_folder(scan_folder(tmp_path), 4)
    broken[2, 3, 1] = np.inf
    _rgb(tmp_path / "v_0004.var.exr", broken)
    assert np.isinf(load_folder(scan_folder(tmp_path), 4).stats.var_mean[2, 3, 1])
    broken[2, 3, 1] = np.nan
    _rgb(tmp_path / "v_0004.var.exr", broken)
    # where the value is itself NaN, its variance may be too (a noisy colour file holding
    # one is refused first: tests/datasets/test_folder_inputs.py)
    noisy_nan = noisy.copy()
    noisy_nan[2, 3, 1] = np.nan
    assert np.isnan(check_variance(broken, "v_0004.var.exr", noisy_nan)[2, 3, 1])
    # the reference's variance image
    (tmp_path / "v_0004.var.exr").unlink()
    _rgb(tmp_path / "v_0004.hdr.exr", noisy)
    (tmp_path / "dataset.json").write_text(json.dumps({"ref_spp": 64}))
    broken = sigma2.copy()
    broken[0, 0, 0] = -1.0
    _rgb(tmp_path / "v_ref.var.exr", broken)
    with pytest.raises(DbenchInputError, match=r"v_ref\.var\.exr: 1 values negative"):
        load_folder(scan_folder(tmp_path), 4)
    # statistics of a .stats.npz
    (tmp_path / "v_ref.var.exr").unlink()
    mean = noisy.astype(np.float64)
    var_mean = sigma2.astype(np.float64) / 4
    var_mean[1, 1, 2] = -1e-3
    export_frame(Frame(color=noisy, stats=SampleStats(n=np.full((H, W, 3), 4.0), mean=mean,
                                                      var_mean=var_mean, m3=np.zeros((H, W, 3)),
                                                      transform="identity", lam=0.5),
                       meta={}), tmp_path, "v", 4, write_reference=False)
    with pytest.raises(DbenchInputError, match=r"v_0004\.stats\.npz: var_mean: 1 values "
                                               r"negative or NaN \(the first at "
                                               r"\(1, 1, 2\)"):
        load_folder(scan_folder(tmp_path), 4)

