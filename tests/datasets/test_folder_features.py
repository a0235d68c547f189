"""Features of a folder's series of spp (dbench.datasets.folders.features): a feature that only
some spp have, and the reference not, is left out at every spp and said so; one that some spp
take from the reference is used and said so where it is read."""
import numpy as np

from dbench.cli import main
from dbench.datasets.folders.load import load_folder, scan_folder
from exr_files import write_rgb as _rgb  # tests/exr_files.py

H, W = 24, 40


def _folder(path, features, ref_features=()):
    """Spp 4, 16 and 64 with a named reference; ``features``: {tag: the spp that have it}."""
    path.mkdir()
    rng = np.random.default_rng(0)
    truth = rng.uniform(0.2, 1.0, (H, W, 3))
    n = rng.normal(size=(H, W, 3))
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    img = {"alb": truth, "nrm": n}
    for spp in (4, 16, 64):
        _rgb(path / f"v_{spp:04d}.hdr.exr", truth + rng.normal(size=truth.shape) * 0.3 / spp)
        for tag, spps in features.items():
            if spp in spps:
                _rgb(path / f"v_{spp:04d}.{tag}.exr", img[tag])
    _rgb(path / "v_ref.hdr.exr", truth)
    for tag in ref_features:
        _rgb(path / f"v_ref.{tag}.exr", img[tag])
    return path


def test_a_feature_some_spp_lack_is_left_out_of_the_whole_series_and_said(tmp_path):
    info = scan_folder(_folder(tmp_path / "f", {"alb": (4,), "nrm": (4, 16, 64)}))
    assert "albedo" not in info.buffers and "normal" in info.buffers
    for spp in info.spps:
        meta = load_folder(info, spp, needs=()).meta  # said whatever the run reads
        warning = meta["feature_warning"]
        assert warning.startswith("albedo missing at spp 16, 64, and not in the reference: "
                                  "albedo left out at every spp")
        assert "v_ref.alb.exr" in warning and "normal" not in warning
    four = load_folder(info, 4, needs={"normal"}).meta
    assert "v_0004.alb.exr: albedo left out at every spp (missing at spp 16, 64, and not in " \
           "the reference)" in four["layers_ignored"]
    # two buffers, each with the spp that lack it
    two = scan_folder(_folder(tmp_path / "g", {"alb": (4,), "nrm": (4, 16)}))
    warning = load_folder(two, 64, needs=()).meta["feature_warning"]
    assert warning.startswith("albedo missing at spp 16, 64; normal missing at spp 64, and "
                              "not in the reference: albedo, normal left out at every spp")
    assert "v_ref.alb.exr, v_ref.nrm.exr" in warning
    # a complete series, or features only in the reference: nothing to say
    for whole in (_folder(tmp_path / "h", {"alb": (4, 16, 64)}),
                  _folder(tmp_path / "i", {}, ref_features=("alb",))):
        meta = load_folder(scan_folder(whole), 16).meta
        assert "feature_warning" not in meta
        assert not any("left out" in line for line in meta["layers_ignored"])


def test_a_feature_some_spp_take_from_the_reference_is_said_where_read(tmp_path):
    info = scan_folder(_folder(tmp_path / "f", {"alb": (4,)}, ref_features=("alb",)))
    assert "albedo" in info.buffers
    meta = load_folder(info, 16, needs={"albedo"}).meta
    assert meta["files"]["albedo"] == "v_ref.alb.exr"
    assert meta["feature_warning"].startswith(
        "albedo at spp 16, 64 comes from the reference (v_ref.alb.exr), at the other spp from "
        "their own files")
    assert "feature_warning" in load_folder(info, 4, needs={"albedo"}).meta
    assert "feature_warning" not in load_folder(info, 16, needs=()).meta  # no albedo read


def test_a_run_names_the_files_it_left_out(tmp_path):
    folder = _folder(tmp_path / "f", {"alb": (4,), "nrm": (4, 16, 64)})
    out = tmp_path / "run"
    assert main(["run", "--method", "noisy,jbf", "--scene", str(folder), "--spp", "4",
                 "--repeats", "1", "--quiet", "--out", str(out)]) == 0
    report = (out / "report.md").read_text(encoding="utf-8")
    assert "- jbf: jbf needs ['albedo']" in report
    assert "v_0004.alb.exr: albedo left out at every spp (missing at spp 16, 64, and not in " \
           "the reference)" in report


def test_statistics_some_spp_lack_are_left_out_of_the_whole_series_and_said(tmp_path):
    folder = _folder(tmp_path / "s", {"alb": (4, 16, 64)})
    _rgb(folder / "v_0004.var.exr", np.full((H, W, 3), 0.01))  # a variance image at 4 spp only
    info = scan_folder(folder)
    assert "stats" not in info.buffers
    warning = load_folder(info, 16, needs=()).meta["feature_warning"]
    assert warning.startswith("statistics (.stats.npz or .var.exr) missing at spp 16, 64: left "
                              "out at every spp")
    # at every spp: nothing to say, and the statistics are there
    for spp in (16, 64):
        _rgb(folder / f"v_{spp:04d}.var.exr", np.full((H, W, 3), 0.01))
    info = scan_folder(folder)
    assert "stats" in info.buffers
    assert "feature_warning" not in load_folder(info, 16, needs=()).meta


def test_feature_buffers_holding_nan_or_inf_are_said(tmp_path):
    """Another renderer's depth where a pixel sees no surface (inf) or a broken albedo (NaN)
    is read as it is, and meta["feature_warning"] names the buffer, the count and the file."""
    img = np.full((H, W, 3), 0.5, np.float32)
    _rgb(tmp_path / "v_0004.hdr.exr", img)
    _rgb(tmp_path / "v_ref.hdr.exr", img)
    albedo = img.copy()
    albedo[1, 2, :] = np.nan
    _rgb(tmp_path / "v_0004.alb.exr", albedo)
    f = load_folder(scan_folder(tmp_path), 4)
    assert np.isnan(f.albedo[1, 2]).all()
    assert f.meta["feature_warning"] == "albedo: 3 values NaN or Inf in v_0004.alb.exr"
    _rgb(tmp_path / "v_0004.alb.exr", img)
    assert not load_folder(scan_folder(tmp_path), 4).meta.get("feature_warning")
