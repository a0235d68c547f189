"""What a run over a folder of renders states about it (docs/formats.md): which folder it
scored, that its noisy images come from the files (no seeds), the reference's spp or
"unknown", the tone map's EV when the folder sets one, and a --ref-spp the files cannot take
refused rather than ignored."""
import json

import numpy as np

from dbench import cli
from exr_files import write_rgb  # tests/exr_files.py

H, W = 24, 40


def _folder(path, dataset=None):
    path.mkdir()
    rng = np.random.default_rng(0)
    truth = rng.uniform(0.2, 1.0, (H, W, 3))
    for spp in (4, 16):
        noise = rng.normal(size=truth.shape) * 0.5 * truth / np.sqrt(spp)
        write_rgb(path / f"v_{spp:04d}.hdr.exr", (truth + noise).astype(np.float32))
    write_rgb(path / "v_ref.hdr.exr", truth.astype(np.float32))
    if dataset is not None:
        (path / "dataset.json").write_text(json.dumps(dataset))
    return path


def _run(tmp_path, folder, *extra):
    out = tmp_path / "out"
    rc = cli.main(["run", "--method", "noisy", "--scene", str(folder), "--spp", "16",
                   "--repeats", "1", "--quiet", "--cache", str(tmp_path / "cache"),
                   "--out", str(out), *extra])
    return rc, out


def test_the_report_names_the_folder_and_says_its_renders_are_files(tmp_path):
    folder = _folder(tmp_path / "renders", {"ev": 3.0})
    rc, out = _run(tmp_path, folder)
    assert rc == 0
    settings = json.loads((out / "run.json").read_text())["settings"]
    assert settings["folder"] == str(folder)
    assert settings["seeds"] == "one render per spp, from the files"
    assert "reference seed" not in settings
    assert settings["ref_spp"] == "unknown"  # no spp in dataset.json or the file name
    assert settings["reference RMSE (estimated)"].startswith("unknown")
    assert "unknown (unknown" not in settings["reference RMSE (estimated)"]
    # the EV changes every LDR metric, so the report says it and where it came from
    assert settings["tone-map EV"] == "3 stops (the LDR metrics' exposure, dataset.json)"
    assert "- tone-map EV: 3 stops" in (out / "report.md").read_text()


def test_the_headline_of_a_folder_run_says_one_seed(tmp_path, capsys):
    """It said "2 seeds": the seed count was the number of comma-separated parts of the
    settings' "one render per spp, from the files"."""
    capsys.readouterr()
    assert _run(tmp_path, _folder(tmp_path / "renders"))[0] == 0
    head = [line for line in capsys.readouterr().out.splitlines() if " spp, " in line]
    assert head and head[0].endswith("px, 1 seed; device cpu"), head


def test_a_catalogue_run_keeps_its_seeds_and_states_no_folder(tmp_path):
    rc = cli.main(["run", "--method", "noisy", "--scene", "cornell", "--spp", "2", "--res",
                   "8", "--ref-spp", "16", "--repeats", "1", "--quiet", "--cache",
                   str(tmp_path / "cache"), "--out", str(tmp_path / "out")])
    settings = json.loads((tmp_path / "out" / "run.json").read_text())["settings"]
    assert rc == 0 and settings["seeds"] == "0" and settings["reference seed"] == 0
    assert "folder" not in settings and "tone-map EV" not in settings


def test_ref_spp_on_a_folder_whose_reference_states_none_is_refused(tmp_path, capsys):
    """It used to be ignored without a word ("ref_spp: None" in the report)."""
    folder = _folder(tmp_path / "renders")
    rc, out = _run(tmp_path, folder, "--ref-spp", "4096")
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1, err
    assert err.startswith("dbench: --ref-spp: the reference in ") and "dataset.json" in err
    assert not out.exists()
    _folder(tmp_path / "declared", {"ref_spp": 4096})
    assert _run(tmp_path, tmp_path / "declared", "--ref-spp", "4096")[0] == 0



def test_a_sweep_over_folders_alone_checks_ref_spp_as_run_does(tmp_path, capsys):
    """Beside a rendered scene a folder stating no spp keeps "unknown" (--ref-spp is the
    rendered scene's: tests/datasets/test_scene_files.py); over folders alone the option would
    apply to nothing, and is refused as ``dbench run`` refuses it."""
    folder = _folder(tmp_path / "renders")
    rc = cli.main(["sweep", "--methods", "noisy", "--scenes", str(folder), "--spp", "16",
                   "--ref-spp", "64", "--repeats", "1", "--quiet", "--cache",
                   str(tmp_path / "cache"), "--out", str(tmp_path / "sweep")])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1, err
    assert err.startswith("dbench: --ref-spp: the reference in ") and "states no spp" in err
    assert not (tmp_path / "sweep").exists()
