"""Method and scene names as users read them in the reports (README.md, "Usage"): a plugin may
register any name, and a name must never move a number into another column of report.md or
of the sweep's README.md; a name the figures' font cannot draw costs one line of warnings."""
from __future__ import annotations

import json
import re

import pandas as pd

from dbench.report import headline, publish, run_report as report
from dbench.report.formats import markdown_table
from sweep_cells import ok_cell  # tests/sweep_cells.py

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


#: Names Markdown would read as markup: emphasis, an HTML tag, a code span, a link, a heading.
ODD_SCENES = ["a_b_c", "<x>"]
ODD_METHODS = ["noisy", "*star*", "tick`s", "[l](u)", "#h"]


def _cell(scene: str, spp: int, method: str) -> dict:
    err = 0.05 if method == "noisy" else 0.03 + 0.001 * ODD_METHODS.index(method)
    return ok_cell(scene, spp, method, err, base_method="noisy")


def _sweep(folder, cells, scenes, methods, spp):
    folder.mkdir(parents=True)
    (folder / "sweep.json").write_text(json.dumps({"config": {
        "labels": methods, "methods": methods, "scenes": scenes, "spp": spp, "res": 16,
        "seeds": 1, "seed": 0, "repeats": 1}}))
    for c in cells:
        p = folder / "cells" / c["scene"] / f"{c['spp']:05d}spp" / f"{c['method']}.json"
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(json.dumps(c))


def _raw(text: str, names) -> list[str]:
    """The names that stand unescaped in Markdown ``text`` (not preceded by a backslash)."""
    return [n for n in names if re.search(r"(?<!\\)" + re.escape(n), text)]


def test_names_markdown_reads_as_markup_are_escaped_in_readme_and_kept_raw_in_csv(tmp_path):
    from dbench.report.formats import markdown_text

    results = tmp_path / "results"
    cells = [_cell(s, p, m) for s in ODD_SCENES for p in (4, 16) for m in ODD_METHODS
             if (s, p, m) != ("<x>", 4, "#h")]  # one missing: named in the problems list
    cells.append({**_cell("a_b_c", 4, "*star*"), "method": "err_or", "status": "error",
                  "error": "ValueError: <lambda> failed"})
    _sweep(results / "sweep", cells, ODD_SCENES, ODD_METHODS + ["err_or"], [4, 16])
    md = publish.publish(results).read_text(encoding="utf-8")
    names = ["a_b_c", "<x>", "*star*", "tick`s", "[l](u)", "<lambda>", "err_or"]
    assert _raw(md, names) == []
    for name in ("a_b_c", "<x>", "*star*", "tick`s"):
        assert markdown_text(name) in md, name
    assert "### a\\_b\\_c" in md and "### \\<x\\>" in md  # the headline's headings
    assert "- missing \\#h on \\<x\\> at 4 spp" in md
    assert "- error err\\_or on a\\_b\\_c at 4 spp: ValueError: \\<lambda\\> failed" in md
    # CSV keeps names as they are; the viewer escapes HTML, not Markdown
    csv = (results / "sweep" / "tables" / "cells.csv").read_text(encoding="utf-8")
    assert "<x>" in csv and "*star*" in csv and "a\\_b" not in csv
    page = (results / "index.html").read_text(encoding="utf-8")
    assert "&lt;x&gt;" in page and "<x>" not in page and "a\\_b" not in page


def test_names_markdown_reads_as_markup_are_escaped_in_the_run_report():
    from dbench.report.formats import markdown_text

    table = pd.DataFrame([{**_cell("<x>", 4, m), "n_seeds": 1} for m in ODD_METHODS])
    settings = {"scene": "<x>", "kind": "steady", "spp": 4, "res": 16, "repeats": 1,
                "method parameters": "*star*: {}"}
    machine = {"cpu": "c", "cores": 2, "gpu": "none", "python": "3", "platform": "p",
               "packages": {}}
    md = report.run_report_md(table, settings, machine, skipped={"a_b": "sequence only"},
                              failed={"tick`s": "ValueError: <lambda>"})
    assert md.startswith("# dbench run: \\<x\\> at 4 spp")
    assert _raw(md, ["<x>", "*star*", "a_b", "<lambda>", "tick`s", "[l](u)"]) == []
    assert "- **tick\\`s**: ValueError: \\<lambda\\>" in md and "- a\\_b: sequence only" in md
    ranking = next(ln for ln in md.splitlines() if ln.startswith("Ranking by "))
    assert markdown_text("*star*") in ranking and markdown_text("[l](u)") in ranking


def test_markdown_text_escapes_markup_once_and_leaves_plain_labels_alone():
    from dbench.report.formats import markdown_cell, markdown_code, markdown_text

    assert markdown_text("jbf[radius=3]") == "jbf[radius=3]"  # no link: left as it reads
    assert markdown_text("[l](u)") == "\\[l\\](u)"
    assert markdown_text("a|b") == "a\\|b" and markdown_cell(markdown_text("a|b")) == "a\\|b"
    assert markdown_cell("a|b") == "a\\|b"
    assert markdown_text("two\nlines") == "two lines"
    assert markdown_code("x`y") == "`` x`y ``"
