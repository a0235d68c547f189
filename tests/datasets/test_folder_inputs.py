"""What a folder of EXR renders must hold to be read (dbench/datasets/folders/; docs/formats.md
§1-2): finite colour, one data window per view, readable files; and what it may hold beside
(a reference's ``.stats.npz``, numbered frames a sweep reads)."""
import os

import numpy as np
import pytest

from dbench.cli import main
from dbench.data import SampleStats
from dbench.datasets.folders.export import write_stats_npz
from dbench.datasets.folders.load import load_folder, scan_folder
from dbench.errors import DbenchInputError
from exr_files import write_rgb as _rgb  # tests/exr_files.py

H, W = 16, 20


def _img(seed, lo=0.2, hi=1.0):
    return np.random.default_rng(seed).uniform(lo, hi, (H, W, 3)).astype(np.float32)


def _series(folder, view="v"):
    """Noisy renders at 4 and 16 spp and a reference of one scene (``view``)."""
    folder.mkdir(exist_ok=True)
    truth = _img(0)
    rng = np.random.default_rng(1)
    for spp in (4, 16):
        noise = rng.normal(0, 0.2 / np.sqrt(spp), truth.shape)
        _rgb(folder / f"{view}_{spp:04d}.hdr.exr", (truth + noise).astype(np.float32))
    _rgb(folder / f"{view}_ref.hdr.exr", truth)
    return folder


def test_a_noisy_colour_holding_nan_or_inf_is_refused_naming_the_first_pixel(tmp_path, capsys):
    """The reference was checked for finiteness, the noisy colour was not: its NaN reached the
    methods, whose rows were blamed for "non-finite output values"."""
    folder = _series(tmp_path / "renders")
    noisy = _img(5)
    noisy[4, 4, 0] = np.nan  # R at x 4, y 4
    noisy[7, 9, 1] = np.inf  # G at x 9, y 7
    _rgb(folder / "v_0016.hdr.exr", noisy)
    said = (r"v_0016\.hdr\.exr: colour contains NaN or Inf: 2 values, the first at pixel "
            r"\(x, y\) = \(4, 4\); expected finite values")
    info = scan_folder(folder)
    with pytest.raises(DbenchInputError, match=said):
        load_folder(info, 16, needs={"color"})
    # spp 4's run reads spp 16 too, for the reference's estimate: refused alike
    with pytest.raises(DbenchInputError, match=said):
        load_folder(info, 4)
    out = tmp_path / "run"
    assert main(["run", "--method", "noisy", "--scene", str(folder), "--spp", "16",
                 "--repeats", "1", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("dbench: ") and "v_0016.hdr.exr" in err[0]
    assert not (out / "metrics.csv").exists()  # refused before any method ran


def test_files_of_one_view_with_other_data_windows_are_refused_naming_both(tmp_path):
    """Only the sizes were compared: a reference whose data window starts at x = 3 was scored
    against a noisy image at x = 0 of the same size, pixel by pixel, offset by 3."""
    folder = _series(tmp_path / "renders")
    _rgb(folder / "v_ref.hdr.exr", _img(0), origin=(3, 0))
    with pytest.raises(DbenchInputError, match=(
            r"v_ref\.hdr\.exr: data window \(3, 0\)-\(22, 15\), while v_0004\.hdr\.exr has "
            r"\(0, 0\)-\(19, 15\) .*expected one data window for the whole view")):
        scan_folder(folder)
    # one window shared by every file, wherever it lies, is read as it is
    for spp in (4, 16):
        _rgb(folder / f"v_{spp:04d}.hdr.exr", _img(spp), origin=(3, 0))
    frame = load_folder(scan_folder(folder), 4)
    assert frame.color.shape == (H, W, 3)
    np.testing.assert_array_equal(frame.color, _img(4))


def test_a_sweep_reads_a_folder_holding_a_sequence(tmp_path, capsys):
    """dbench sweep ended in an internal error (AttributeError: no n_frames) on a folder of
    numbered frames: its fingerprint was taken as a rendered sequence's. It is the folder's own
    key, its content hash, as for a folder of one frame."""
    import json

    from dbench import datasets
    from dbench.datasets.scenes import catalogue

    folder = tmp_path / "walk"
    folder.mkdir()
    for k in range(3):
        view = _series(tmp_path / "one", view=f"v_f{k:04d}")
        for f in view.iterdir():
            f.rename(folder / f.name)
    scene = catalogue.get(str(folder))
    assert scene.kind == "sequence" and scene.info.frames == (0, 1, 2)
    first = datasets.scene_fingerprint(scene, (W, H))
    out = tmp_path / "sweep"
    args = ["sweep", "--scenes", str(folder), "--methods", "noisy", "--spp", "4", "--out",
            str(out), "--quiet"]
    assert main(args) == 0
    cell = json.loads((out / "cells" / "v" / "00004spp" / "noisy.json").read_text())
    assert (cell["status"], cell["frames"]) == ("ok", 3)
    assert "1 cell computed" in capsys.readouterr().out
    assert main(args) == 0  # the same content: the same cell, kept
    assert "0 cells computed, 0 not applicable, 1 already finished" in capsys.readouterr().out
    _rgb(folder / "v_f0002_0016.hdr.exr", _img(9))  # another content: another identity
    assert datasets.scene_fingerprint(catalogue.get(str(folder)), (W, H)) != first


def _stats(mean, var_mean, transform):
    n = np.full(mean.shape, 4096.0)
    return SampleStats(n=n, mean=mean.astype(np.float64), var_mean=var_mean,
                       m3=np.zeros(mean.shape), transform=transform, lam=0.5)


def test_a_reference_stats_npz_gives_the_references_variance(tmp_path):
    """<view>_ref.stats.npz was not even listed (the variance fell back to an estimate from
    the series), though the docstrings named it a source of the reference's variance."""
    folder = _series(tmp_path / "renders")
    (folder / "dataset.json").write_text('{"ref_spp": 4096}')
    var_mean = np.random.default_rng(3).uniform(1e-6, 1e-4, (H, W, 3))
    write_stats_npz(folder / "v_ref.stats.npz", _stats(_img(0), var_mean, "identity"))
    info = scan_folder(folder)
    frame = load_folder(info, 4)
    np.testing.assert_array_equal(frame.reference_var, var_mean.astype(np.float32))
    assert frame.meta["ref_noise_source"] == "statistics v_ref.stats.npz"
    assert frame.meta["files"]["reference_var"] == "v_ref.stats.npz"
    before = info.fingerprint  # the file is part of what the folder's identity covers
    write_stats_npz(folder / "v_ref.stats.npz", _stats(_img(0), var_mean * 2, "identity"))
    assert scan_folder(folder).fingerprint != before
    # statistics of transformed samples do not give the colour's variance: unused, and said
    write_stats_npz(folder / "v_ref.stats.npz", _stats(_img(0), var_mean, "box-cox"))
    said = load_folder(scan_folder(folder), 4).meta["ref_noise_source"]
    assert said.startswith("estimated from the noisy series") and said.endswith(
        "(v_ref.stats.npz holds statistics of box-cox-transformed samples, not the colour's "
        "variance: unused)")


def test_a_truncated_exr_gives_one_line(tmp_path, capfd):
    """A file cut to half its bytes gave three lines: OpenEXR's own EXR_ERR_BAD_CHUNK_LEADER
    on stderr, its "Warning: Exception raised reading pixel data" on stdout, then dbench's
    "Invalid part index '0': file has 0 parts"."""
    folder = _series(tmp_path / "renders")
    path = folder / "v_0016.hdr.exr"
    data = path.read_bytes()
    path.write_bytes(data[:len(data) // 2])
    capfd.readouterr()
    assert main(["run", "--method", "noisy", "--scene", str(folder), "--spp", "16",
                 "--repeats", "1", "--out", str(tmp_path / "run")]) == 2
    out, err = capfd.readouterr()
    assert "Warning" not in out and "EXR_ERR" not in out
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(f"dbench: {path}: not a readable EXR file (truncated or damaged: ")
    assert "EXR_ERR_BAD_CHUNK_LEADER" in lines[0] and "parts" not in lines[0]
    # the descriptors are back where they were: what is printed next is seen
    print("after", flush=True)
    os.write(2, b"after\n")
    assert capfd.readouterr() == ("after\n", "after\n")


def _frames(folder, numbers):
    """A folder of numbered frames ``numbers`` of one view ``v`` (4 and 16 spp, a reference)."""
    folder.mkdir()
    for k in numbers:
        view = _series(folder.parent / f"one{k}", view=f"v_f{k:04d}")
        for f in view.iterdir():
            f.rename(folder / f.name)
    return folder


def test_numbered_frames_with_a_gap_are_refused(tmp_path, capsys):
    """Frames 0, 2 and 3 were read as a sequence of three: frame 2's motion vectors (to frame
    1) reprojected frame 0's history and t_rmse differenced frames 0 and 2, silently."""
    folder = _frames(tmp_path / "walk", (0, 2, 3))
    with pytest.raises(DbenchInputError, match=r"walk/v: frames 0-3 lack frame 1; expected "
                                               r"consecutive frame numbers"):
        scan_folder(folder)
    assert main(["run", "--method", "noisy", "--scene", str(folder), "--spp", "4",
                 "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "lack frame 1" in err[0]
    assert not (tmp_path / "run").exists()
    assert scan_folder(_frames(tmp_path / "later", (5, 6, 7))).frames == (5, 6, 7)


def test_more_frames_than_a_folder_numbers_are_refused(tmp_path, capsys):
    """--frames 10 on a folder of 3 frames ran 3 frames and said nothing (a catalogue
    sequence refuses more frames than it has)."""
    folder = _frames(tmp_path / "walk", (0, 1, 2))
    assert main(["run", "--method", "noisy", "--scene", str(folder), "--spp", "4",
                 "--frames", "10", "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"dbench: --frames: {folder}/v holds 3 numbered frames (0-2); expected an "
                   "integer in [1, 3], got 10"]
    assert not (tmp_path / "run").exists()
    assert main(["run", "--method", "noisy", "--scene", str(folder), "--spp", "4",
                 "--frames", "2", "--out", str(tmp_path / "run2"), "--quiet"]) == 0


def test_a_sweep_refuses_more_frames_than_a_folder_numbers_before_anything_renders(tmp_path,
                                                                                  capsys):
    """Beside a rendered sequence the folder was loaded only in its turn: orbit had rendered
    and its cells and sweep.json were written before the refusal."""
    folder = _frames(tmp_path / "walk", (0, 1, 2))
    out, cache = tmp_path / "x" / "sw", tmp_path / "cache"
    assert main(["sweep", "--scenes", f"orbit,{folder}", "--methods", "noisy", "--spp", "4",
                 "--frames", "5", "--quiet", "--cache", str(cache), "--out", str(out)]) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        f"dbench: --frames: {folder}/v holds 3 numbered frames (0-2); expected an integer in "
        "[1, 3], got 5"]
    assert not (tmp_path / "x").exists() and not cache.exists()


@pytest.mark.parametrize("ev", ["NaN", "Infinity", "1e6", "-2000"])
def test_a_dataset_json_exposure_the_tone_map_cannot_use_is_refused_before_any_method(
        tmp_path, capsys, ev):
    """JSON's NaN and Infinity passed the type check and failed in the metrics after every
    method ran (the line not naming dataset.json); 1e6 ended in an internal OverflowError
    (exit 1) and -2000 scaled every tone-mapped pixel to black (2^ev rounds to 0)."""
    folder = _series(tmp_path / "renders")
    (folder / "dataset.json").write_text(f'{{"ev": {ev}}}')
    with pytest.raises(DbenchInputError, match=r"dataset\.json: ev: expected a finite number"):
        scan_folder(folder)
    out = tmp_path / "run"
    assert main(["run", "--method", "noisy", "--scene", str(folder), "--spp", "16",
                 "--repeats", "1", "--out", str(out)]) == 2
    captured = capsys.readouterr()
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and "dataset.json: ev:" in err[0] and "[-1074, 1023]" in err[0], err
    assert "running" not in captured.out + captured.err and not out.exists()


def test_a_file_named_with_0_spp_is_refused_naming_it(tmp_path, capsys):
    """``v_0000.hdr.exr`` was read as a render of 0 spp: it entered the noisy series and the
    reference's error estimated from it ("noisy series (0, 16 spp)"), and a refusal of another
    --spp offered 0, which --spp itself refuses."""
    folder = _series(tmp_path / "renders")
    (folder / "v_0004.hdr.exr").rename(folder / "v_0000.hdr.exr")
    with pytest.raises(DbenchInputError, match=r"v_0000\.hdr\.exr: spp 0 in its name; expected "
                                               r"a sample count in \[1, 2147483647\]"):
        scan_folder(folder)
    assert main(["run", "--method", "noisy", "--scene", str(folder), "--spp", "16",
                 "--repeats", "1", "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "v_0000.hdr.exr: spp 0" in err[0], err


def test_a_view_that_a_folder_does_not_hold_is_refused_naming_its_views(tmp_path, capsys):
    """DIR/NAME beside renders, NAME a typo or one of the files, was refused as an unknown
    catalogue scene, listing the catalogue's scenes instead of the folder's views."""
    folder = _series(tmp_path / "renders", view="kitchen")
    for name in ("kitchn", "kitchen_0004.hdr.exr"):
        assert main(["run", "--method", "noisy", "--scene", str(folder / name), "--spp", "4",
                     "--out", str(tmp_path / "run")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and f"no files of view {name!r}" in err[0] \
            and "(views: kitchen)" in err[0], err
    # a bare name is still a catalogue name, and a path elsewhere an unknown scene
    for name in ("cornel", str(tmp_path / "elsewhere" / "x")):
        assert main(["run", "--method", "noisy", "--scene", name, "--spp", "4",
                     "--out", str(tmp_path / "run")]) == 2
        assert "unknown scene" in capsys.readouterr().err
