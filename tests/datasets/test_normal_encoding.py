"""How a folder's normals are encoded (dbench.datasets.folders.normals): both hypotheses tested against
unit length by their median, the dataset.json declaration winning, ``dbench run
--normal-encoding`` winning over both, a warning where neither fits; and the record of the
files and EXR channels a load read and left."""
import json
import shutil

import numpy as np
import pytest

from dbench.cli import main
from dbench.cli.args import _scene_of
from dbench.cli.parser import build_parser
from dbench.datasets.folders.load import load_folder, scan_folder, with_normal_encoding
from dbench.datasets.folders.normals import decide, deviations
from dbench.errors import DbenchInputError
from exr_files import write_exr as _exr, write_rgb as _rgb  # tests/exr_files.py

H, W = 24, 40


def _unit(seed):
    n = np.random.default_rng(seed).normal(size=(H, W, 3))
    n[..., 2] = np.abs(n[..., 2])  # facing the camera's hemisphere
    return (n / np.linalg.norm(n, axis=-1, keepdims=True)).astype(np.float32)


def _old_score(stored):
    """A mean-based figure: the mean |‖2n − 1‖ − 1| over non-zero pixels, which a 0.1
    threshold on it would call signed above 0.1."""
    v = stored.reshape(-1, 3).astype(np.float64)
    v = v[np.any(v != 0, axis=-1)]
    return float(np.abs(np.linalg.norm(2 * v - 1, axis=-1) - 1).mean())


def _boundary_normals():
    """Unsigned normals whose background (10.6 % of the pixels) holds 0.5 grey, the encoding of
    a zero normal: the mean-based figure comes out at 0.106."""
    stored = _unit(1) * 0.5 + 0.5
    grey = np.zeros(H * W, bool)
    grey[np.random.default_rng(2).permutation(H * W)[:round(0.106 * H * W)]] = True
    grey = grey.reshape(H, W)
    stored[grey] = 0.5
    return stored, grey


def _folder(path, normal, dataset=None):
    path.mkdir()
    rng = np.random.default_rng(0)
    _rgb(path / "v_0004.hdr.exr", rng.uniform(0, 1, (H, W, 3)))
    _rgb(path / "v_0004.alb.exr", rng.uniform(0, 1, (H, W, 3)))
    _rgb(path / "v_0004.nrm.exr", normal)
    _rgb(path / "v_ref.hdr.exr", rng.uniform(0, 1, (H, W, 3)))
    if dataset is not None:
        (path / "dataset.json").write_text(json.dumps(dataset))
    return path


def test_unsigned_normals_at_a_mean_threshold_boundary_are_decoded(tmp_path):
    stored, grey = _boundary_normals()
    assert _old_score(stored) == pytest.approx(0.106, abs=0.01)
    assert _old_score(stored) > 0.1  # a mean with a 0.1 threshold calls them signed
    found = decide(stored, "v_0004.nrm.exr")
    assert found.encoding == "unsigned" and not found.warning
    assert found.unsigned_dev < 0.01 and found.signed_dev > 0.15
    info = scan_folder(_folder(tmp_path / "f", stored))
    f = load_folder(info, 4, needs={"normal"})
    assert info.normals == "unsigned"
    np.testing.assert_allclose(f.normal[~grey], _unit(1)[~grey], atol=1e-6)
    assert not f.normal[grey].any()  # 0.5 grey decodes to "nothing hit"
    assert f.meta["normal_encoding"].startswith("unsigned [0,1] → 2n−1 (median |‖n‖−1| 0.")
    assert "v_0004.nrm.exr (R, G, B)" in f.meta["normal_encoding"]
    # short normals at antialiased edges move a mean, not the median
    edges = _unit(3) * 0.5 + 0.5
    edges[:3] = 0.5 + (edges[:3] - 0.5) * 0.2
    assert decide(edges, "x").encoding == "unsigned"


def test_signed_normals_stay_signed():
    n = _unit(4)
    assert decide(n, "x").encoding == "signed"
    assert decide(np.abs(n), "x").encoding == "signed"  # one octant: unit length as stored
    signed, unsigned = deviations(np.abs(n))
    assert signed < 1e-6 and unsigned > 0.15


def test_dataset_json_declaration_wins(tmp_path):
    stored, _ = _boundary_normals()
    info = scan_folder(_folder(tmp_path / "f", stored, {"normal_encoding": "signed"}))
    f = load_folder(info, 4, needs={"normal"})
    assert info.normals == "signed"
    np.testing.assert_array_equal(f.normal, stored)
    assert "declared in dataset.json" in f.meta["normal_encoding"]
    assert "looks unsigned" in f.meta["normal_warning"]
    legacy = scan_folder(_folder(tmp_path / "g", _unit(5), {"normals": "unsigned"}))
    assert legacy.normals == "unsigned"
    with pytest.raises(DbenchInputError, match="disagree"):
        scan_folder(_folder(tmp_path / "h", _unit(5), {"normals": "unsigned",
                                                       "normal_encoding": "signed"}))
    with pytest.raises(DbenchInputError, match="normal_encoding 'raw'"):
        scan_folder(_folder(tmp_path / "i", _unit(5), {"normal_encoding": "raw"}))


def test_ambiguous_normals_give_a_warning(tmp_path):
    # unnormalised vectors (a gradient, not a normal): neither n nor 2n − 1 is near unit
    # length, and nothing is guessed
    vague = (_unit(6) * np.random.default_rng(6).uniform(0.2, 0.5, (H, W, 1))
             * np.where(np.random.default_rng(8).random((H, W, 3)) < 0.5, -1, 1)
             ).astype(np.float32)
    found = decide(vague, "v_0004.nrm.exr")
    assert found.encoding == "signed" and "neither is near unit length" in found.warning
    f = load_folder(scan_folder(_folder(tmp_path / "f", vague)), 4, needs={"normal"})
    assert "fit neither encoding clearly" in f.meta["normal_warning"]
    assert f.meta["normal_encoding"].startswith("undecided, used as stored")
    np.testing.assert_array_equal(f.normal, vague)
    # a run that reads no normal is not warned about them
    assert "normal_warning" not in load_folder(scan_folder(tmp_path / "f"), 4, needs=()).meta


def test_layers_read_and_ignored_are_recorded(tmp_path):
    rng = np.random.default_rng(7)
    color, alb, ref = (rng.uniform(0, 1, (H, W, 3)) for _ in range(3))
    ch = {c: color[..., i] for i, c in enumerate("RGB")}
    ch["A"] = np.ones((H, W))
    ch.update({f"albedo.{c}": alb[..., i] for i, c in enumerate("RGB")})
    ch.update({f"_arg_0.{c}": alb[..., i] for i, c in enumerate("RGB")})
    _exr(tmp_path / "m_0008.exr", ch)
    _rgb(tmp_path / "m_ref.exr", ref)
    _rgb(tmp_path / "m_0008.ldr.exr", np.clip(color, 0, 1))
    f = load_folder(scan_folder(tmp_path), 8, needs={"albedo", "reference"})
    assert f.meta["layers_read"] == [
        "m_0008.exr: color (R, G, B)", "m_0008.exr: albedo (albedo.R, albedo.G, albedo.B)",
        "m_ref.exr: color (R, G, B)"]
    assert f.meta["layers_ignored"] == [
        "m_0008.exr: A, _arg_0.B, _arg_0.G, _arg_0.R",
        "m_0008.ldr.exr: whole file (not a buffer dbench reads)"]


def test_the_option_wins_over_dataset_json_and_the_detection(tmp_path):
    """``--normal-encoding`` decides, says what dataset.json said where they differ, warns
    where the pixels contradict it, and enters the folder's fingerprint (the result's
    identity): another encoding is another result."""
    stored, grey = _boundary_normals()  # unsigned, and detected as such
    info = scan_folder(_folder(tmp_path / "f", stored, {"normal_encoding": "signed"}))
    assert info.normals == "signed"
    given = with_normal_encoding(info, "unsigned")
    f = load_folder(given, 4, needs={"normal"})
    assert given.normals == "unsigned"
    np.testing.assert_allclose(f.normal[~grey], _unit(1)[~grey], atol=1e-6)
    assert "given by --normal-encoding, over dataset.json's 'signed'" in \
        f.meta["normal_encoding"]
    assert "normal_warning" not in f.meta  # the pixels agree with the option
    against = with_normal_encoding(info, "signed")
    g = load_folder(against, 4, needs={"normal"})
    np.testing.assert_array_equal(g.normal, stored)
    assert "over dataset.json" not in g.meta["normal_encoding"]  # they agree
    assert "--normal-encoding gives signed normals, but v_0004.nrm.exr" in \
        g.meta["normal_warning"] and "looks unsigned" in g.meta["normal_warning"]
    assert len({info.fingerprint, given.fingerprint, against.fingerprint}) == 3
    # over the detection alone (no dataset.json)
    detected = scan_folder(_folder(tmp_path / "d", stored))
    assert detected.normals == "unsigned"
    assert with_normal_encoding(detected, "signed").normals == "signed"
    with pytest.raises(DbenchInputError, match="--normal-encoding: 'raw'; valid: signed, "
                                               "unsigned"):
        with_normal_encoding(info, "raw")


def test_the_option_on_the_command_line(tmp_path, capsys):
    """A bad value: one line naming the option and the choices, exit 2, before anything is
    read or written; a scene dbench renders refuses it; on a folder the scene's identity
    carries the encoding and the report states where it came from."""
    folder = _folder(tmp_path / "f", _boundary_normals()[0], {"normal_encoding": "signed"})
    out = tmp_path / "run"
    assert main(["run", "--method", "noisy", "--scene", str(folder), "--out", str(out),
                 "--normal-encoding", "raw"]) == 2
    err = capsys.readouterr().err
    assert err.strip() == "dbench: --normal-encoding: 'raw'; valid: signed, unsigned"
    assert not out.exists()
    assert main(["run", "--method", "noisy", "--scene", "cornell", "--out", str(out),
                 "--normal-encoding", "signed"]) == 2
    err = capsys.readouterr().err
    assert "--normal-encoding: cornell is rendered by dbench" in err and len(
        err.strip().splitlines()) == 1
    parser = build_parser()
    plain = _scene_of(parser.parse_args(["run", "--method", "noisy", "--scene", str(folder)]))
    given = _scene_of(parser.parse_args(["run", "--method", "noisy", "--scene", str(folder),
                                         "--normal-encoding", "unsigned"]))
    assert given.info.normals == "unsigned" and plain.info.normals == "signed"
    assert given.params["fingerprint"] != plain.params["fingerprint"]
    assert given.key_dict(None, None) != plain.key_dict(None, None)
    assert main(["run", "--method", "noisy", "--scene", str(folder), "--out", str(out),
                 "--repeats", "1", "--quiet", "--normal-encoding", "unsigned"]) == 0
    report = (out / "report.md").read_text(encoding="utf-8")
    assert "- normal encoding: unsigned [0,1] → 2n−1 (given by --normal-encoding, over " \
        "dataset.json's 'signed'" in report


def test_the_option_on_a_sweep(tmp_path, capsys):
    """``sweep --normal-encoding`` reads the sweep's folders that way, is stored in sweep.json
    and enters each folder cell's identity; a sweep of scenes dbench renders refuses it, with
    one line and exit 2, before its folder exists; a catalogue scene beside a folder keeps its
    own normals."""
    folder = _folder(tmp_path / "f", _boundary_normals()[0], {"normal_encoding": "signed"})
    for layer in ("hdr", "alb", "nrm"):  # the folder offers 8 spp too
        shutil.copy(folder / f"v_0004.{layer}.exr", folder / f"v_0008.{layer}.exr")
    out = tmp_path / "sw"
    assert main(["sweep", "--methods", "noisy", "--scenes", "cornell", "--spp", "4",
                 "--out", str(out), "--normal-encoding", "unsigned"]) == 2
    err = capsys.readouterr().err
    assert err.strip() == ("dbench: --normal-encoding: none of the sweep's scenes (cornell) is "
                           "a folder of renders; dbench renders the others, with signed normals")
    assert not out.exists()
    base = ["sweep", "--methods", "noisy", "--scenes", str(folder), "--spp", "4", "--repeats",
            "1", "--quiet", "--out"]
    assert main(base + [str(tmp_path / "plain")]) == 0
    assert main(base + [str(out), "--normal-encoding", "unsigned"]) == 0
    capsys.readouterr()
    stored = json.loads((out / "sweep.json").read_text())
    assert stored["config"]["normal_encoding"] == "unsigned"

    def fingerprint(root):
        cells = list((root / "cells").rglob("*.json"))
        assert cells
        return {json.loads(c.read_text())["identity"]["scene_fingerprint"] for c in cells}

    assert fingerprint(out).isdisjoint(fingerprint(tmp_path / "plain"))
    # the same folder read the other way is another sweep: refused, not mixed in, at the spp
    # it holds and at any other (a setting every cell of the folder shares)
    for spp in ("4", "8"):
        asked = [spp if a == "4" else a for a in base]
        assert main(asked + [str(out), "--normal-encoding", "signed", "--rerun"]) == 2
        err = capsys.readouterr().err
        assert "holds a sweep with other settings (normal_encoding: 'unsigned' there, " \
            "'signed' now)" in err
    assert json.loads((out / "sweep.json").read_text())["config"]["normal_encoding"] == \
        "unsigned"
