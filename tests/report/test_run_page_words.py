"""What a ``dbench run``'s index.html says in words (README.md, "The interactive report"): the
rows it shows in red are the rows whose verdict says "worse than noisy", as the page's note
says, and a method that failed is named with its error, as report.md names it."""
from __future__ import annotations

import json
import re

import numpy as np
import pandas as pd

from dbench.report import html
from dbench.synthetic import base_frame


def _table() -> pd.DataFrame:
    noisy = {"scene": "s", "spp": 4, "status": "ok", "method": "noisy", "rmse": 0.1,
             "rmse_surface": 0.05, "relmse": 0.02, "relmse_surface": 0.02, "ssim": 0.8,
             "flip": 0.2, "time_s": 1e-5}
    # better than the noisy input on relMSE and surface RMSE, worse on FLIP
    flips = {**noisy, "method": "flips", "relmse": 0.01, "rmse_surface": 0.04, "flip": 0.3,
             "time_s": 0.02}
    d = pd.DataFrame([noisy, flips])
    for c in ("rmse", "rmse_surface", "relmse", "relmse_surface", "ssim", "flip"):
        d[c + "_ci"] = d[c] * 1e-3
    return d


def _page(tmp_path, failed=None):
    f = base_frame(16, 16)
    out = np.asarray(f.color, dtype=np.float32)
    page = html.run_page(tmp_path, title="s, 4 spp, 16×16 px", frame=f,
                         outputs=[("noisy", f.color), ("flips", out)], table=_table(),
                         columns=("rmse", "rmse_surface", "relmse", "ssim", "flip", "time_s"),
                         settings={"scene": "s"}, machine={}, skipped={},
                         **({} if failed is None else {"failed": failed}))
    text = page.read_text(encoding="utf-8")
    js = (tmp_path / "viewer" / "data.js").read_text(encoding="utf-8")
    data = json.loads(js[js.index("{"):js.rindex("}") + 1])
    return text, data["tables"][0]


def test_red_rows_are_the_rows_the_verdict_calls_worse_and_the_note_says_so(tmp_path):
    text, table = _page(tmp_path)
    verdict = {r[0]: r[-1] for r in table["rows"]}
    assert verdict["flips"].startswith("worse than noisy on flip")
    flagged = {table["rows"][i][0] for i in table["flagged"]}
    assert flagged == {m for m, v in verdict.items() if v.startswith("worse")} == {"flips"}
    note = " ".join(re.findall(r'<p class="note">(.*?)</p>', text, flags=re.S))
    # the note must not claim a narrower rule than the one the page applies
    assert "on relMSE or surface RMSE" not in note
    assert "at least one headline metric, as its verdict says" in " ".join(note.split())
    # the noisy input is the fastest yet never the bold time: the note says why
    time_col = str(table["columns"].index("time_s"))
    assert [table["rows"][i][0] for i in table["best"][time_col]] == ["flips"]
    assert "the noisy input is not a candidate for the fastest time_s" in " ".join(note.split())


def test_a_failed_method_is_named_on_the_page_with_its_error_escaped(tmp_path):
    text, table = _page(tmp_path, failed={"boom<b>": "RuntimeError: <script>x</script>"})
    assert "<h2>Failed</h2>" in text
    assert "boom&lt;b&gt;" in text and "RuntimeError: &lt;script&gt;x&lt;/script&gt;" in text
    assert "<script>x" not in text
    assert {r[0] for r in table["rows"]} == {"noisy", "flips"}
    text, _ = _page(tmp_path / "none", failed={})
    assert "<h2>Failed</h2>" not in text


def test_the_page_says_the_interval_kind_and_the_reference_as_report_md_does(tmp_path):
    """One seed: a block bootstrap (or no interval); the reference's spp and estimated error,
    "unknown" where the run could not estimate it (a folder's reference without variance)."""
    from dbench.report import run_report

    kind = "block bootstrap 95 % (4-px blocks, 1000 resamples, one seed)"
    table = _table().assign(ci_kind=kind, ref_spp=16)
    f = base_frame(16, 16)
    page = html.run_page(tmp_path, title="s", frame=f, outputs=[("noisy", f.color)],
                         table=table, columns=("rmse", "relmse", "time_s"),
                         settings={"scene": "s"}, machine={}, skipped={})
    text = " ".join(page.read_text(encoding="utf-8").split())
    assert f"Intervals: {kind}; reference 16 spp, estimated reference RMSE unknown." in text
    assert "Ranking by relmse (lower is better): flips &lt; noisy" in text
    settings = {"scene": "s", "kind": "steady", "spp": 4, "res": 16, "repeats": 1,
                "ref_spp": 16, "reference RMSE (estimated)": "unknown (no variance image)"}
    machine = {"cpu": "c", "cores": 2, "gpu": "none", "python": "3", "platform": "p",
               "packages": {}}
    md = " ".join(run_report.run_report_md(table, settings, machine, {}).split())
    assert f"Intervals: {kind}; reference 16 spp, estimated reference RMSE unknown." in md
