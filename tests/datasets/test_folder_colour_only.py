"""Colour-only renders: a method's needs follow its resolved parameters, so ``oidn`` with
``features=none`` runs where the default ``oidn`` is skipped with its reason."""
import json

import numpy as np
import pandas as pd

from dbench import registry
from dbench.cli import main
from exr_files import write_rgb as _rgb  # tests/exr_files.py

H, W = 24, 40


def _colour_only(folder):
    folder.mkdir()
    rng = np.random.default_rng(0)
    truth = rng.uniform(0.2, 1.0, (H, W, 3))
    _rgb(folder / "v_0004.hdr.exr", truth + rng.normal(0, 0.1, truth.shape))
    _rgb(folder / "v_ref.hdr.exr", truth)
    return folder


def test_needs_follow_the_features_parameter():
    colour = {"color", "reference"}
    oidn = registry.get("oidn", features="none")
    assert oidn.applies_to("steady", colour) == (True, "")
    assert oidn.wants(colour) == {"color"}
    assert registry.get("oidn", features="albedo").needs == {"color", "albedo"}
    assert registry.get("oidn").applies_to("steady", colour) == (
        False, "oidn needs ['albedo', 'normal'], which the scene cannot provide; "
               "--param oidn.features=none runs on the colour alone")
    # said where a reader sees the skip
    from dbench.report.terminal import skipped_line
    assert skipped_line({"oidn": registry.get("oidn").applies_to("steady", colour)[1]}) == (
        "skipped: oidn (needs albedo, normal; --param oidn.features=none runs on the colour "
        "alone)")
    # the gate passes its method's needs on, plus the statistics
    assert registry.get("oidn+gate", features="none").needs == {"color", "stats"}
    assert registry.get("oidn-bins", features="none").needs == {"color"}
    assert registry.method_class("oidn").needs == {"color", "albedo", "normal"}  # the default


def test_colour_only_folder_runs_what_needs_no_features(tmp_path, capsys):
    folder = _colour_only(tmp_path / "renders")
    out = tmp_path / "run"
    assert main(["run", "--method", "all", "--param", "oidn.features=none", "--scene",
                 str(folder), "--spp", "4", "--repeats", "1", "--out", str(out)]) == 0
    table = pd.read_csv(out / "metrics.csv")
    assert sorted(table.base_method) == ["noisy", "oidn"]
    # one line, the methods grouped by the kind of reason
    groups = _skip_groups(_skipped_line(capsys.readouterr().out))
    assert "jbf" in groups["needs albedo, normal"]
    assert not any("oidn" in names for names in groups.values())
    skipped = json.loads((out / "run.json").read_text(encoding="utf-8"))["skipped"]
    assert "oidn" not in skipped and "which the scene cannot provide" in skipped["nca"]
    assert np.isfinite(table.loc[table.base_method == "oidn", "rmse"]).all()


def test_colour_only_folder_skips_default_oidn_with_its_reason(tmp_path, capsys):
    folder = _colour_only(tmp_path / "renders")
    out = tmp_path / "run"
    assert main(["run", "--method", "oidn", "--scene", str(folder), "--spp", "4",
                 "--repeats", "1", "--out", str(out)]) == 0
    assert _skipped_line(capsys.readouterr().out) == (
        "skipped: oidn (needs albedo, normal; --param oidn.features=none runs on the colour "
        "alone)")
    assert list(pd.read_csv(out / "metrics.csv").base_method) == ["noisy"]


def _skipped_line(printed: str) -> str:
    """The one ``skipped:`` line of a run's output, its wrapped continuation joined."""
    lines = printed.splitlines()
    assert sum(ln.startswith("skipped:") for ln in lines) == 1, printed
    i = next(k for k, ln in enumerate(lines) if ln.startswith("skipped:"))
    text = lines[i]
    for ln in lines[i + 1:]:
        if not ln.startswith("  "):
            break
        text += " " + ln.strip()
    return text


def _skip_groups(line: str) -> dict[str, list[str]]:
    """{reason kind: methods} of a ``skipped: a, b (kind); c (kind)`` line."""
    import re
    groups = {}
    for part in line.removeprefix("skipped: ").split("; "):
        names, kind = re.fullmatch(r"(.*) \(([^()]*)\)", part).groups()
        groups[kind] = names.split(", ")
    return groups
