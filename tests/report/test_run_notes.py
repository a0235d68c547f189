"""The notes a sweep's runs record in sweep.json (what ``--methods all`` or ``--scenes all``
left out: dbench/run/sweep_history.py) in both reports of ``dbench report``: the README's
"Notes of the runs" and the results page (``results/index.html``), under the sweep's settings
line."""
from __future__ import annotations

import json

from dbench.report import publish
from sweep_cells import ok_cell  # tests/sweep_cells.py

NOTE = "--scenes all leaves out these scene plugins: plugin <lab> (ImportError: no_such_mod)"


def test_a_runs_notes_are_on_the_readme_and_the_page(tmp_path):
    results = tmp_path / "results"
    sweep = results / "sweep"
    sweep.mkdir(parents=True)
    runs = [{"started": "2026-01-01T00:00:00"},
            {"started": "2026-01-02T00:00:00", "notes": [NOTE]}]
    (sweep / "sweep.json").write_text(json.dumps({"config": {
        "labels": ["noisy", "jbf"], "methods": ["noisy", "jbf"], "scenes": ["cornell"],
        "spp": [4], "res": 16, "seeds": 1, "seed": 0, "repeats": 1}, "runs": runs}))
    for method in ("noisy", "jbf"):
        p = sweep / "cells" / "cornell" / "00004spp" / f"{method}.json"
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(json.dumps(ok_cell("cornell", 4, method)))
    readme = publish.publish(results).read_text(encoding="utf-8")
    page = (results / "index.html").read_text(encoding="utf-8")
    assert r"- run 2 (2026-01-02T00:00:00): --scenes all leaves out these scene plugins: " \
           r"plugin \<lab\> (ImportError: no\_such\_mod)" in readme
    section = page[page.index("<h2>Sweep sweep</h2>"):page.index('data-table="0"')]
    assert ("run 2 (2026-01-02T00:00:00): --scenes all leaves out these scene plugins: "
            "plugin &lt;lab&gt; (ImportError: no_such_mod)</p>") in section, section
    assert "<lab>" not in page and "run 1 (" not in page
