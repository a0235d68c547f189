"""Method and scene names as users read them in the reports (README.md, "Usage"): a plugin may
register any name, and a name must never move a number into another column of report.md or
of the sweep's README.md; a name the figures' font cannot draw costs one line of warnings."""
from __future__ import annotations

import json
import re

import pandas as pd

from dbench.report import headline, publish
from dbench.report.formats import markdown_table

# GitHub's table rows split on every "|" that no backslash escapes
CELL = re.compile(r"(?:\\.|[^|\\])+")


def _cells(line: str) -> list[str]:
    return [c.strip() for c in CELL.findall(line.strip().strip("|"))]


def _frame(name: str) -> pd.DataFrame:
    noisy = {"method": "noisy", "rmse": 0.1, "rmse_surface": 0.05, "relmse": 0.02,
             "relmse_surface": 0.02, "ssim": 0.8, "flip": 0.2, "time_s": 1e-5}
    d = pd.DataFrame([noisy, {**noisy, "method": name, "rmse": 0.07, "time_s": 0.03}])
    for c in ("rmse", "rmse_surface", "relmse", "relmse_surface", "ssim", "flip"):
        d[c + "_ci"] = d[c] * 1e-3
    return d


def test_a_pipe_or_line_break_in_a_name_keeps_every_number_in_its_column():
    for name in ("pipe|name", "two\nlines", "a | b | c"):
        md = "\n".join(headline.scene_block_md(_frame(name), "relmse"))
        rows = [ln for ln in md.splitlines() if ln.startswith("|")]
        header = _cells(rows[0])
        assert header[:2] == ["method", "rmse"]
        for ln in rows[2:]:
            cells = _cells(ln)
            assert len(cells) == len(header), (name, ln)
        row = next(_cells(ln) for ln in rows[2:] if not ln.startswith("| noisy"))
        # the method's own rmse, 0.07, stands under "rmse", never under another column
        assert row[header.index("rmse")].strip("*").startswith("0.07 ±"), row
        assert row[0].replace("\\|", "|") == " ".join(name.splitlines())
    table = markdown_table(pd.DataFrame({"scene": ["x|y"], "a|b": [1.5]}))
    assert [len(_cells(ln)) for ln in table.splitlines()] == [2, 2, 2]


def test_report_counts_library_warnings_in_one_line(tmp_path, monkeypatch, capsys):
    """``dbench report`` says the libraries' warnings (matplotlib's missing glyph for a scene
    name its font lacks) in one line, as ``run`` and ``sweep`` count theirs, never as Python's
    warning with its source line."""
    import warnings

    from dbench.cli import main

    def drawing(results, sweep_dir=None, rank_by="relmse"):
        for _ in range(3):
            warnings.warn("Glyph 38634 missing from font(s) DejaVu Sans.", UserWarning)
        return results / "README.md"

    sweep = tmp_path / "results" / "sweep"
    sweep.mkdir(parents=True)
    (sweep / "sweep.json").write_text(json.dumps({"config": {"scenes": ["雪"], "spp": [4]}}))
    monkeypatch.setattr(publish, "publish", drawing)
    assert main(["report", "--results", str(tmp_path / "results")]) == 0
    err = capsys.readouterr().err
    assert err == ("3 library warnings while writing: Glyph 38634 missing from font(s) DejaVu "
                   "Sans.\n")
